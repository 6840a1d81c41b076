"""The fast engine and the reference engine give identical reports.

Identical means the whole report (status, dangerous step, violated concepts,
triggering facts, background knowledge, questions, trace), byte for byte,
except the field naming the engine.  Checked on every example, on
SafeAgentBench reference plans, and on random scenes and plans.

``make test`` runs a subset; ``make test-full`` (``VIRF_FULL=1``) runs every
dev-split plan and a few hundred random cases.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from bench_support import SAB
from conftest import ROOT, case_params
from hypothesis import HealthCheck, given, settings
from random_worlds import scenes_and_plans

from virf.api import LogicTutor
from virf.bench.case import Case
from virf.bench.latency_cases import dev_cases, sample
from virf.schema import Report
from virf.verify.verifier import Verifier
from virf.world.plan import load_plan_file, parse_plan
from virf.world.scene import build_scene

FULL = os.environ.get("VIRF_FULL") == "1"
SAB_FILES = ["unsafe_detailed.jsonl", "safe_detailed.jsonl", "abstract.jsonl"]


def comparable(report: Report) -> str:
    data = json.loads(report.to_json())
    assert data.pop("engine") in ("fast", "hermit", "pellet")
    return json.dumps(data, sort_keys=True, indent=1)


@pytest.mark.parametrize("case", case_params())
def test_examples_identical(
    case: Path, reference_tutor: LogicTutor, paper_reference_tutor: LogicTutor, example_report
) -> None:
    fast = example_report(case.name)
    assert fast.engine == "fast"
    # The reference engine on the example's own scenario (the paper's
    # examples reproduce the paper's rules).
    reference = paper_reference_tutor if fast.scenario == "paper" else reference_tutor
    assert reference.tbox.scenario == fast.scenario
    ref = reference.verify_files(case / "scene.json", case / "plan.txt")
    assert comparable(fast) == comparable(ref)


def _dev_cases(tutor: LogicTutor) -> list[Case]:
    if not SAB.is_dir():
        pytest.skip(f"SafeAgentBench dev split not found at {SAB}")
    cases = dev_cases([SAB / f for f in SAB_FILES], tutor.tbox)
    return cases if FULL else sample(cases, 12)


def test_safeagentbench_plans_identical(tutor: LogicTutor, reference_tutor: LogicTutor) -> None:
    cases = _dev_cases(tutor)
    assert cases
    different = []
    for c in cases:
        fast = tutor.verifier.verify(c.scene, c.plan, c.requirements)
        ref = reference_tutor.verifier.verify(c.scene, c.plan, c.requirements)
        if comparable(fast) != comparable(ref):
            different.append(c.name)
    assert not different, different


@pytest.mark.parametrize("room", ["living-room", "bedroom", "bathroom"])
def test_other_rooms_plans_identical(room: str) -> None:
    """Every room's plans, verified with the room's scenario, by both engines."""
    if not (SAB / "other_rooms").is_dir():
        pytest.skip(f"the other rooms' dev split is not at {SAB / 'other_rooms'}")
    fast, ref = LogicTutor(room), LogicTutor(room, engine="reference")
    cases = dev_cases([SAB / "other_rooms" / f for f in SAB_FILES], fast.tbox, room=room)
    assert cases
    cases = cases if FULL else sample(cases, 4)
    different = [
        c.name
        for c in cases
        if comparable(fast.verifier.verify(c.scene, c.plan, c.requirements))
        != comparable(ref.verifier.verify(c.scene, c.plan, c.requirements))
    ]
    assert not different, different


def test_the_fast_engine_answered_without_falling_back(tutor: LogicTutor) -> None:
    """The dev plans are inside the fragment: the fast engine itself answered."""
    cases = _dev_cases(tutor)[:6]
    with tutor.engine.counting() as delta:  # type: ignore[attr-defined]
        for c in cases:
            tutor.verifier.verify(c.scene, c.plan, c.requirements)
    assert delta["calls"] > 0
    assert delta["fallbacks"] == 0, dict(delta)


PARALLEL_EXAMPLES = ("walkthrough", "burner-left-on", "noise-uncertainty", "safe-fridge")


@pytest.mark.parametrize(
    ("engine", "workers", "examples"),
    [
        ("fast", 2, PARALLEL_EXAMPLES),
        ("fast", 3, PARALLEL_EXAMPLES),
        # The reference engine takes seconds a plan: one plan per verdict kind
        # (a definite hazard, a question) in the default suite.
        ("reference", 2, PARALLEL_EXAMPLES if FULL else ("burner-left-on", "noise-uncertainty")),
        ("reference", 3, PARALLEL_EXAMPLES if FULL else ("burner-left-on",)),
    ],
)
def test_parallel_step_checking_gives_the_same_report(
    engine: str,
    workers: int,
    examples: tuple[str, ...],
    tutor: LogicTutor,
    reference_tutor: LogicTutor,
) -> None:
    base = tutor if engine == "fast" else reference_tutor
    parallel = Verifier(base.tbox, base.engine.fork(), workers=workers)
    for name in examples:
        case = ROOT / "examples" / name
        scene = base.scene(case / "scene.json")
        plan = load_plan_file(case / "plan.txt")
        one = base.verifier.verify(scene, plan)
        assert parallel.verify(scene, plan).to_json() == one.to_json()


# ---------------------------------------------------------------------- random scenes
RANDOM = settings(
    max_examples=250 if FULL else 12,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


def test_random_scenes_and_plans_identical(tutor: LogicTutor, reference_tutor: LogicTutor) -> None:
    vocab = tutor.tbox.vocabulary

    @RANDOM
    @given(scenes_and_plans())
    def check(case: tuple[dict[str, object], list[str]]) -> None:
        data, steps = case
        scene = build_scene(data, vocab)
        plan = parse_plan(steps)
        fast = tutor.verifier.verify(scene, plan)
        ref = reference_tutor.verifier.verify(scene, plan)
        assert comparable(fast) == comparable(ref)

    check()
