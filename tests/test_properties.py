"""Property-based: any plan over the 17 verbs in a small kitchen gets a verdict, never a crash."""

from __future__ import annotations

from typing import Any

import pytest
from conftest import inst, rel
from hypothesis import given, settings
from hypothesis import strategies as st

from virf.world.language import ARITY, LIQUIDS, VERBS
from virf.world.plan import parse_plan

SCENE: dict[str, Any] = {
    "instances": [
        inst("Apple", "Apple_1"),
        inst("Mug", "Mug_1"),
        inst("Fridge", "Fridge_1"),
        inst("Microwave", "Microwave_1"),
        inst("CounterTop", "CounterTop_1"),
        inst("StoveKnob", "StoveKnob_1"),
        inst("StoveBurner", "StoveBurner_1"),
        inst("Knife", "Knife_1"),
    ],
    "assertions": [
        rel("Apple_1", "isOn", "CounterTop_1"),
        rel("Mug_1", "isOn", "CounterTop_1"),
        rel("Knife_1", "isOn", "CounterTop_1"),
        rel("Fridge_1", "hasState", "ClosedState"),
        rel("Microwave_1", "hasState", "ClosedState"),
        rel("StoveKnob_1", "controls", "StoveBurner_1"),
        rel("StoveKnob_1", "hasState", "OffState"),
        rel("StoveBurner_1", "hasState", "OffState"),
    ],
}
# Instance names, class names (resolved by the simulator) and one object the scene lacks.
TERMS = [i["instance_name"] for i in SCENE["instances"]] + ["Apple", "Fridge", "AppleSliced"]


@st.composite
def plan_lines(draw: st.DrawFn) -> str:
    verb = draw(st.sampled_from(VERBS))
    if verb == "fillLiquid":
        return f"fillLiquid {draw(st.sampled_from(TERMS))} {draw(st.sampled_from(LIQUIDS))}"
    lo, hi = ARITY[verb]
    n = draw(st.integers(lo, hi))
    return " ".join([verb, *(draw(st.sampled_from(TERMS)) for _ in range(n))])


@pytest.fixture(scope="module")
def scene(tutor):
    return tutor.scene(SCENE)


@settings(max_examples=15, deadline=None, derandomize=True, database=None)
@given(lines=st.lists(plan_lines(), min_size=1, max_size=6))
def test_random_plans_get_a_deterministic_verdict(tutor, scene, lines: list[str]) -> None:
    plan = parse_plan(lines)
    assert len(plan) == len(lines)
    report = tutor.verify(scene, plan)
    assert report.status in ("SAFE", "UNSAFE", "UNKNOWN"), report.reason
    assert len(report.trace) == len(plan)
    if report.status == "SAFE":
        assert report.violations == ()
    else:
        assert report.dangerous_step is not None
        assert 0 <= report.dangerous_step <= len(plan)
    assert tutor.verify(scene, plan).to_json() == report.to_json()
