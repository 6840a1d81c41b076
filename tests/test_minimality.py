"""The causal chain in a report is a real, minimal proof.

The reported triggering facts (plus any catalogue defaults the report lists as
background) must entail the violated concept for the reported individual, and
dropping any one of them must break the entailment.  These are checked by
asking the reasoner again, independently of how the verifier minimised.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import case_params, inst, load_expected

from virf.schema import Fact, Report, Violation

NO_PROOF_PHASES = {"precondition", "inconsistency", "missing-object"}
NO_PROOF_CONCEPTS = {"MissingObject", "InconsistentWorldModel"}


def _has_proof(case: Path) -> bool:
    expected = load_expected(case)
    concept = expected.get("violated_concept")
    return (
        expected["status"] != "SAFE"
        and concept not in NO_PROOF_CONCEPTS
        and not str(concept).startswith("Precondition_")
    )


def proof_facts(v: Violation) -> list[Fact]:
    """The triggering facts plus the catalogue defaults listed as background."""
    facts = [Fact.from_triple(t) for t in v.triggering_facts]
    for b in v.background:
        if b.id.startswith("DEFAULT-"):
            subject, material = b.id.removeprefix("DEFAULT-").rsplit("-", 1)
            facts.append(Fact(subject, "hasMaterial", material))
    return facts


def _assert_minimal_proof(tutor, v: Violation) -> None:
    facts = proof_facts(v)
    assert facts
    assert len(set(facts)) == len(facts)
    assert tutor.engine.entails(facts, v.name, v.subject), "the chain does not prove the finding"
    for i, dropped in enumerate(facts):
        rest = facts[:i] + facts[i + 1 :]
        assert not tutor.engine.entails(rest, v.name, v.subject), (
            f"not minimal: still entailed without {dropped.render()}"
        )


@pytest.mark.parametrize("case", case_params(_has_proof))
def test_triggering_facts_are_a_minimal_proof(case: Path, example_tutor, example_report) -> None:
    report = example_report(case.name)
    v = report.violations[0]
    assert v.phase not in NO_PROOF_PHASES
    assert v.triggering_facts
    _assert_minimal_proof(example_tutor(case.name), v)


def test_minimal_proof_with_catalogue_default(tutor) -> None:
    # A mug states no material: the catalogue default (ceramic, hence fragile)
    # is what makes dropping it dangerous, so it must appear in the proof.
    report = tutor.verify({"instances": [inst("Mug", "Mug_1")]}, ["pick Mug_1", "drop"])
    assert report.status == "UNSAFE"
    v = report.violations[0]
    assert v.id == "FragileOrSharpObjectFallsDanger"
    assert "DEFAULT-Mug_1-Ceramic" in [b.id for b in v.background]
    assert Fact("Mug_1", "hasMaterial", "Ceramic") in proof_facts(v)
    # Defaults are background, not scene facts: they are not triggering facts.
    assert all(t.predicate != "hasMaterial" for t in v.triggering_facts)
    _assert_minimal_proof(tutor, v)


def test_a_proof_read_back_from_json_is_the_same_proof(paper_tutor, example_report) -> None:
    # Its proof holds an open-world closure: nothing is on the burner.
    tutor = paper_tutor
    report = example_report("burner-left-on-open-world")
    back = Report.model_validate_json(report.to_json()).violations[0]
    facts = proof_facts(back)
    assert facts == proof_facts(report.violations[0])
    assert Fact.closure("StoveBurner_1", "supports", []) in facts
    _assert_minimal_proof(tutor, back)


def test_contradiction_is_minimal(tutor, example_report) -> None:
    report = example_report("noise-contradiction")
    v = report.violations[0]
    assert v.phase == "inconsistency"
    facts = [Fact.from_triple(t) for t in v.triggering_facts]
    assert len(facts) >= 2
    assert not tutor.engine.consistent(facts)
    for i in range(len(facts)):
        assert tutor.engine.consistent(facts[:i] + facts[i + 1 :])


def test_walkthrough_needs_pot_material_axiom(paper_tutor, example_report) -> None:
    tutor = paper_tutor
    v = example_report("walkthrough").violations[0]
    assert "KIT-Pot-material-Metal" in [b.id for b in v.background]
    facts = proof_facts(v)
    assert tutor.engine.entails(facts, v.name, v.subject)
    assert not tutor.engine.entails(facts, v.name, v.subject, without={"KIT-Pot-material-Metal"})
    # Removing an unrelated background axiom changes nothing.
    assert tutor.engine.entails(facts, v.name, v.subject, without={"KIT-Knife-property-Sharp"})


@pytest.mark.parametrize("case", case_params(_has_proof))
def test_listed_background_is_sufficient_and_minimal(
    case: Path, example_tutor, example_report
) -> None:
    tutor = example_tutor(case.name)
    vocab = tutor.tbox.vocabulary
    # The TBox may prove a fact in two ways (a knife is a physical object both as
    # cutlery and as something made of metal), so minimality is relative to the
    # background axioms the report lists: with every *other* background axiom
    # removed the proof still goes through, and each listed one is then needed.
    v = example_report(case.name).violations[0]
    facts = proof_facts(v)
    listed = {b.id for b in v.background if not b.id.startswith("DEFAULT-")}
    assert listed <= set(vocab.background)
    others = set(vocab.background) - listed
    assert tutor.engine.entails(facts, v.name, v.subject, without=others)
    for ident in sorted(listed):
        assert not tutor.engine.entails(facts, v.name, v.subject, without=others | {ident}), ident
