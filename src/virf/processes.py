"""Child processes that end with VIRF, and signals that end VIRF cleanly.

Two guarantees (docs/reliability.md, "Stopping"):

* **Children end with their parent.**  :func:`guarded` runs a command under
  a small guard process (:mod:`virf.guard`) in a session of its own, the
  command in a process group of its own.  Leaving the ``with`` block for
  any reason (an error, Ctrl-C, :class:`Terminated`) stops the command and
  everything it started, and waits for them.  When VIRF itself is killed
  (SIGKILL, a crash), the guard notices, because a pipe only VIRF held
  reads end of file, and stops them itself, removing the command's
  temporary folder too.
* **SIGTERM and SIGHUP end a command the way Ctrl-C does.**  After
  :func:`end_on_termination`, each raises :class:`Terminated` in the main
  thread, so ``finally`` blocks and ``with`` blocks run (children stopped,
  temporary folders removed) and the command line exits with 128 + the
  signal's number (143 for SIGTERM) instead of dying where it stood.  The
  JVM is started with ``-Xrs`` (:mod:`virf.ontology.jvm`), so it leaves
  these signals to Python.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

if TYPE_CHECKING:
    import subprocess

GUARD: Final = Path(__file__).with_name("guard.py")
# How long a stopped guard may take: its grace between SIGTERM and SIGKILL,
# and a margin.
STOP_S: Final = 15.0
# The signals that end a command as an interrupt does (SIGINT is Python's
# KeyboardInterrupt already).
TERMINATING: Final = (signal.SIGTERM, signal.SIGHUP)


class Terminated(BaseException):
    """SIGTERM or SIGHUP arrived.  A BaseException, like KeyboardInterrupt:
    nothing that handles errors (a verifier turning them into ERROR reports,
    a harness storing a failed row) may take it for one."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(f"interrupted by {self.name}")

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name

    @property
    def exit_code(self) -> int:
        return 128 + self.signum


def end_on_termination() -> None:
    """From now on, SIGTERM and SIGHUP raise :class:`Terminated` in the main
    thread.  A second one while the first is being handled (``finally``
    blocks stopping children) is ignored, so the clean-up is not cut short;
    SIGKILL still ends the process, and :func:`guarded` children with it."""
    if threading.current_thread() is not threading.main_thread():
        return
    raised = False

    def terminate(signum: int, frame: object) -> None:
        nonlocal raised
        if raised:
            return
        raised = True
        raise Terminated(signum)

    for signum in TERMINATING:
        signal.signal(signum, terminate)


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


def run(
    command: Sequence[str], *, timeout: float | None = None, **popen: Any
) -> subprocess.CompletedProcess[str]:
    """``subprocess.run(command, capture_output=True, text=True)`` under a
    guard (:func:`guarded`): the command, and whatever it starts, ends with
    this process even when this process is killed, and when ``timeout``
    passes (``subprocess.TimeoutExpired``), not only the command itself, as
    ``subprocess.run`` would, but its whole process group is stopped."""
    import subprocess

    with guarded(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **popen
    ) as proc:
        try:
            out, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            raise subprocess.TimeoutExpired(list(command), timeout or 0.0) from None
    return subprocess.CompletedProcess(list(command), proc.returncode, out, err)


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
