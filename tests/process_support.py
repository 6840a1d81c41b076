"""Whether processes a test started are still alive (a support module, not tests)."""

from __future__ import annotations

import time
from pathlib import Path

# How long a process is given to end after it is asked to.
WITHIN_S = 20.0


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie waiting for its parent does not)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    state = next(line for line in status.splitlines() if line.startswith("State:"))
    return "Z" not in state.split()[1]


def gone(pids: list[int], within: float = WITHIN_S) -> bool:
    """Whether every one of ``pids`` has ended within ``within`` seconds."""
    end = time.monotonic() + within
    while time.monotonic() < end:
        if not any(alive(p) for p in pids):
            return True
        time.sleep(0.05)
    return False
