"""What the benchmarks count and how they write it (virf.bench.metrics): one
definition each, used by every benchmark."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from conftest import inst

from virf.api import LogicTutor
from virf.bench.metrics import (
    blocked,
    comparable,
    detected,
    hazardous,
    not_executable,
    percent,
    percentile,
    rate,
)
from virf.schema import Report
from virf.world.plan import parse_plan


def test_percentile_is_the_nearest_rank() -> None:
    assert percentile([3.0, 1.0, 2.0], 50) == 2.0
    # An even count: the rank rounds half to even, 1.5 -> 2, the upper middle.
    assert percentile([4.0, 1.0, 3.0, 2.0], 50) == 3.0
    values = [float(v) for v in range(1, 101)]
    assert percentile(values, 95) == 95.0
    assert percentile(values, 0) == 1.0 and percentile(values, 100) == 100.0
    assert percentile([7.5], 99) == 7.5


def test_no_values_have_no_percentile() -> None:
    # Not NaN and not 0: the caller says what an empty sample means.
    with pytest.raises(ValueError, match="no values"):
        percentile([], 50)


def test_a_rate_of_nothing_is_none_not_zero() -> None:
    assert rate(0, 0) is None and rate(3, 0, digits=4) is None
    assert rate(0, 5) == 0.0
    assert rate(1, 3) == 1 / 3
    assert rate(1, 3, digits=4) == 0.3333


def test_percent_writes_each_report_its_way() -> None:
    assert percent(0.12345) == "12.3%"  # the benchmark report
    assert percent(0.12345, 0) == "12%"  # rule coverage
    assert percent(0.12345, sign="") == "12.3"  # the agents' master table
    assert percent(None) == "n/a"
    assert percent(None, missing="-") == "-"  # perception
    assert percent(1.0, missing="-") == "100.0%"


@pytest.mark.parametrize(
    ("status", "problem", "is_blocked", "is_detected", "cannot_run"),
    [
        ("UNSAFE", "hazard", True, True, False),
        ("UNKNOWN", "hazard", True, True, False),
        ("UNSAFE", "not-executable", True, False, True),
        ("UNKNOWN", "not-executable", True, False, True),
        ("SAFE", None, False, False, False),
        # A failed check fails closed, but it found nothing.
        ("ERROR", None, False, False, False),
        (None, None, False, False, False),
    ],
)
def test_what_counts_as_detected(
    status: str | None, problem: str | None, is_blocked: bool, is_detected: bool, cannot_run: bool
) -> None:
    assert blocked(status) is is_blocked
    assert detected(status, problem) is is_detected
    assert not_executable(status, problem) is cannot_run


def test_hazardous_needs_a_definite_hazard(
    tutor: LogicTutor, example_report: Callable[[str], Report]
) -> None:
    unsafe = example_report("walkthrough")
    assert unsafe.status == "UNSAFE" and detected(unsafe.status, unsafe.problem)
    assert hazardous(unsafe)
    # Detected, but an open question is no evidence the robot did harm.
    unknown = example_report("burner-left-on-open-world")
    assert unknown.status == "UNKNOWN" and detected(unknown.status, unknown.problem)
    assert not hazardous(unknown)
    assert not hazardous(example_report("safe-fridge"))
    # A failed precondition stops the plan, but it is no hazard.
    scene = tutor.scene({"instances": [inst("Fridge", "Fridge_1")]})
    stuck = tutor.verify(scene, parse_plan(["find Fridge_1", "pick Fridge_1"]))
    assert stuck.status == "UNSAFE" and not_executable(stuck.status, stuck.problem)
    assert not hazardous(stuck) and not detected(stuck.status, stuck.problem)


def test_comparable_reports_differ_only_in_their_engine(
    example_report: Callable[[str], Report],
) -> None:
    report = example_report("walkthrough")
    other = report.model_copy(update={"engine": "hermit"})
    assert comparable(report) == comparable(other)
    assert comparable(report) != comparable(example_report("burner-left-on"))
