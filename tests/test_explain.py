"""Minimal explanations: trying runs of deletions first finds what deleting
one item at a time finds, whenever the test is monotone (as entailment is)."""

from __future__ import annotations

from collections.abc import Callable, Collection

from hypothesis import given, settings
from hypothesis import strategies as st

from virf.verify.deletion import Hint, Reader, drop_greedily


def one_at_a_time(items: list[int], holds: Callable[[list[int]], bool]) -> list[int]:
    """The deletion the explainer used before runs were tried."""
    current = list(items)
    i = 0
    while i < len(current):
        trial = current[:i] + current[i + 1 :]
        if holds(trial):
            current = trial
        else:
            i += 1
    return current


def needing(needs: list[frozenset[int]]) -> Callable[[list[int]], bool]:
    """The monotone test: does a list contain one of ``needs``?"""

    def holds(kept: list[int]) -> bool:
        return any(need <= set(kept) for need in needs)

    return holds


def counting(holds: Callable[[list[int]], bool], calls: list[int]) -> Callable[[list[int]], bool]:
    def counted(kept: list[int]) -> bool:
        calls.append(len(kept))
        return holds(kept)

    return counted


@st.composite
def monotone_tests(draw: st.DrawFn) -> tuple[list[int], list[frozenset[int]]]:
    """Items, and the minimal sets of which a list must contain one (a monotone test)."""
    n = draw(st.integers(0, 14))
    items = list(range(n))
    needs = draw(
        st.lists(
            st.frozensets(st.sampled_from(items), min_size=1, max_size=4)
            if items
            else st.just(frozenset()),
            min_size=1,
            max_size=3,
        )
    )
    return items, needs


@settings(max_examples=300, deadline=None, derandomize=True)
@given(monotone_tests())
def test_runs_of_deletions_find_the_one_at_a_time_result(
    case: tuple[list[int], list[frozenset[int]]],
) -> None:
    items, needs = case

    holds = needing(needs)

    if not holds(items):
        return  # the explainer only minimises what holds
    calls: list[int] = []
    counted = counting(holds, calls)

    assert drop_greedily(items, counted) == one_at_a_time(items, holds)
    assert len(calls) <= 2 * len(items) + 1


@settings(max_examples=300, deadline=None, derandomize=True)
@given(monotone_tests(), st.data())
def test_proofs_as_hints_change_nothing_but_the_calls(
    case: tuple[list[int], list[frozenset[int]]], data: st.DataObject
) -> None:
    """Whatever a proof names (enough, too little, items not in the list,
    nothing), the search keeps what deleting one at a time keeps."""
    items, needs = case

    holds = needing(needs)

    if not holds(items):
        return
    answers = data.draw(
        st.lists(st.one_of(st.none(), st.frozensets(st.integers(-2, 16))), max_size=6)
    )
    asked: list[list[int]] = []

    def prove(kept: list[int]) -> Hint[int] | None:
        asked.append(list(kept))
        answer = answers[len(asked) - 1] if len(asked) <= len(answers) else None
        return None if answer is None else Hint(answer)

    assert drop_greedily(items, holds, prove) == one_at_a_time(items, holds)

    def each(kept: list[int], rest: list[int], tested: list[bool]) -> list[bool]:
        """The tests of a proof's items, asked together (as the spec says)."""
        return [
            holds(
                kept + [y for y, t in zip(rest[:k], tested[:k], strict=True) if t] + rest[k + 1 :]
            )
            for k in range(len(rest))
            if tested[k]
        ]

    asked.clear()
    assert drop_greedily(items, holds, prove, each) == one_at_a_time(items, holds)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(monotone_tests())
def test_a_proof_of_the_result_costs_one_call_per_item_plus_one(
    case: tuple[list[int], list[frozenset[int]]],
) -> None:
    items, needs = case

    holds = needing(needs)

    if not holds(items):
        return
    result = one_at_a_time(items, holds)
    calls: list[int] = []
    counted = counting(holds, calls)

    assert drop_greedily(items, counted, lambda kept: Hint(frozenset(result))) == result
    assert len(calls) <= len(result) + 1


@settings(max_examples=300, deadline=None, derandomize=True)
@given(monotone_tests(), st.data())
def test_items_a_proof_needs_are_kept_without_asking(
    case: tuple[list[int], list[frozenset[int]]], data: st.DataObject
) -> None:
    """A proof may name items without which what it was asked of fails:
    some of the truly needed ones, never one that is not.  The search keeps
    them without a call, and finds what deleting one at a time finds."""
    items, needs = case

    holds = needing(needs)

    if not holds(items):
        return
    result = one_at_a_time(items, holds)

    def prove(kept: list[int]) -> Hint[int] | None:
        proof = one_at_a_time(kept, holds)
        needed = [x for x in kept if not holds([y for y in kept if y != x])]
        return Hint(
            frozenset(proof),
            frozenset(data.draw(st.sets(st.sampled_from(needed))) if needed else ()),
        )

    calls: list[int] = []
    assert drop_greedily(items, counting(holds, calls), prove) == result
    without: list[int] = []
    assert (
        drop_greedily(
            items,
            counting(holds, without),
            lambda kept: Hint(frozenset(one_at_a_time(kept, holds))),
        )
        == result
    )
    assert len(calls) <= len(without)

    def proves_all(kept: list[int]) -> Hint[int] | None:
        needed = [x for x in kept if not holds([y for y in kept if y != x])]
        return Hint(frozenset(one_at_a_time(kept, holds)), frozenset(needed))

    calls.clear()
    assert drop_greedily(items, counting(holds, calls), proves_all) == result
    if all(not holds([y for y in items if y != x]) for x in result):
        assert len(calls) <= 1  # the proof is tested once, if it leaves anything out


@settings(max_examples=300, deadline=None, derandomize=True)
@given(monotone_tests(), st.data())
def test_a_proofs_oracle_answers_for_the_engine(
    case: tuple[list[int], list[frozenset[int]]], data: st.DataObject
) -> None:
    """An oracle that answers some questions rightly and cannot tell the
    others (it cannot leave some items out at all): the search finds what
    one-at-a-time deletion finds, and asks ``holds`` only what the oracle
    could not tell."""
    items, needs = case

    holds = needing(needs)

    if not holds(items):
        return
    unknown = data.draw(st.sets(st.sampled_from(items))) if items else set()
    blind = data.draw(st.sets(st.sampled_from(items))) if items else set()
    told: list[int] = []

    def prove(kept: list[int]) -> Hint[int] | None:
        base = list(kept)

        def mask(xs: Collection[int]) -> int | None:
            if any(x in blind for x in xs):
                return None
            return sum(1 << base.index(x) for x in set(xs))

        def decide(removed: int) -> bool | None:
            rest = [x for k, x in enumerate(base) if not removed >> k & 1]
            if any(x in unknown for k, x in enumerate(base) if removed >> k & 1):
                return None
            told.append(removed)
            return holds(rest)

        return Hint(frozenset(one_at_a_time(kept, holds)), (), Reader(mask, decide))

    calls: list[int] = []
    assert drop_greedily(items, counting(holds, calls), prove) == one_at_a_time(items, holds)
    if not unknown and not blind:
        assert len(calls) == 0  # the oracle told everything
