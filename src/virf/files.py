"""Files VIRF writes, whole or not at all, and the prompt files it ships."""

from __future__ import annotations

import os
import stat
import tempfile
from functools import cache
from importlib import resources
from pathlib import Path


def write_atomically(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file in the same folder
    and a rename, so a crash or a full disk never leaves half a file.  Raises
    ``OSError``; callers say what the file was."""
    try:
        mode = stat.S_IMODE(path.stat().st_mode)
    except OSError:
        mask = os.umask(0o022)  # the only way to read the umask is to set it
        os.umask(mask)
        mode = 0o666 & ~mask
    # mkstemp makes the file private (0600); a module or report is not.
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, mode)
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@cache
def read_prompt(package: str, name: str) -> str:
    """The text of ``name`` in the ``prompts`` folder that ``package`` ships
    (``read_prompt("virf.planner", "apprentice.txt")``).  Prompts are package
    data so that they can be read and changed without touching code; the
    planner, the drafter and the vision cascade all read theirs here, once."""
    return resources.files(package).joinpath("prompts", name).read_text(encoding="utf-8")
