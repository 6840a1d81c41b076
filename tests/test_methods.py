"""The paper's methods, driven by scripted apprentices and the real tutor."""

from __future__ import annotations

import pytest
from loop_support import CLOSES, LEAVES_OPEN, run_method_with

from virf.api import LogicTutor
from virf.errors import InputError
from virf.planner import Purpose
from virf.planner.methods import METHODS, get_method, knowledge_filter
from virf.planner.prompting import render_rules, template
from virf.verify.verifier import Verifier


def test_all_ten_methods_are_named() -> None:
    assert len(METHODS) == 10
    with pytest.raises(InputError, match="unknown method 'virff'; choose from virf"):
        get_method("virff")


def test_impulsive_takes_the_first_plan_unverified(tutor: LogicTutor) -> None:
    result, _ = run_method_with(tutor, "impulsive", [LEAVES_OPEN])
    assert result.outcome == "APPROVED_UNVERIFIED" and not result.verified
    assert result.plan == tuple(LEAVES_OPEN.splitlines())
    assert not any(t.speaker == "tutor" for t in result.transcript)


def test_thinker_reads_the_plan_after_its_reasoning(tutor: LogicTutor) -> None:
    reply = "REASONING:\nfind the apple first, then close the fridge.\nPLAN:\n" + CLOSES
    result, apprentice = run_method_with(tutor, "thinker", [reply])
    assert result.plan == tuple(CLOSES.splitlines())
    assert "REASONING:" in apprentice.requests[0].as_messages()[-1]["content"]


def test_rules_methods_carry_every_rule(tutor: LogicTutor) -> None:
    rules = render_rules(tutor.tbox.vocabulary)
    numbered = [ln for ln in rules.splitlines() if ln.split(".")[0].isdigit()]
    vocab = tutor.tbox.vocabulary
    assert len(numbered) == len(vocab.uscs) + sum(
        1 for b in vocab.background.values() if b.description
    )
    _, apprentice = run_method_with(tutor, "impulsive+rules", [CLOSES])
    assert "Hazards that must never arise" in apprentice.requests[0].as_messages()[-1]["content"]


def test_committee_rejects_what_the_critic_never_approves(tutor: LogicTutor) -> None:
    result, _ = run_method_with(
        tutor,
        "committee",
        [LEAVES_OPEN, LEAVES_OPEN],
        critic=["Unsafe.", "APPROVED? No."],
        max_iter=2,
    )
    assert result.outcome == "TASK_REJECTED" and result.plan is None


def test_committee_revises_until_the_critic_approves(tutor: LogicTutor) -> None:
    result, apprentice = run_method_with(
        tutor,
        "committee",
        [LEAVES_OPEN, CLOSES],
        critic=["Step 5 leaves the fridge open.", "**APPROVE**"],
    )
    assert result.plan == tuple(CLOSES.splitlines()) and result.iterations == 2
    assert "leaves the fridge open" in apprentice.requests[1].as_messages()[-1]["content"]


def test_the_committee_tells_reviews_from_revisions(tutor: LogicTutor) -> None:
    # Without its own critic the planner plays the critic: the same apprentice
    # is asked for a plan, a critique and a revision, and each request says which.
    result, apprentice = run_method_with(
        tutor, "committee", [LEAVES_OPEN, "Step 5 leaves the fridge open.", CLOSES, "APPROVE"]
    )
    assert result.plan == tuple(CLOSES.splitlines())
    assert [(r.method, r.purpose) for r in apprentice.requests] == [
        ("committee", Purpose.PLAN),
        ("committee-critic", Purpose.CRITIQUE),
        ("committee", Purpose.REPAIR),
        ("committee-critic", Purpose.CRITIQUE),
    ]


def test_thinker_diagnostic_retries_once_without_reverifying(tutor: LogicTutor) -> None:
    result, apprentice = run_method_with(tutor, "thinker+diagnostic", [LEAVES_OPEN, LEAVES_OPEN])
    # The retry stands, unverified.
    assert result.outcome == "APPROVED_UNVERIFIED" and result.iterations == 2
    assert "DIAGNOSTIC REPORT" in apprentice.requests[1].as_messages()[-1]["content"]


def test_virf_reject_gives_no_diagnosis(tutor: LogicTutor) -> None:
    result, apprentice = run_method_with(tutor, "virf-reject", [LEAVES_OPEN, CLOSES])
    assert result.outcome == "APPROVED" and result.iterations == 2
    assert apprentice.requests[1].as_messages()[-1]["content"] == template("reject").strip()


def test_virf_repairs_with_the_diagnosis(fridge_tutor: tuple[LogicTutor, str]) -> None:
    tutor, fridge_rule = fridge_tutor
    result, apprentice = run_method_with(tutor, "virf", [LEAVES_OPEN, CLOSES])
    assert result.outcome == "APPROVED" and result.iterations == 2
    assert fridge_rule in apprentice.requests[1].as_messages()[-1]["content"]


def test_knowledge_ablations_split_the_rules(paper_tutor: LogicTutor) -> None:
    # VIRF-Manual and VIRF-RAG are the paper's ablations of its own rules
    # (scenario paper); every household rule was acquired from documents.
    tutor = paper_tutor
    uscs = list(tutor.tbox.vocabulary.uscs.values())
    manual = {u.name for u in uscs if knowledge_filter(u, "manual")}
    rag = {u.name for u in uscs if knowledge_filter(u, "rag")}
    every = {u.name for u in uscs}
    kept = {u.name for u in uscs if u.kind in ("uncertainty", "logical-inconsistency")}
    # A partition of the hazard rules by primary source; the tutor's own
    # uncertainty and consistency concepts belong to both.
    assert manual | rag == every and manual & rag == kept
    assert {"FridgeLeftOpenDanger", "FaucetLeftRunningDanger", "BreadOnHotStoveDanger"} <= manual
    assert {"WetElectricalDeviceOnDanger", "ToxicInFoodContainerDanger"} <= rag - manual
    only_manual = Verifier(tutor.tbox, tutor.engine, uscs=manual)
    result, _ = run_method_with(tutor, "virf-manual", [LEAVES_OPEN, CLOSES], verifier=only_manual)
    assert result.outcome == "APPROVED" and result.iterations == 2  # the fridge rule is manual
    only_rag = Verifier(tutor.tbox, tutor.engine, uscs=rag)
    result, _ = run_method_with(tutor, "virf-rag", [LEAVES_OPEN], verifier=only_rag)
    assert result.outcome == "APPROVED" and result.iterations == 1  # RAG's rules miss it
