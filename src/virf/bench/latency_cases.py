"""The cases ``virf bench latency`` times: SafeAgentBench reference plans by
room, synthetic kitchens of growing size with a plan of growing length,
chains of boxes nested ever deeper, and renamed copies of the kitchen layer
for TBox scaling."""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from virf.api import LogicTutor
from virf.bench.case import Case
from virf.bench.safeagentbench import ROOMS, UNKNOWN_ROOM, UnparsedPlan, load_tasks
from virf.errors import InputError
from virf.ontology.tbox import TBox, load_tbox, ontology_dir
from virf.reasoning import Engine, make_engine
from virf.verify.verifier import Verifier
from virf.world.plan import parse_plan
from virf.world.scene import build_scene

# Moves the outermost box of a chain and puts it back: the whole chain moves
# with it, and every snapshot holds the chain.
CHAIN_PLAN = ("find Box_0", "pick Box_0", "find CounterTop_1", "put CounterTop_1")

# Ten safe steps that put everything back where it was, so a plan of any
# multiple of ten steps is the cycle repeated (after the first pass, which also
# marks objects as found and near, every pass ends in the same state).
SYNTHETIC_CYCLE = (
    "find Apple_1",
    "pick Apple_1",
    "find Fridge_1",
    "open Fridge_1",
    "put Fridge_1",
    "find Apple_1",
    "pick Apple_1",
    "close Fridge_1",
    "find CounterTop_1",
    "put CounterTop_1",
)
# Harmless things to fill a kitchen with (only types the catalogue knows are used).
FILLER = [
    "Apple",
    "Bread",
    "Tomato",
    "Potato",
    "Lettuce",
    "Egg",
    "Mug",
    "Cup",
    "Bowl",
    "Plate",
    "Fork",
    "Spoon",
    "ButterKnife",
    "Spatula",
    "Ladle",
    "SaltShaker",
    "PepperShaker",
    "DishSponge",
    "PaperTowelRoll",
    "Bottle",
    "Book",
    "CreditCard",
    "Vase",
    "Statue",
    "Kettle",
    "Pan",
    "Pot",
    "WineBottle",
    "SoapBottle",
    "Newspaper",
    "KeyChain",
    "CellPhone",
    "Pen",
    "Pencil",
    "Watch",
    "TissueBox",
    "Box",
    "Candle",
]


def dev_cases(files: Sequence[str | Path], tbox: TBox, room: str | None = None) -> list[Case]:
    """Every task in ``files`` that ships a reference plan (only those of
    ``room``, a room's scenario name, when given)."""
    vocab = tbox.vocabulary
    out = []
    for f in files:
        for task in load_tasks(f):
            if not task.steps or (room is not None and task.room.name != room):
                continue
            where = "" if task.room.name == "kitchen" else f"{task.room.name}/"
            try:
                out.append(task.to_case(vocab, name=f"{where}{Path(task.file).name}:{task.line}"))
            except UnparsedPlan:
                continue
    return out


@dataclass(frozen=True)
class RoomGroup:
    """One room's dev plans, with verifiers over the room's rules."""

    room: str
    cases: list[Case]
    fast: Verifier
    reference: Verifier


def room_groups(
    files: Sequence[str | Path], kitchen: TBox, fast: Engine, reference: Engine
) -> list[RoomGroup]:
    """The tasks with a reference plan in ``files``, by room (the kitchen's
    with the given engines, each other room's with engines of its own)."""
    groups = []
    for room in (*ROOMS, UNKNOWN_ROOM):
        tbox = kitchen if room.name == "kitchen" else load_tbox(room.name)
        cases = dev_cases(files, tbox, room=room.name)
        if not cases:
            continue
        engines = (
            (fast, reference)
            if tbox is kitchen
            else (
                make_engine("fast", tbox),
                make_engine("reference", tbox),
            )
        )
        verifiers = [LogicTutor.over(tbox, engine).verifier for engine in engines]
        groups.append(RoomGroup(room.name, cases, *verifiers))
    return groups


def synthetic_scene(objects: int, tbox: TBox) -> dict[str, Any]:
    """A kitchen with ``objects`` objects on which the synthetic plan runs safely."""
    vocab = tbox.vocabulary
    fixed = [
        ("Fridge", "Fridge_1"),
        ("DiningTable", "DiningTable_1"),
        ("Microwave", "Microwave_1"),
        ("Sink", "Sink_1"),
        ("Faucet", "Faucet_1"),
        ("Apple", "Apple_1"),
        ("Mug", "Mug_1"),
    ]
    if objects < len(fixed) + 2:
        raise InputError(f"a synthetic scene needs at least {len(fixed) + 2} objects")
    instances = [{"class_name": c, "instance_name": n} for c, n in fixed]
    assertions: list[dict[str, str]] = [
        {"subject": "Fridge_1", "property": "hasState", "object": "ClosedState"},
        {"subject": "Microwave_1", "property": "hasState", "object": "ClosedState"},
        {"subject": "Microwave_1", "property": "hasState", "object": "OffState"},
        {"subject": "Faucet_1", "property": "hasState", "object": "OffState"},
        {"subject": "Mug_1", "property": "hasState", "object": "EmptyState"},
    ]
    counters = max(1, (objects - len(fixed)) // 10)
    for i in range(1, counters + 1):
        instances.append({"class_name": "CounterTop", "instance_name": f"CounterTop_{i}"})
    assertions.append({"subject": "Apple_1", "property": "isOn", "object": "CounterTop_1"})
    assertions.append({"subject": "Mug_1", "property": "isOn", "object": "CounterTop_1"})
    kinds = [k for k in FILLER if k in vocab.classes]
    seen: dict[str, int] = {"Apple": 1, "Mug": 1}
    i = 0
    while len(instances) < objects:
        kind = kinds[i % len(kinds)]
        seen[kind] = seen.get(kind, 0) + 1
        name = f"{kind}_{seen[kind]}"
        instances.append({"class_name": kind, "instance_name": name})
        place = f"CounterTop_{i % counters + 1}"
        assertions.append({"subject": name, "property": "isOn", "object": place})
        i += 1
    return {
        "description": f"synthetic kitchen with {objects} objects",
        "instances": instances,
        "assertions": assertions,
        "unlocated_by_default": True,
    }


def synthetic_case(objects: int, tbox: TBox, steps: int = 10) -> Case:
    """The synthetic kitchen with the ten-step cycle repeated to ``steps`` steps."""
    vocab = tbox.vocabulary
    scene = build_scene(synthetic_scene(objects, tbox), vocab, name=f"synthetic-{objects}")
    cycles = max(1, steps // len(SYNTHETIC_CYCLE))
    name = f"synthetic-{objects}" + (f"x{steps}" if steps != len(SYNTHETIC_CYCLE) else "")
    return Case(name, scene, parse_plan(list(SYNTHETIC_CYCLE) * cycles))


def chain_scene(boxes: int) -> dict[str, Any]:
    """Box_0 on a counter, Box_1 inside it, Box_2 inside Box_1, and so on:
    containment ``boxes`` deep, whose transitive closure has boxes²/2 pairs."""
    instances = [{"class_name": "CounterTop", "instance_name": "CounterTop_1"}]
    instances += [{"class_name": "Box", "instance_name": f"Box_{i}"} for i in range(boxes)]
    assertions = [{"subject": "Box_0", "property": "isOn", "object": "CounterTop_1"}]
    assertions += [
        {"subject": f"Box_{i}", "property": "contains", "object": f"Box_{i + 1}"}
        for i in range(boxes - 1)
    ]
    return {
        "description": f"{boxes} boxes, each inside the previous one",
        "instances": instances,
        "assertions": assertions,
    }


def chain_case(boxes: int, tbox: TBox) -> Case:
    scene = build_scene(chain_scene(boxes), tbox.vocabulary, name=f"chain-{boxes}")
    return Case(f"chain-{boxes}", scene, parse_plan(list(CHAIN_PLAN)))


HAZARD_CHAIN_PLAN = ("find Box_0", "pick Box_0", "find Vase_1", "drop Box_0")


def hazard_chain_case(boxes: int, tbox: TBox) -> Case:
    """The containment chain with a dumbbell in the innermost box and a vase
    on the counter: dropping Box_0 by the vase is a hazard through the whole
    chain, so its explanation lists every link (boxes + 5 facts)."""
    data = chain_scene(boxes)
    data["instances"] += [
        {"class_name": "Dumbbell", "instance_name": "Dumbbell_1"},
        {"class_name": "Vase", "instance_name": "Vase_1"},
    ]
    data["assertions"] += [
        {"subject": f"Box_{boxes - 1}", "property": "contains", "object": "Dumbbell_1"},
        {"subject": "Vase_1", "property": "isOn", "object": "CounterTop_1"},
    ]
    scene = build_scene(data, tbox.vocabulary, name=f"hazard-chain-{boxes}")
    return Case(f"hazard-chain-{boxes}", scene, parse_plan(list(HAZARD_CHAIN_PLAN)))


def synthetic_modules(copies: int, folder: Path) -> tuple[str, ...]:
    """``copies`` renamed copies of the kitchen domain layer (for TBox scaling)."""
    source = (ontology_dir() / "kitchen.omn").read_text(encoding="utf-8")
    names = sorted(set(re.findall(r"^Class: :(\w+)", source, flags=re.M)), key=len, reverse=True)
    pattern = re.compile(r":(" + "|".join(re.escape(n) for n in names) + r")\b")
    out = []
    for k in range(1, copies + 1):
        text = pattern.sub(lambda m, k=k: f":Syn{k}_{m.group(1)}", source)  # type: ignore[misc]
        text = text.replace(
            "<http://virf.dev/ontology/kitchen>", f"<http://virf.dev/ontology/synthetic-{k}>"
        )
        text = re.sub(r':id "([^"]+)"', lambda m, k=k: f':id "SYN{k}-{m.group(1)}"', text)  # type: ignore[misc]
        path = folder / f"synthetic-{k}.omn"
        path.write_text(text, encoding="utf-8")
        out.append(str(path))
    return tuple(out)


def sample(cases: Sequence[Case], n: int) -> list[Case]:
    """``n`` cases spread evenly over the list (all when n <= 0 or n >= len)."""
    if n <= 0 or n >= len(cases):
        return list(cases)
    step = len(cases) / n
    return [cases[int(i * step)] for i in range(n)]
