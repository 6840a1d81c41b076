"""The readable report and the paper's feedback prompt for the LLM planner."""

from __future__ import annotations

import re

from virf.render.feedback import feedback_prompt, involved_objects
from virf.render.text import render_report


def _section(prompt: str, title: str) -> str:
    match = re.search(rf"\[{re.escape(title)}\]\n(.*?)(?:\n\n|\Z)", prompt, re.S)
    assert match, f"no [{title}] section"
    return match.group(1)


def test_walkthrough_feedback_prompt(example_report, paper_tutor) -> None:
    report = example_report("walkthrough")  # the paper's walkthrough, on its rules
    prompt = feedback_prompt(report)
    usc = paper_tutor.tbox.vocabulary.uscs["UnsafeMicrowaveUsage"]
    assert "STEP 7" in prompt
    assert "turn_on(TestMicrowave_Action)" in _section(prompt, "FAILURE ANALYSIS")
    assert "Rule ID: UnsafeMicrowaveUsage" in _section(prompt, "VIOLATED SAFETY RULE")
    assert f"Danger Level: {usc.danger_level}" in prompt
    assert usc.safety_warning in prompt
    assert usc.trigger_reason in _section(prompt, "CAUSAL EXPLANATION")
    assert usc.suggestion in _section(prompt, "SUGGESTED CORRECTION")
    objects = _section(prompt, "INVOLVED OBJECTS").rsplit(":", 1)[1]
    assert [o.strip() for o in objects.split(",")] == ["TestMicrowave_Action", "TestPot_Action"]
    # The knife near the microwave is not part of the causal chain.
    assert "TestKnife_Action" not in prompt
    assert "TASK_ABORT" in prompt


def test_causal_message_cites_facts_and_background(example_report) -> None:
    v = example_report("walkthrough").violations[0]
    for t in v.triggering_facts:
        assert t.subject in v.message
    assert all(b.text in v.message for b in v.background)
    assert v.message.endswith(f"Hence {v.subject} is an instance of {v.name}.")


def test_safe_report_has_no_diagnosis(example_report) -> None:
    prompt = feedback_prompt(example_report("pedagogical-refined"))
    assert "passed" in prompt
    assert "STEP" not in prompt


def test_initial_state_feedback(example_report) -> None:
    prompt = feedback_prompt(example_report("challenge-child"))
    assert "STEP 0" in prompt
    assert "initial state" in prompt
    assert "Toddler_1" in _section(prompt, "INVOLVED OBJECTS")


def test_render_report_shows_causal_chain(example_report) -> None:
    report = example_report("walkthrough")
    text = render_report(report, title="walkthrough")
    assert text.startswith("== walkthrough\n")
    assert "Verdict: UNSAFE at step 7 (turn_on(TestMicrowave_Action))" in text
    assert "Triggering facts (minimal):" in text
    for t in report.violations[0].triggering_facts:
        assert f"- {t.subject} {t.predicate} {t.object}" in text
    assert "Background knowledge used:" in text
    assert "KIT-Pot-material-Metal" in text
    step7 = next(line for line in text.splitlines() if " 7. turn_on(TestMicrowave_Action)" in line)
    assert "<- " in step7 and "UnsafeMicrowaveUsage" in step7
    # One trace line per plan step.
    assert len(re.findall(r"^\s+[ !?x-]\s+\d+\. ", text, re.M)) == len(report.plan)


def test_render_marks_assumptions_and_questions(example_report) -> None:
    report = example_report("burner-left-on-open-world")
    text = render_report(report)
    assert "[needs confirmation]" in text
    assert "(assumed)" in text
    assert "Questions for the user:" in text
    for q in report.questions:
        assert q.text.split()[0] in text


def test_render_stopped_plan(example_report) -> None:
    text = render_report(example_report("noise-omission"))
    assert "Verdict: UNKNOWN at step 1" in text
    assert "not simulated" in text


def test_involved_objects_lists_subject_first(example_report) -> None:
    v = example_report("challenge-chemical").violations[0]
    names = involved_objects(v)
    assert names[0] == v.subject
    assert len(names) == len(set(names))
    assert set(names) == {"AmmoniaCleaner_1", "BleachCleaner_1"}
