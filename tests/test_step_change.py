"""A step costs what it changes: the simulator finds what its effects touch
through indexes carried from the state before, and records the facts the
step changed instead of comparing every fact.  These tests hold the carried
answers to ones computed from scratch, over random plans in the examples'
scenes (hypothesis)."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import pytest
from conftest import EXAMPLES_DIR
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from virf.api import LogicTutor
from virf.ontology.tbox import Vocabulary
from virf.schema import Fact
from virf.world.actions import Change
from virf.world.language import LIQUIDS, VERBS
from virf.world.plan import parse_line
from virf.world.scene import Scene
from virf.world.simulator import MissingObject, PreconditionFailure, Simulator
from virf.world.state import WorldState, changed

RANDOM = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
SCENES = (
    "walkthrough",
    "burner-left-on",
    "challenge-chemical",
    "salt-shaker-microwave",
    "toilet-cleaner-unknown-contents",
    "hair-dryer-basin",
)


@pytest.fixture(scope="module")
def scenes(tutor: LogicTutor) -> list[Scene]:
    return [tutor.scene(EXAMPLES_DIR / name / "scene.json") for name in SCENES]


def fresh(state: WorldState) -> WorldState:
    """The same state with nothing remembered: every index built from its facts."""
    return replace(state)


def relation(index: dict[tuple[str, str], list[str]]) -> dict[tuple[str, str], list[str]]:
    return {key: sorted(values) for key, values in index.items()}


def mentions(index: dict[str, dict[Fact, None]]) -> dict[str, set[Fact]]:
    return {name: set(facts) for name, facts in index.items()}


# Verbs of one object, each taken after finding it.
ONE_OBJECT = [v for v in VERBS if v not in ("find", "pick", "put", "pour", "drop", "throw")]


@st.composite
def plan_lines(draw: Any, scene: Scene, vocab: Vocabulary) -> list[str]:
    """Episodes a plan is made of: find a thing and act on it, or carry
    something that can be picked up somewhere and put it down, pour it or
    drop it (most of them run)."""
    objects = list(scene.order)

    def kind(cls: str) -> list[str]:
        return [o for o in objects if vocab.any_is_a(scene.objects[o], cls)] or objects

    movable, places = kind("Pickupable"), kind("Receptacle")
    out: list[str] = []
    for _ in range(draw(st.integers(1, 5))):
        obj, place = draw(st.sampled_from(objects)), draw(st.sampled_from(places))
        verb = draw(st.sampled_from([*ONE_OBJECT, "put", "pour", "drop", "throw"]))
        if verb == "fillLiquid":
            out += [f"find {obj}", f"{verb} {obj} {draw(st.sampled_from(LIQUIDS))}"]
        elif verb in ONE_OBJECT:
            out += [f"find {obj}", f"{verb} {obj}"]
        elif verb in ("drop", "throw"):
            held = draw(st.sampled_from(movable))
            out += [f"find {held}", f"pick {held}", verb]
        else:
            held = draw(st.sampled_from(movable))
            out += [f"find {held}", f"pick {held}", f"find {place}", f"{verb} {place}"]
    return out


def step(sim: Simulator, state: WorldState, line: str, i: int) -> tuple[Change, WorldState] | None:
    """One step as :meth:`Simulator.apply` takes it, with its working copy."""
    r = sim.resolve(state, parse_line(line, i, i))
    if isinstance(r, MissingObject):
        return None
    change = sim.change(state, r)
    if isinstance(change, PreconditionFailure):
        return None
    # What the effects found through the indexes is what a pass over every
    # fact of the working copy finds.
    names = {n for f in change.facts for n in (f.subject, f.object) if n} | {"OnState"}
    for name in names:
        every = [f for f in change.facts if name in (f.subject, f.object)]
        assert sorted(change.mentioning(name), key=repr) == sorted(every, key=repr), name
    after = change.result()
    again = sim.apply(fresh(state), r)
    assert not isinstance(again, PreconditionFailure)
    assert dict(after.facts) == dict(again.facts)
    assert (after.objects, after.order, after.found) == (again.objects, again.order, again.found)
    return change, after


@RANDOM
@given(data=st.data())
def test_a_step_carried_from_the_state_before_equals_one_from_scratch(
    tutor: LogicTutor, scenes: list[Scene], data: st.DataObject
) -> None:
    scene = data.draw(st.sampled_from(scenes))
    sim = Simulator(tutor.tbox.vocabulary)
    state = sim.initial(scene)
    # The first state's indexes are built from its facts; each later one's
    # are carried, in whatever order the steps ask for them.
    for i, line in enumerate(data.draw(plan_lines(scene, tutor.tbox.vocabulary)), start=1):
        taken = step(sim, state, line, i)
        if taken is None:
            continue
        _, after = taken
        assert changed(state, after) == set(state.facts) ^ set(after.facts)
        assert changed(fresh(state), fresh(after)) == changed(state, after)
        # The indexes of names, kept from the state before when the step
        # made no object (slicing makes some).
        scratch = fresh(after)
        assert after._by_lower == scratch._by_lower
        assert after._by_key == scratch._by_key
        assert after._by_stem == scratch._by_stem
        if data.draw(st.booleans()):
            # Asked at once, or left for a later state to carry further.
            new = fresh(after)
            assert relation(after._forward) == relation(new._forward)
            assert relation(after._backward) == relation(new._backward)
            assert mentions(after._mentions) == mentions(new._mentions)
        state = after
    new = fresh(state)
    assert relation(state._forward) == relation(new._forward)
    assert relation(state._backward) == relation(new._backward)
    assert mentions(state._mentions) == mentions(new._mentions)
