"""The wall-clock deadline of a whole ``virf plan`` run.

A run asks the model, verifies, and asks the user, any number of times within
``--max-iter``.  Each model reply is bounded by ``--timeout`` on its own, but
the run as a whole needs a bound as well, or enough slow replies, re-asks and
retries add up to hours.  The loop checks the deadline before every step,
and the model client abandons a request that is still running when it passes
(:mod:`virf.planner.clients`).  A run whose deadline passes is rejected: its
plan was never approved.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Final, ParamSpec, TypeVar

from virf.errors import InputError

DEFAULT_DEADLINE_S: Final = 600.0
# A week: far above any real run, and a bound against typing milliseconds.
MAX_DEADLINE_S: Final = 7 * 86_400.0

_P = ParamSpec("_P")
_T = TypeVar("_T")


def deadline_seconds(value: object, source: str = "--deadline") -> float:
    """``value`` as a number of seconds, or an input error naming ``source``."""
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not 0 < value <= MAX_DEADLINE_S
    ):
        raise InputError(
            f"{source} {value!r} must be a number of seconds in (0, {MAX_DEADLINE_S:g}]"
        )
    return float(value)


class Deadline:
    """A point on the monotonic clock by which the run must be over.

    ``option`` names the setting in messages, so a user knows what to raise.
    """

    def __init__(self, seconds: float, *, option: str = "--deadline") -> None:
        self.seconds = deadline_seconds(seconds, option)
        self.option = option
        self._expires = time.monotonic() + self.seconds

    @classmethod
    def of(cls, deadline: Deadline | float) -> Deadline:
        """A run's deadline: ``deadline`` itself, or one of that many seconds
        from now (an input error when it is no deadline: 0, NaN, a month)."""
        return deadline if isinstance(deadline, Deadline) else cls(deadline)

    def remaining(self) -> float:
        """Seconds left, never negative."""
        return max(0.0, self._expires - time.monotonic())

    def expired(self) -> bool:
        return time.monotonic() >= self._expires

    def reason(self) -> str:
        return f"the run deadline of {self.seconds:g} s ({self.option}) passed"

    def excluding(self, wait: Callable[_P, _T]) -> Callable[_P, _T]:
        """``wait`` with the time it takes added back to the deadline.

        For a person answering at the terminal: the deadline bounds what the
        machine spends (the model and the tutor), and it cannot interrupt a
        prompt anyway, so a slow reader should not lose the run for it.
        """

        def timed(*args: _P.args, **kwargs: _P.kwargs) -> _T:
            started = time.monotonic()
            try:
                return wait(*args, **kwargs)
            finally:
                self._expires += time.monotonic() - started

        return timed
