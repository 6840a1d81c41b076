"""Proofs read off the fast engine's model (:mod:`virf.reasoning.proof`).

A proof only guides the deletion search of an explanation, which tests it,
so a wrong proof could cost time but not change a report.  These tests hold
it to more: every proof suffices on its own, and reports made with proofs
equal those of the deletion search alone on random worlds (the oracle).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Collection, Iterable, Iterator, Sequence
from dataclasses import replace
from pathlib import Path

import pytest
from conftest import case_params
from hypothesis import HealthCheck, given, settings
from random_worlds import scenes_and_plans

from virf.api import LogicTutor
from virf.reasoning import Engine, Oracle, Proof
from virf.reasoning.fast import FastEngine
from virf.schema import Fact
from virf.verify.verifier import Verifier
from virf.world.plan import parse_plan
from virf.world.scene import build_scene


class SearchOnly(FastEngine):
    """The fast engine with no proofs: explanations by deletion alone."""

    def proof(
        self,
        facts: Iterable[Fact],
        concept: str,
        individual: str,
        *,
        without: Collection[str] = (),
        order: Sequence[object] = (),
        deadline: float | None = None,
    ) -> Proof | None:
        return None


class Checked:
    """A proof's oracle, each answer it gives checked by the engine."""

    def __init__(
        self,
        engine: Recording,
        oracle: Oracle,
        facts: list[Fact],
        without: Collection[str],
        order: Sequence[object],
        concept: str,
        individual: str,
    ) -> None:
        self.engine, self.oracle, self.facts = engine, oracle, facts
        self.without, self.order = frozenset(without), order
        self.concept, self.individual = concept, individual

    def mask(self, facts: Collection[Fact], axioms: Collection[str]) -> int | None:
        return self.oracle.mask(facts, axioms)

    def decide(self, removed: int) -> bool | None:
        answer = self.oracle.decide(removed)
        if answer is not None:
            out = {self.order[i] for i in range(removed.bit_length()) if removed >> i & 1}
            kept = [f for f in self.facts if f not in out]
            off = self.without | {a for a in out if isinstance(a, str)}
            assert answer == self.engine.entails(kept, self.concept, self.individual, without=off)
            self.engine.answers += 1
        return answer


class Recording(FastEngine):
    """The fast engine, checking each proof it gives as it gives it."""

    def __init__(self, *args: object, needs: bool = True, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.needs = needs  # False: proofs name nothing as needed, so batches are asked
        self.proofs = 0
        self.claims = 0  # facts and axioms named as needed, each checked
        self.answers = 0  # questions the proofs' oracles answered, each checked
        self.batches = 0  # questions answered together, each checked one by one

    def proof(
        self,
        facts: Iterable[Fact],
        concept: str,
        individual: str,
        *,
        without: Collection[str] = (),
        order: Sequence[object] = (),
        deadline: float | None = None,
    ) -> Proof | None:
        facts = list(facts)
        found = super().proof(
            facts, concept, individual, without=without, order=order, deadline=deadline
        )
        if found is not None:
            self.proofs += 1
            assert found.facts <= set(facts)
            assert not found.axioms & set(without)
            # The proof's facts entail the finding without any axiom outside
            # it, of those the explanation could leave out.
            others = frozenset(self.tbox.vocabulary.background) - found.axioms
            assert self.entails(found.facts, concept, individual, without=others | set(without))
            # What it names as needed is: the finding fails without each.
            off = frozenset(without)
            for f in found.needed_facts:
                rest = [g for g in facts if g != f]
                assert not self.entails(rest, concept, individual, without=off), f.render()
            for a in found.needed_axioms:
                assert not self.entails(facts, concept, individual, without=off | {a}), a
            self.claims += len(found.needed_facts) + len(found.needed_axioms)
            if not self.needs:
                return Proof(found.facts, found.axioms)
            if found.oracle is not None:
                oracle = Checked(self, found.oracle, facts, without, order, concept, individual)
                found = replace(found, oracle=oracle)
        return found

    def entails_each(
        self,
        kept: Sequence[Fact],
        items: Sequence[Fact],
        tested: Sequence[bool],
        concept: str,
        individual: str,
        *,
        deadline: float | None = None,
    ) -> Iterator[bool]:
        together = list(super().entails_each(kept, items, tested, concept, individual))
        self.batches += 1
        one_by_one = Engine.entails_each(self, kept, items, tested, concept, individual)
        assert together == list(one_by_one)
        return iter(together)

    def entails_each_without(
        self,
        facts: Sequence[Fact],
        dropped: Collection[str],
        items: Sequence[str],
        tested: Sequence[bool],
        concept: str,
        individual: str,
        *,
        deadline: float | None = None,
    ) -> Iterator[bool]:
        args = (facts, dropped, items, tested, concept, individual)
        together = list(super().entails_each_without(*args))
        self.batches += 1
        assert together == list(Engine.entails_each_without(self, *args))
        return iter(together)


def _report(verifier: Verifier, data: dict[str, object], steps: list[str]) -> str:
    scene = build_scene(data, verifier.tbox.vocabulary)
    report = json.loads(verifier.verify(scene, parse_plan(steps)).to_json())
    return json.dumps(report, sort_keys=True)


def same_on_random_worlds(first: Verifier, second: Verifier, examples: int) -> None:
    """The two verifiers give byte-identical reports on random scenes and plans."""

    @settings(
        max_examples=examples,
        deadline=None,
        derandomize=True,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )
    @given(scenes_and_plans())
    def check(case: tuple[dict[str, object], list[str]]) -> None:
        data, steps = case
        assert _report(first, data, steps) == _report(second, data, steps)

    check()


@pytest.fixture(scope="module")
def engines(tutor: LogicTutor) -> tuple[Verifier, Verifier, Recording]:
    recording = Recording(tutor.tbox)
    return (
        LogicTutor.over(tutor.tbox, recording).verifier,
        LogicTutor.over(tutor.tbox, SearchOnly(tutor.tbox)).verifier,
        recording,
    )


def test_reports_with_proofs_equal_the_deletion_search(
    engines: tuple[Verifier, Verifier, Recording],
) -> None:
    with_proofs, search_only, recording = engines
    same_on_random_worlds(with_proofs, search_only, 60)
    assert recording.proofs > 20  # the proofs were there to be wrong
    assert recording.claims > 50
    assert recording.answers > 100
    # Batches are now rarely asked: test_questions_answered_together checks them.


def test_questions_answered_together_equal_one_by_one(
    tutor: LogicTutor, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every batch halved on one model (the fast engine batches only larger
    ones), on random worlds and on a hazard explained through a chain of
    nested boxes; each batch is checked against one-by-one answers."""
    from virf.bench.latency_cases import hazard_chain_case

    monkeypatch.setattr("virf.reasoning.fast.BATCH_FROM", 1)
    recording = Recording(tutor.tbox, needs=False)
    together = LogicTutor.over(tutor.tbox, recording).verifier
    search_only = LogicTutor.over(tutor.tbox, SearchOnly(tutor.tbox)).verifier
    chain = hazard_chain_case(12, tutor.tbox)
    reports = [v.verify(chain.scene, chain.plan).to_json() for v in (together, search_only)]
    assert reports[0] == reports[1]
    assert '"HardObjectDroppedOntoFragileDanger"' in reports[0]
    same_on_random_worlds(together, search_only, 25)
    assert recording.batches > 10


@pytest.mark.parametrize("case", case_params())
def test_examples_with_proofs_equal_the_deletion_search(
    case: Path, example_tutor: Callable[[str], LogicTutor]
) -> None:
    tbox = example_tutor(case.name).tbox
    reports = [
        LogicTutor.over(tbox, engine).verify_files(case / "scene.json", case / "plan.txt")
        for engine in (Recording(tbox), SearchOnly(tbox))
    ]
    assert reports[0].to_json() == reports[1].to_json()
