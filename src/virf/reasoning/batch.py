"""Many entailment questions about one model, answered by halving.

The deletion search of an explanation asks, for each fact (or axiom) of a
proof, whether the finding survives without it, with the facts after it in
place.  Asked one by one, each question builds a model of its own; halved,
an item is added about log n times instead of n times (see
:meth:`FastEngine.entails_each`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from virf.reasoning.chase import Model


def halving(
    m: Model,
    tested: Sequence[bool],
    add: Callable[[Model, list[int]], None],
    decide: Callable[[Model], bool],
) -> list[bool]:
    """For each tested item ``i``, in order, ``decide`` on ``m`` grown with
    the tested items before ``i`` and every item after it (``m`` holds none
    of them to begin with; ``add`` grows it with some).  The items are
    halved: the first half's questions are asked with the second half
    added, the second's with the first half's tested items added, each
    rolled back after (with the rules switched off, which ``add`` may
    change)."""
    answers: dict[int, bool] = {}

    def solve(lo: int, hi: int) -> None:
        # m holds the tested items before lo and every item after hi.
        targets = [i for i in range(lo, hi + 1) if tested[i]]
        if not targets:
            return
        if len(targets) == 1 and targets[0] == hi:
            # Items lo..hi-1 are untested ones before it: left out.
            answers[hi] = decide(m)
            return
        mid = (lo + hi) // 2
        for half, chosen in (
            ((lo, mid), list(range(mid + 1, hi + 1))),
            ((mid + 1, hi), [i for i in range(lo, mid + 1) if tested[i]]),
        ):
            token, off = m.begin(), m.disabled
            try:
                add(m, chosen)
                solve(*half)
            finally:
                m.rollback(token)
                m.disabled = off

    solve(0, len(tested) - 1)
    return [answers[i] for i in range(len(tested)) if tested[i]]
