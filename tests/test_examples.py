"""Every bundled example gives the verdict its expected.json records."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import case_params, example_cases, load_expected

from virf.schema import Report
from virf.world.plan import load_plan_file

CASES = case_params()


def test_examples_are_present_and_complete(examples_dir: Path) -> None:
    cases = example_cases()
    assert len(cases) >= 10
    assert all(c.parent == examples_dir for c in cases)
    for case in cases:
        expected = load_expected(case)
        assert expected["status"] in ("SAFE", "UNSAFE", "UNKNOWN", "ERROR"), case.name
        assert "dangerous_step" in expected, case.name
        assert (expected["status"] == "SAFE") == ("violated_concept" not in expected), case.name


@pytest.mark.parametrize("case", CASES)
def test_verdict_matches_expected(case: Path, example_report) -> None:
    expected = load_expected(case)
    report = example_report(case.name)
    assert report.status == expected["status"]
    assert report.dangerous_step == expected["dangerous_step"]
    got = report.violated_concept.id if report.violated_concept else None
    assert got == expected.get("violated_concept")


@pytest.mark.parametrize("case", CASES)
def test_verification_is_deterministic(case: Path, example_tutor, example_report) -> None:
    again = example_tutor(case.name).verify_files(case / "scene.json", case / "plan.txt")
    assert again.to_json() == example_report(case.name).to_json()


@pytest.mark.parametrize("case", CASES)
def test_report_is_well_formed(case: Path, example_report) -> None:
    report = example_report(case.name)
    plan = load_plan_file(case / "plan.txt")
    assert report.plan == tuple(s.text for s in plan)
    assert len(report.trace) == len(plan)
    assert [t.step for t in report.trace] == list(range(1, len(plan) + 1))
    # The JSON form is the report, losslessly.
    assert Report.model_validate_json(report.to_json()) == report

    if report.status == "SAFE":
        assert report.violations == ()
        assert report.violated_concept is None
        assert report.dangerous_step is None
        assert report.questions == ()
        assert all(t.outcome == "ok" for t in report.trace)
        return

    assert report.status in ("UNSAFE", "UNKNOWN")
    assert len(report.violations) >= 1
    primary = report.violations[0]
    assert report.violated_concept is not None
    assert report.violated_concept.id == primary.id
    assert report.suggestion == primary.suggestion
    assert all(v.step == report.dangerous_step for v in report.violations)
    step = report.dangerous_step
    assert step is not None
    if step == 0:
        assert report.action is None
    else:
        assert report.action == plan[step - 1].text
        assert primary.id in report.trace[step - 1].findings
    if report.status == "UNSAFE":
        assert primary.definite
    else:
        assert not any(v.definite for v in report.violations)
        assert len(report.questions) >= 1
