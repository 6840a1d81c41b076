"""Child processes that end with VIRF (docs/reliability.md, "Stopping").

* **Children end with their parent.**  :func:`guarded` runs a command under
  a small guard process (:mod:`virf.guard`) in a session of its own, the
  command in a process group of its own.  Leaving the ``with`` block for
  any reason (an error, Ctrl-C) stops the command and
  everything it started, and waits for them.  When VIRF itself is killed
  (SIGKILL, a crash), the guard notices, because a pipe only VIRF held
  reads end of file, and stops them itself, removing the command's
  temporary folder too.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

if TYPE_CHECKING:
    import subprocess

GUARD: Final = Path(__file__).with_name("guard.py")
# How long a stopped guard may take: its grace between SIGTERM and SIGKILL,
# and a margin.
STOP_S: Final = 15.0


@contextlib.contextmanager
def guarded(
    command: Sequence[str], *, remove: str | Path | None = None, **popen: Any
) -> Iterator[subprocess.Popen[Any]]:
    """``command`` running under a guard until the block is left.

    The process yielded is the guard's: its ``stdin``, ``stdout`` and
    ``stderr`` (``popen`` takes ``subprocess.Popen``'s options) are the
    command's, and its exit status is the command's, or 128 + N when signal
    N ended it.  On leaving the block the command, and whatever it started,
    is stopped (SIGTERM, then SIGKILL after the guard's grace) and waited
    for.  ``remove`` is a folder the guard deletes when VIRF dies first;
    otherwise removing it stays the caller's business."""
    import subprocess

    read_end, write_end = os.pipe()  # neither is inherited by other children
    argv = [sys.executable, "-I", str(GUARD), str(read_end)]
    if remove is not None:
        argv += ["--remove", str(remove)]
    try:
        proc = subprocess.Popen(
            [*argv, "--", *command], pass_fds=(read_end,), start_new_session=True, **popen
        )
    except BaseException:
        os.close(write_end)
        raise
    finally:
        os.close(read_end)
    try:
        yield proc
    finally:
        try:
            stop(proc)
        finally:
            os.close(write_end)
            for stream in (proc.stdin, proc.stdout, proc.stderr):
                if stream is not None:
                    with contextlib.suppress(OSError):
                        stream.close()


def stop(proc: subprocess.Popen[Any]) -> None:
    """Stop a guard started by :func:`guarded` (and so its command), and wait
    for it; a guard that does not end in ``STOP_S`` is killed."""
    import subprocess

    if proc.poll() is not None:
        return
    with contextlib.suppress(ProcessLookupError):
        proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=STOP_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
