"""Seals on the compiled artifacts VIRF caches in a writable folder.

A knowledge workspace caches its compiled TBox in its own ``cache/`` folder.
The artifact names a digest of the module files it was compiled from, but a
digest is only a cache key: anyone who can write the folder can copy it into
an artifact of their own (say, one without the Unsafe State Concepts), and a
plan would then be SAFE under rules nobody accepted.  Keeping a second digest
of the artifact beside it would not help, since whoever forges the one can
recompute the other.

So a cached artifact is sealed with an HMAC-SHA256 under a key that never
lives in the workspace: a random 32-byte key of this user, created on first
use in ``$XDG_CACHE_HOME/virf/artifact.key`` (``~/.cache/virf``), readable by
the user alone.  A cache is used only when its seal verifies, that is when
VIRF running as this user wrote it; anything else (a forged or edited file,
one written by another user or on another machine, a seal without a key to
check it against) is compiled again from the modules, which needs Java and
takes a few seconds, then sealed anew.  Recompiling on every load instead
would cost those seconds (and Java) on every ``--kb`` command; the seal keeps
the cache and the guarantee that what is used is what the modules compile to.

The key is not trusted when it is not a regular file of this user that no one
else may read or write, or when it cannot be created (a read-only home): then
no cache is read or written, and every load compiles.  The built-in artifacts
(``virf/ontology/compiled``) are part of the installed package, as trusted as
its code; ``virf kb check`` compares them with the modules.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
import stat
import tempfile
from pathlib import Path
from typing import Final

from virf import __version__

KEY_BYTES: Final = 32
# The first line of a sealed file; the artifact's own text follows it.
_HEADER: Final = "virf-sealed-artifact hmac-sha256 "
_CONTEXT: Final = b"virf compiled artifact\0"


def key_path() -> Path:
    cache_home = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(cache_home) / "virf" / "artifact.key"


def local_key() -> bytes | None:
    """This user's sealing key, created on first use; None when there is none
    that only this user can read and write."""
    try:
        path = key_path()
        path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        if not path.exists():
            # Written whole under another name and linked into place, which
            # fails when another process got there first: a reader never sees
            # half a key, and every process ends up with the same one.
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".artifact.key.")
            try:
                with os.fdopen(fd, "wb") as fh:
                    fh.write(secrets.token_bytes(KEY_BYTES))
                os.link(tmp, path)
            except FileExistsError:
                pass
            finally:
                os.unlink(tmp)
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
        with os.fdopen(fd, "rb") as fh:
            info = os.fstat(fh.fileno())
            key = fh.read(KEY_BYTES + 1)
    except (OSError, RuntimeError):  # RuntimeError: no home folder to keep it in
        return None
    if (
        not stat.S_ISREG(info.st_mode)
        or info.st_uid != os.getuid()
        or info.st_mode & 0o077
        or len(key) != KEY_BYTES
    ):
        return None
    return key


def _tag(text: str, key: bytes) -> str:
    # The version too: a cache another VIRF compiled is compiled again.
    context = _CONTEXT + __version__.encode() + b"\0"
    return hmac.new(key, context + text.encode("utf-8"), hashlib.sha256).hexdigest()


def seal(text: str, key: bytes) -> str:
    """``text`` with a first line that proves who wrote it."""
    return f"{_HEADER}{_tag(text, key)}\n{text}"


def unseal(sealed: str, key: bytes) -> str | None:
    """The text a seal made by ``key`` covers, or None for anything else."""
    first, sep, text = sealed.partition("\n")
    if not sep or not first.startswith(_HEADER):
        return None
    if not hmac.compare_digest(first.removeprefix(_HEADER), _tag(text, key)):
        return None
    return text
