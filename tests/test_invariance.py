"""Metamorphic: one world, many spellings, one verdict.

A world is generated once, in canonical terms (objects, states, materials,
receptacle relations), and written out as scene JSON several times: each
state as a punned class name, a state individual, a data literal or a type of
the object; each material through hasMaterial or isMadeOf, as a material
individual or a material-defined object class; each relation in either
direction; each type in ``instances`` or as an rdf:type assertion; instances
and assertions shuffled; individuals renamed. Every spelling must give the
same report, up to the renaming (the user's own spellings, kept for display in
``as_written``, aside).
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from virf.render.text import render_report
from virf.schema import Triple

FULL = os.environ.get("VIRF_FULL") == "1"

APPLIANCES = {  # type -> (toggleable, openable, receptacle relation)
    "Toaster": (True, False, "contains"),
    "Microwave": (True, True, "contains"),
    "StoveBurner": (True, False, "supports"),
    "Fridge": (False, True, "contains"),
}
SMALL = ("Fork", "Bowl", "Mug", "Bread", "Apple", "Pot", "Plate", "Knife")
LIQUID_CONTAINERS = {"Bowl", "Mug", "Pot"}
MATERIALS = ("Metal", "Plastic", "Glass", "Ceramic", "Wood")
MATERIAL_CLASS = {
    "Metal": "MetallicObject",
    "Plastic": "PlasticObject",
    "Glass": "GlassObject",
    "Ceramic": "CeramicObject",
    "Wood": "WoodenObject",
}
STATE_WORD = {
    "OnState": "on",
    "OffState": "off",
    "OpenState": "open",
    "ClosedState": "closed",
    "FilledWithLiquidState": "filled",
    "EmptyState": "empty",
}
STATE_SUBCLASS = {"ClosedState": "DoorClosedState", "OpenState": "DoorOpenState"}
INVERSE = {"contains": "isInside", "supports": "isOn"}


@dataclass(frozen=True)
class World:
    types: tuple[tuple[str, str], ...]  # (instance, class)
    states: tuple[tuple[str, str], ...]  # (instance, state class)
    materials: tuple[tuple[str, str], ...]  # (instance, material)
    relations: tuple[tuple[str, str, str], ...]  # (receptacle, relation, object)
    closed: tuple[str, ...]
    plan: tuple[str, ...]


@st.composite
def worlds(draw: st.DrawFn) -> World:
    appliances = draw(st.lists(st.sampled_from(sorted(APPLIANCES)), unique=True, max_size=3))
    small = draw(st.lists(st.sampled_from(SMALL), unique=True, min_size=1, max_size=3))
    types = [("CounterTop_1", "CounterTop")]
    types += [(f"{t}_1", t) for t in appliances] + [(f"{t}_1", t) for t in small]
    states: list[tuple[str, str]] = []
    for t in appliances:
        toggle, opens, _ = APPLIANCES[t]
        if toggle:
            s = draw(st.sampled_from([None, "OnState", "OffState"]))
            if s:
                states.append((f"{t}_1", s))
        if opens:
            s = draw(st.sampled_from([None, "OpenState", "ClosedState"]))
            if s:
                states.append((f"{t}_1", s))
    materials: list[tuple[str, str]] = []
    relations: list[tuple[str, str, str]] = []
    for t in small:
        if t in LIQUID_CONTAINERS:
            s = draw(st.sampled_from([None, "FilledWithLiquidState", "EmptyState"]))
            if s:
                states.append((f"{t}_1", s))
        m = draw(st.sampled_from([None, *MATERIALS]))
        if m:
            materials.append((f"{t}_1", m))
        where = draw(st.sampled_from(["CounterTop", *appliances]))
        rel = "supports" if where == "CounterTop" else APPLIANCES[where][2]
        relations.append((f"{where}_1", rel, f"{t}_1"))
    closed = draw(st.lists(st.sampled_from(["contains", "supports"]), unique=True))
    names = [n for n, _ in types]
    movable = [f"{t}_1" for t in small]
    steps = draw(
        st.lists(
            st.one_of(
                st.sampled_from(names).map(lambda n: f"find {n}"),
                st.sampled_from(movable).map(lambda n: f"pick {n}"),
                st.sampled_from(["CounterTop_1"] + [f"{t}_1" for t in appliances]).map(
                    lambda n: f"put {n}"
                ),
                st.sampled_from([f"{t}_1" for t in appliances if APPLIANCES[t][1]] or ["X"])
                .filter(lambda n: n != "X")
                .map(lambda n: f"open {n}"),
                st.sampled_from([f"{t}_1" for t in appliances if APPLIANCES[t][0]] or ["X"])
                .filter(lambda n: n != "X")
                .map(lambda n: f"turn_on {n}"),
            ),
            min_size=1,
            max_size=5,
        )
    )
    return World(
        tuple(types), tuple(states), tuple(materials), tuple(relations), tuple(closed), tuple(steps)
    )


@dataclass(frozen=True)
class Spelling:
    """How one rewrite writes each kind of fact (indexes into the choices)."""

    seed: int
    rename: bool


def write_scene(world: World, how: Spelling) -> tuple[dict[str, Any], dict[str, str]]:
    """The world as scene JSON in one spelling, and the renaming it used."""
    rng = __import__("random").Random(how.seed)
    # Renaming keeps the names' order, so that where two minimal explanations
    # exist the same one is found.
    names = {n: (f"{n}x" if how.rename else n) for n, _ in world.types}
    instances: list[dict[str, str]] = []
    assertions: list[dict[str, str]] = []
    extra = 0

    def fresh(prefix: str) -> str:
        nonlocal extra
        extra += 1
        return f"{prefix}{extra}"

    for n, cls in world.types:
        if rng.random() < 0.5:
            instances.append({"class_name": cls, "instance_name": names[n]})
        else:
            assertions.append({"subject": names[n], "property": "rdf:type", "object": cls})
    for n, state in world.states:
        form = rng.choice(["punned", "individual", "literal", "typed", "typed-instance"])
        if form == "punned":
            assertions.append({"subject": names[n], "property": "hasState", "object": state})
        elif form == "individual":
            ind = fresh("State_")
            cls = STATE_SUBCLASS.get(state, state) if rng.random() < 0.5 else state
            instances.append({"class_name": cls, "instance_name": ind})
            assertions.append({"subject": names[n], "property": "hasState", "object": ind})
        elif form == "literal":
            assertions.append(
                {
                    "subject": names[n],
                    "property": "hasState",
                    "object": STATE_WORD[state],
                    "type": "data_property",
                }
            )
        elif form == "typed":
            assertions.append({"subject": names[n], "property": "rdf:type", "object": state})
        else:
            instances.append({"class_name": state, "instance_name": names[n]})
    for n, material in world.materials:
        form = rng.choice(["hasMaterial", "isMadeOf", "individual", "class"])
        if form in ("hasMaterial", "isMadeOf"):
            assertions.append({"subject": names[n], "property": form, "object": material})
        elif form == "individual":
            ind = fresh("Material_")
            instances.append({"class_name": material, "instance_name": ind})
            prop = rng.choice(["hasMaterial", "isMadeOf"])
            assertions.append({"subject": names[n], "property": prop, "object": ind})
        else:
            instances.append({"class_name": MATERIAL_CLASS[material], "instance_name": names[n]})
    for r, rel, o in world.relations:
        if rng.random() < 0.5:
            assertions.append({"subject": names[r], "property": rel, "object": names[o]})
        else:
            assertions.append({"subject": names[o], "property": INVERSE[rel], "object": names[r]})
    rng.shuffle(instances)
    rng.shuffle(assertions)
    closed = list(world.closed)
    rng.shuffle(closed)
    scene = {"instances": instances, "assertions": assertions, "closed_world": closed}
    return scene, names


def canonical_report(report_json: str, names: dict[str, str]) -> dict[str, Any]:
    """The report with the renaming undone and the user's spellings set aside."""
    text = report_json
    for original, renamed in sorted(names.items(), key=lambda kv: -len(kv[1])):
        if original != renamed:
            text = re.sub(rf"\b{re.escape(renamed)}\b", original, text)
    data: dict[str, Any] = json.loads(text)
    for v in data["violations"]:
        v.pop("as_written", None)
    if data.get("causal_chain"):
        data["causal_chain"].pop("as_written", None)
    return data


@settings(
    max_examples=120 if FULL else 25,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(world=worlds(), seeds=st.lists(st.integers(0, 10_000), min_size=2, max_size=2))
def test_every_spelling_gives_the_same_report(tutor, world: World, seeds: list[int]) -> None:
    reference, ref_names = write_scene(world, Spelling(seed=-1, rename=False))
    baseline = canonical_report(tutor.verify(reference, list(world.plan)).to_json(), ref_names)
    for i, seed in enumerate(seeds):
        scene, names = write_scene(world, Spelling(seed=seed, rename=i == 1))
        plan = [" ".join(names.get(w, w) for w in s.split()) for s in world.plan]
        got = canonical_report(tutor.verify(scene, plan).to_json(), names)
        assert got["status"] == baseline["status"], (scene, world.plan)
        assert got["dangerous_step"] == baseline["dangerous_step"]
        assert [v["id"] for v in got["violations"]] == [v["id"] for v in baseline["violations"]]
        assert got == baseline, (scene, world.plan)


def test_spellings_cover_every_form() -> None:
    """The generator really writes each form (the test above is not vacuous)."""
    world = World(
        types=(("Toaster_1", "Toaster"), ("Fork_1", "Fork"), ("CounterTop_1", "CounterTop")),
        states=(("Toaster_1", "OnState"),),
        materials=(("Fork_1", "Metal"),),
        relations=(("Toaster_1", "contains", "Fork_1"),),
        closed=(),
        plan=("find Fork_1",),
    )
    seen: set[str] = set()
    for seed in range(60):
        scene, _ = write_scene(world, Spelling(seed=seed, rename=False))
        text = json.dumps(scene)
        for marker in ('"on"', "State_", "rdf:type", "isMadeOf", "Material_", "MetallicObject"):
            if marker in text:
                seen.add(marker)
        for inst_ in scene["instances"]:
            if inst_["class_name"] == "OnState" and inst_["instance_name"] == "Toaster_1":
                seen.add("typed-instance")
        if any(a["property"] == "isInside" for a in scene["assertions"]):
            seen.add("isInside")
    assert seen == {
        '"on"',
        "State_",
        "rdf:type",
        "isMadeOf",
        "Material_",
        "MetallicObject",
        "typed-instance",
        "isInside",
    }


@pytest.mark.parametrize(
    "state_spelling",
    [
        {"subject": "Toaster_1", "property": "hasState", "object": "OnState"},
        {"subject": "Toaster_1", "property": "hasState", "object": "On_1"},
        {"subject": "Toaster_1", "property": "hasState", "object": "on", "type": "data_property"},
        {"subject": "Toaster_1", "property": "rdf:type", "object": "OnState"},
    ],
    ids=["punned", "individual", "literal", "typed"],
)
def test_state_spellings_toaster_with_fork(tutor, state_spelling: dict[str, str]) -> None:
    """The issue's own case: a state individual must not get a default OffState
    beside it (a contradiction at step 0)."""
    scene = {
        "instances": [
            {"class_name": "Toaster", "instance_name": "Toaster_1"},
            {"class_name": "Fork", "instance_name": "Fork_1"},
            {"class_name": "CounterTop", "instance_name": "CounterTop_1"},
            {"class_name": "OnState", "instance_name": "On_1"},
        ],
        "assertions": [
            state_spelling,
            {"subject": "Fork_1", "property": "isOn", "object": "CounterTop_1"},
        ],
    }
    report = tutor.verify(scene, ["find Fork_1", "pick Fork_1", "find Toaster_1", "put Toaster_1"])
    assert (report.status, report.dangerous_step) == ("UNSAFE", 4)
    assert report.violated_concept is not None
    # Putting a fork into a toaster is a hazard whether or not it is on ...
    assert report.violated_concept.id == "ConductiveObjectIntoLiveElementsDanger"
    # ... and a fork among live elements needs the toaster on, as every spelling says.
    assert "ConductiveObjectAmongLiveElementsDanger" in [v.id for v in report.violations]


def test_open_replaces_a_door_closed_state_individual(tutor) -> None:
    scene = {
        "instances": [
            {"class_name": "Fridge", "instance_name": "Fridge_1"},
            {"class_name": "DoorClosedState", "instance_name": "DoorClosedState_1"},
        ],
        "assertions": [
            {"subject": "Fridge_1", "property": "hasState", "object": "DoorClosedState_1"}
        ],
    }
    closed_again = tutor.verify(scene, ["find Fridge_1", "open Fridge_1", "close Fridge_1"])
    assert closed_again.status == "SAFE", closed_again.reason
    left_open = tutor.verify(scene, ["find Fridge_1", "open Fridge_1"])
    assert (left_open.status, left_open.dangerous_step) == ("UNSAFE", 2)
    assert left_open.violated_concept is not None
    assert left_open.violated_concept.id == "ColdStorageLeftOpenDanger"


def test_reports_show_the_users_own_spelling(tutor) -> None:
    scene = {
        "instances": [
            {"class_name": "Toaster", "instance_name": "Toaster_1"},
            {"class_name": "Fork", "instance_name": "Fork_1"},
            {"class_name": "OnState", "instance_name": "On_1"},
        ],
        "assertions": [
            {"subject": "Toaster_1", "property": "hasState", "object": "On_1"},
            {"subject": "Fork_1", "property": "isInside", "object": "Toaster_1"},
        ],
    }
    report = tutor.verify(scene, ["find Toaster_1"])
    assert report.status == "UNSAFE"
    v = report.violations[0]
    assert Triple(subject="Toaster_1", predicate="hasState", object="OnState") in v.triggering_facts
    assert Triple(subject="Toaster_1", predicate="hasState", object="On_1") in v.as_written
    assert Triple(subject="Fork_1", predicate="isInside", object="Toaster_1") in v.as_written
    assert "As the scene wrote them:" in render_report(report)
