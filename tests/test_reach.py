"""Work kept between steps and between verifications changes no answer.

* A step's classification takes the previous step's answers where the change
  between the two steps' models cannot reach (:mod:`virf.reasoning.prior`):
  every step's classes equal those of a fast engine that classifies the
  step's facts from nothing.
* The model of what a plan's steps share is kept after the verification,
  rolled back to what later ones share (:mod:`virf.reasoning.kept`): plans
  verified one after another in the same scene, and in other scenes between
  them, give the reports a new engine gives each of them.
"""

from __future__ import annotations

import json
from collections.abc import Sequence

import pytest
from bench_support import SAB
from hypothesis import HealthCheck, given, settings
from random_worlds import scenes_and_plans

from virf.api import LogicTutor
from virf.bench.latency_cases import dev_cases
from virf.reasoning import make_engine
from virf.schema import Report
from virf.world.plan import PlanStep, parse_plan
from virf.world.scene import Scene, build_scene

RANDOM = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _report(report: Report) -> str:
    return json.dumps(json.loads(report.to_json()), sort_keys=True)


def _steps_as_from_nothing(tutor: LogicTutor, scene: Scene, plan: Sequence[PlanStep]) -> None:
    """Every step classified on the shared model, after the step before it,
    as a fast engine classifies the step's facts alone."""
    tbox = tutor.tbox
    concepts = sorted(tbox.vocabulary.uscs)
    snapshots = tutor.verifier.snapshots(scene, plan)
    engine, fresh = make_engine("fast", tbox), make_engine("fast", tbox)
    first, *rest = snapshots
    shared = frozenset(set(first).intersection(*rest))
    with engine.sharing(shared):
        for k, snapshot in enumerate(snapshots):
            got = engine.classify_shared(shared, set(snapshot) - shared, concepts)
            assert got == fresh.classify(snapshot.keys(), concepts), f"step {k}"


def test_each_step_classified_as_from_nothing(tutor: LogicTutor) -> None:
    @RANDOM
    @given(scenes_and_plans())
    def check(case: tuple[dict[str, object], list[str]]) -> None:
        data, steps = case
        scene = build_scene(data, tutor.tbox.vocabulary)
        _steps_as_from_nothing(tutor, scene, parse_plan(steps))

    check()


def test_dev_plans_steps_classified_as_from_nothing(tutor: LogicTutor) -> None:
    # Their scenes are the ones where a step's change and an earlier answer
    # meet: random worlds of a few objects rarely keep an answer the change
    # then overturns.
    if not SAB.is_dir():
        pytest.skip(f"SafeAgentBench dev split not found at {SAB}")
    files = [SAB / f for f in ("unsafe_detailed.jsonl", "safe_detailed.jsonl", "abstract.jsonl")]
    for case in dev_cases(files, tutor.tbox):
        _steps_as_from_nothing(tutor, case.scene, case.plan)


def test_plans_in_one_scene_after_another_as_with_a_new_engine(tutor: LogicTutor) -> None:
    tbox = tutor.tbox
    kept = LogicTutor.over(tbox, make_engine("fast", tbox)).verifier

    @RANDOM
    @given(scenes_and_plans(), scenes_and_plans())
    def check(
        case: tuple[dict[str, object], list[str]], other: tuple[dict[str, object], list[str]]
    ) -> None:
        scene = build_scene(case[0], tbox.vocabulary)
        elsewhere = build_scene(other[0], tbox.vocabulary)
        steps = case[1]
        # Plans that share different parts of the scene: the kept model is
        # grown, cut back to what two plans share, and replaced by another
        # scene's.
        runs = [
            (scene, steps),
            (scene, steps[: len(steps) // 2] or steps),
            (scene, steps[::-1]),
            (elsewhere, other[1]),
            (scene, steps),
        ]
        for where, lines in runs:
            plan = parse_plan(lines)
            new = LogicTutor.over(tbox, make_engine("fast", tbox)).verifier
            assert _report(kept.verify(where, plan)) == _report(new.verify(where, plan))

    check()
