"""Run a command for VIRF, and end it, with all it started, when VIRF ends.

    python -I guard.py FD [--remove DIR] -- COMMAND [ARG...]

:func:`virf.processes.guarded` starts this script; it is not meant to be run
by hand.  VIRF holds the write end of a pipe whose read end is ``FD`` here,
and never writes to it: the pipe reads end of file once VIRF's process is
gone, however it ended (SIGKILL and a crash included), because the kernel
closes its descriptors.

The command runs in a process group of its own, which its children join
(owlready2 starts Java, ``virf serve`` starts its workers).  The group is
ended, SIGTERM first and SIGKILL ``GRACE_S`` seconds later, when

* the pipe reads end of file (VIRF is gone); ``DIR`` is then removed as well,
  since nobody is left to remove it;
* the guard receives SIGTERM, SIGINT or SIGHUP (VIRF stops the command).

When the command ends by itself, whatever it left running in its group is
killed too.  The guard exits with the command's exit status, or 128 + N when
signal N ended it (as a shell reports it).

Only the standard library: the guard runs under VIRF's interpreter with
``-I`` (no environment, no user site), and imports nothing of VIRF.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import threading
import time

GRACE_S = 5.0  # between SIGTERM and SIGKILL
POLL_S = 0.05
USAGE = "usage: guard.py FD [--remove DIR] -- COMMAND [ARG...]"


def main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    remove: str | None = None
    try:
        fd = int(args.pop(0))
        if args[:1] == ["--remove"]:
            args.pop(0)
            remove = args.pop(0)
        if args[:1] == ["--"]:
            args.pop(0)
    except (IndexError, ValueError):
        args = []
    if not args:
        print(USAGE, file=sys.stderr)
        return 2
    stop = threading.Event()
    orphaned = threading.Event()

    def asked_to_stop(signum: int, frame: object) -> None:
        stop.set()

    for signum in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
        signal.signal(signum, asked_to_stop)
    try:
        # Its own group: a signal for the group never reaches the guard.
        child = subprocess.Popen(args, process_group=0)
    except OSError as exc:
        print(f"error: cannot start {args[0]}: {exc.strerror}", file=sys.stderr)
        return 127

    def watch_parent() -> None:
        with contextlib.suppress(OSError):
            while os.read(fd, 512):
                pass  # VIRF never writes; nothing to read but the end
        orphaned.set()
        stop.set()

    threading.Thread(target=watch_parent, name="parent-watch", daemon=True).start()
    stopped_at: float | None = None
    while not _ended(child.pid):
        if stop.is_set():
            now = time.monotonic()
            if stopped_at is None:
                stopped_at = now
                _signal_group(child.pid, signal.SIGTERM)
            elif now - stopped_at > GRACE_S:
                _signal_group(child.pid, signal.SIGKILL)
        time.sleep(POLL_S)
    # The command has ended but is not yet reaped, so its group id cannot
    # have been reused: what it left running in the group goes now.
    _signal_group(child.pid, signal.SIGKILL)
    code = child.wait()
    if orphaned.is_set() and remove:
        shutil.rmtree(remove, ignore_errors=True)
    return 128 - code if code < 0 else code


def _ended(pid: int) -> bool:
    """Whether the command has ended (it is left unreaped)."""
    try:
        found = os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT)
    except ChildProcessError:
        return True
    return found is not None


def _signal_group(pgid: int, signum: int) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pgid, signum)


if __name__ == "__main__":
    sys.exit(main())
