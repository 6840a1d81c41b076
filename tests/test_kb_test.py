"""``virf kb test``: every rule's minimal pairs pass in every scenario, the
catalogue sweeps follow the types' properties, and the test can fail."""

from __future__ import annotations

import json
import re

import pytest

from virf.errors import InputError
from virf.ontology.tbox import load_tbox, scenario_names
from virf.reasoning import make_engine
from virf.verify.kbtest import check_pair, run_kb_test
from virf.verify.twins import MinimalPair, read_pair, scene_data
from virf.verify.verifier import Verifier


@pytest.mark.parametrize("scenario", scenario_names())
def test_every_rule_passes_its_minimal_pairs(scenario: str) -> None:
    tbox = load_tbox(scenario)
    result = run_kb_test(tbox, make_engine("fast", tbox), sweeps=False)
    assert not result.failures, [(p.rule, p.index, p.problem) for p in result.failures]
    assert all(p.index for p in result.pairs)  # every rule has at least one pair


def test_the_household_rules_pass_the_sweeps() -> None:
    tbox = load_tbox("household")
    result = run_kb_test(tbox, make_engine("fast", tbox))
    assert result.sweep_cases > 300
    assert not result.sweeps, [(f.sweep, f.case, f.expected, f.got) for f in result.sweeps[:10]]


def test_a_pair_swapped_with_its_twin_fails() -> None:
    # The test can fail: each rule's twin, taken as its world, must not pass.
    tbox = load_tbox("kitchen")
    engine = make_engine("fast", tbox)
    vocab = tbox.vocabulary
    checked = 0
    for name in sorted(vocab.uscs):
        verifier = Verifier(tbox, engine, explain=False, uscs=[name])
        for i, text in enumerate(vocab.annotation(name, "twin"), start=1):
            pair = read_pair(name, text)
            swapped = MinimalPair(name, text, pair.twin, pair.twin_plan, pair.new, pair.old)
            assert not check_pair(verifier, swapped, i, vocab.uscs[name].kind).ok, name
            checked += 1
    assert checked >= len(vocab.uscs)


def test_a_rule_keyed_on_a_name_fails_the_sweeps(tmp_path) -> None:  # type: ignore[no-untyped-def]
    # A rule that flags throwing a pillow by name gives a verdict the pillow's
    # properties (soft) do not call for.
    module = tmp_path / "pillow.omn"
    module.write_text(
        """Prefix: : <http://virf.dev/ontology#>
Prefix: rdfs: <http://www.w3.org/2000/01/rdf-schema#>
Ontology: <http://example.org/pillow>
    Import: <http://virf.dev/ontology/scenario-kitchen>
AnnotationProperty: :id
AnnotationProperty: :kind
AnnotationProperty: :category
AnnotationProperty: :dangerLevel
AnnotationProperty: :safetyWarning
AnnotationProperty: :triggerReason
AnnotationProperty: :suggestion
AnnotationProperty: :source
AnnotationProperty: :checkAt
AnnotationProperty: :twin
Class: :Pillow
Class: :ThrowAction
ObjectProperty: :hasPatient
Class: :UnsafeStateConcept
Class: :PillowThrownDanger
    Annotations: :id "PillowThrownDanger", :kind "action-based", :category "Breakage and Dropping",
        :dangerLevel "low", rdfs:comment "A pillow is thrown.", :safetyWarning "w", :triggerReason "t",
        :suggestion "s", :source "a test", :checkAt "always",
        :twin "Pillow_1: Pillow | pick Pillow_1; throw | throw => drop"
    EquivalentTo: :ThrowAction and (:hasPatient some :Pillow)
    SubClassOf: :UnsafeStateConcept
""",
        encoding="utf-8",
    )
    tbox = load_tbox("kitchen", extra_modules=(str(module),))
    result = run_kb_test(tbox, make_engine("fast", tbox))
    assert not result.failures  # its pair passes: a pair alone does not catch a name
    assert any(f.sweep == "throw" and f.case == "Pillow" for f in result.sweeps)


def test_twins_are_read_strictly() -> None:
    with pytest.raises(InputError, match=re.escape("WORLD | PLAN | OLD => NEW")):
        read_pair("R", "A_1: Apple | -")
    with pytest.raises(InputError, match="does not state once"):
        read_pair("R", "A_1: Apple | - | A_1: Pear => A_1: Apple")
    with pytest.raises(InputError, match="changes nothing"):
        read_pair("R", "A_1: Apple | - | A_1: Apple => A_1: Apple")
    pair = read_pair("R", "A_1: Apple; closed: contains | eat A_1 | - => A_1 hasState sliced")
    assert pair.twin[-1] == "A_1 hasState sliced"
    data = scene_data(pair.world)
    assert data["closed_world"] == ["contains"]
    assert data["instances"] == [{"instance_name": "A_1", "class_name": "Apple"}]


def test_kb_test_from_the_terminal(cli) -> None:  # type: ignore[no-untyped-def]
    r = cli("kb", "test", "--scenario", "paper", "--json")
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    assert out["passed"] and out["pairs"] == out["rules"] and out["sweep_cases"] == 0
    r = cli("kb", "test")
    assert r.exit_code == 0, r.output
    assert "0 failing; sweeps:" in r.stdout and "All rules pass" in r.stdout


def test_kb_test_fails_the_paper_s_verb_rules_when_swept(cli) -> None:  # type: ignore[no-untyped-def]
    # The paper's ThrowActionDanger fires on the verb: swept, a thrown apple is
    # called unsafe, and the command says so and exits 1.
    r = cli("kb", "test", "--scenario", "paper", "--sweeps", "--json")
    assert r.exit_code == 1, r.output
    out = json.loads(r.stdout)
    assert not out["passed"] and not out["pair_failures"]
    apple = [f for f in out["sweep_failures"] if (f["sweep"], f["case"]) == ("throw", "Apple")]
    assert apple and apple[0]["expected"] == "SAFE" and "ThrowActionDanger" in apple[0]["got"]
    r = cli("kb", "test", "--scenario", "paper")
    assert r.exit_code == 0 and "sweeps skipped" in r.stdout
