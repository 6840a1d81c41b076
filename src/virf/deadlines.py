"""Deadlines for reasoning, and the failures that end a reasoner call.

Shared by the engines (:mod:`virf.reasoning`) and the Java bridge
(:mod:`virf.ontology.owlapi`), which sits before them in the data flow and so
cannot import them.

Every engine question takes an optional ``deadline`` (a :func:`time.monotonic`
instant).  Once it passes, the engine stops where it is and raises
:class:`DeadlineExceeded`, a :class:`ReasonerFailure`, so the caller fails
closed.  The deadline is held in a context variable for the duration of the
call: an engine that asks another engine (the fast engine's fallback, a
wrapper that delegates) passes it on without having to thread it through,
and an engine's inner loops read it with :func:`check_deadline`.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar


class ReasonerFailure(Exception):
    """The engine could not answer (crash, timeout).  Verification fails closed."""


class DeadlineExceeded(ReasonerFailure):
    """The caller's deadline passed before the engine had an answer."""


_DEADLINE: ContextVar[float | None] = ContextVar("virf_deadline", default=None)


def current_deadline() -> float | None:
    """The deadline in force for the engine call running in this context."""
    return _DEADLINE.get()


def check_deadline(where: str = "") -> None:
    """Raise :class:`DeadlineExceeded` when the deadline in force has passed.

    Cheap enough for an inner loop that calls it every few thousand
    iterations, not on every one."""
    deadline = _DEADLINE.get()
    if deadline is not None and time.monotonic() > deadline:
        raise DeadlineExceeded(f"the deadline passed{' ' + where if where else ''}")


@contextmanager
def until(deadline: float | None) -> Iterator[None]:
    """Engine calls inside the block stop at ``deadline``.  An earlier deadline
    already in force is kept: a nested call may not extend its caller's time."""
    outer = _DEADLINE.get()
    if deadline is None or (outer is not None and outer <= deadline):
        yield
        return
    token = _DEADLINE.set(deadline)
    try:
        yield
    finally:
        _DEADLINE.reset(token)
