"""A minimal subset by deletion: drop each item in turn, keep it out when
the test still holds.  The result is what deleting one item at a time
finds; proofs (which items suffice, which are needed) and oracles (a proof's
model answering questions) only save the tests it would ask.

:mod:`virf.verify.explain` runs it over a finding's facts and background
axioms.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable, Iterator
from dataclasses import dataclass
from typing import Generic, TypeVar

T = TypeVar("T")


@dataclass(frozen=True)
class Hint(Generic[T]):
    """A proof's items that suffice, those it names as needed (without one
    of them, what the proof was asked of does not hold: an engine's claim,
    see :attr:`virf.reasoning.Proof.needed_facts`), and an oracle: do the
    items the proof was asked of hold without some of them (None: it
    cannot tell)?"""

    suffices: Collection[T]
    needed: Collection[T] = ()
    reader: Reader[T] | None = None


@dataclass(frozen=True)
class Reader(Generic[T]):
    """A proof's oracle (:class:`virf.reasoning.Oracle`) over a search's
    items: the mask of some items (None: one it cannot leave out), and
    whether the items the proof was asked of hold without a mask's (None:
    it cannot tell)."""

    mask: Callable[[Collection[T]], int | None]
    decide: Callable[[int], bool | None]


@dataclass(frozen=True)
class _Known(Generic[T]):
    """A proof that holds: its items, those it needs, its oracle."""

    proof: set[T]
    needed: set[T]
    reader: Reader[T] | None


def checked_proof(
    items: list[T],
    prove: Callable[[list[T]], Hint[T] | None],
    holds: Callable[[list[T]], bool],
    *,
    holding: bool = False,
) -> _Known[T] | None:
    """The items of a proof of ``items`` that hold on their own, and those
    of them it needs (None when there is no proof, or it does not hold).
    With ``holding``, ``items`` are known to hold: a proof of them all is
    not asked about again."""
    found = prove(items)
    if found is None:
        return None
    kept = [x for x in items if x in found.suffices]
    answer = None
    if found.reader is not None:
        dropped = found.reader.mask([x for x in items if x not in found.suffices])
        answer = None if dropped is None else found.reader.decide(dropped)
    if answer is None:
        answer = (holding and len(kept) == len(items)) or holds(kept)
    if answer:
        return _Known(set(kept), {x for x in kept if x in found.needed}, found.reader)
    return None


def one_at_a_time(
    current: list[T],
    i: int,
    reader: Reader[T] | None,
    holds: Callable[[list[T]], bool],
) -> list[T]:
    """The deletion itself, from item ``i`` on, each question put to the
    oracle first (does ``current`` hold without some items?) and to
    ``holds`` when it cannot tell."""
    gone = 0  # the items deleted, as the oracle's mask
    while i < len(current):
        trial = current[:i] + current[i + 1 :]
        bit = reader.mask([current[i]]) if reader is not None else None
        answer = reader.decide(gone | bit) if reader is not None and bit is not None else None
        if answer is None:
            answer = holds(trial)
        if answer:
            if bit is None:
                reader = None  # an item it cannot leave out is gone: no more answers
            else:
                gone |= bit
            current = trial
        else:
            i += 1
    return current


def drop_greedily(
    items: list[T],
    holds: Callable[[list[T]], bool],
    prove: Callable[[list[T]], Hint[T] | None] | None = None,
    each: Callable[[list[T], list[T], list[bool]], Iterable[bool]] | None = None,
    first: _Known[T] | None = None,
    asked: bool = False,
) -> list[T]:
    """What is left of ``items`` after trying to drop each in turn, keeping
    it out when ``holds`` stays true: the one-at-a-time deletion, with the
    same result, usually in fewer reasoner calls (proofs need few of their
    facts; alternating needed and unneeded items cost a few more).

    ``holds`` must be monotone (true of a list, true of any list containing
    it), as entailment and inconsistency are.  Then if dropping a run of
    items at once keeps it true, dropping them one by one would too, so runs
    are tried first, doubling after a success and halving after a failure;
    an item is kept only when dropping it alone fails, the one-at-a-time
    test itself.

    ``prove(kept)`` may name items of ``kept`` that suffice (one proof's).
    When they do (one call tells), every trial that keeps them all holds
    without asking: the items outside the proof are dropped, and each of
    its items is tested alone, as one at a time would, with the items after
    it in place.  When one can go too (another proof does without it), a
    proof of what is left is asked for.  So the result is the same with any
    proofs, or none; when the proof is the result, the search costs one
    call per item of it, plus one.  ``each(kept, rest, tested)`` asks those
    tests together: for each tested item of ``rest``, does ``kept`` with the
    tested items before it and every item after it hold?  With ``asked``, the
    caller has already asked for the first proof: ``first`` is what
    :func:`checked_proof` made of it.

    A proof may also name items it needs (kept without asking), and bring
    an oracle that answers questions about lists of its items.  Once the
    oracle reads the list as holding, the rest is deleted one at a time,
    each question put to it, and to ``holds`` only when it cannot tell."""
    current = list(items)

    def proved() -> _Known[T] | None:
        return checked_proof(current, prove, holds, holding=True) if prove is not None else None

    def one_by_one(kept: list[T], rest: list[T], tested: list[bool]) -> Iterator[bool]:
        before: list[T] = []
        for k, x in enumerate(rest):
            if tested[k]:
                yield holds(kept + before + rest[k + 1 :])
                before.append(x)

    known = first if asked else proved()
    proving = known is not None  # an engine without proofs is not asked again
    i, run = 0, 1
    while i < len(current):
        if known is not None:
            if known.reader is not None and known.reader.decide(0) is True:
                return one_at_a_time(current, i, known.reader, holds)
            proof, needed = known.proof, known.needed
            rest = current[i:]
            # What the proof needs stays without asking; the others' tests
            # are asked with it in place, as one at a time would.
            sure = [x for x in rest if x in needed]
            open_ = [x for x in rest if x not in needed]
            tested = [x in proof for x in open_]
            answers: Iterator[bool] = iter(())
            if any(tested):
                ask = each or one_by_one
                answers = iter(ask(current[:i] + sure, open_, tested))
            kept = current[:i]
            for k, x in enumerate(rest):
                if x not in proof:
                    continue  # the proof is kept whole: this goes without asking
                if x not in needed and next(answers):  # another proof does without x
                    current = kept + rest[k + 1 :]
                    i = len(kept)
                    known = proved()
                    break
                kept.append(x)
            else:
                return kept
            continue
        run = min(run, len(current) - i)
        trial = current[:i] + current[i + run :]
        if holds(trial):
            current = trial
            run *= 2
            if proving:
                known = proved()
        elif run > 1:
            run //= 2
        else:
            i += 1
    return current
