"""SafeAgentBench grounding: tasks, their scenes, the cases a benchmark checks.

SafeAgentBench (Yin et al.) ships tasks as JSON lines with a reference plan
(``step``), a risk category, and goal conditions (``final_state``), but no
object lists for its AI2-THOR scenes.  A task's scene is therefore built here
from the object types its plan, objects list, goal conditions and instruction
name, plus the fixtures every kitchen has, with the catalogue's defaults.
The goal conditions are checked in :mod:`virf.bench.goals`.

Assumptions of a built scene (documented in docs/benchmarks/safeagentbench.md):

* the room comes from the floor plan (``FloorPlan1``-``30`` kitchens,
  ``201``-``230`` living rooms, ``301``-``330`` bedrooms, ``401``-``430``
  bathrooms), and its scenario verifies the task;
* one instance per type named by the plan, the objects list, the goal
  conditions, the instruction or its unsafe twin (``risk_instruction``), and
  one of each of the room's fixtures (a kitchen's counter top, sink, stove,
  fridge...; a living room's sofa and side table; a bedroom's bed and dresser;
  a bathroom's counter top, sink and toilet; every room's floor and light
  switch);
* every pickupable object starts on the room's typical surface (a kitchen's
  or bathroom's counter top, a living room's side table, a bedroom's
  dresser); fixtures stand alone;
* the stove knob controls the stove burner (knob k controls burner k);
* a faucet is near the sink and basin it feeds, a shower head near the tub,
  shower door, curtain or glass of the scene;
* states AI2-THOR fixes at start (closed, off, clean, empty) are asserted;
  states it randomises (a mug may start dirty or filled) are left unknown;
* the robot starts having found nothing (``unlocated_by_default``);
* the builder knows everything it placed, so ``contains`` and ``supports``
  are closed-world, except the contents of containers AI2-THOR may start
  filled (``unknown_contents``).
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from virf.bench.case import Case
from virf.errors import InputError, read_input_file
from virf.names import term_key
from virf.ontology.tbox import Vocabulary
from virf.verify.requirements import Requirement, Unreadable, parse_requirement, requirement_text
from virf.world.plan import MAX_NAME_WORDS, PlanStep, parse_plan, singular_forms
from virf.world.scene import build_scene

CATEGORIES = (
    "Fire Hazard",
    "Electrical Shock Hazard",
    "Explosion Hazard",
    "Poisoning/Ingestion Hazard",
    "Slip Hazard",
    "Liquid and Spill Damage",
    "Breakage and Dropping",
    "Misuse of Electrical Appliances",
    "Furniture and Decor Damage",
    "Damage to Small Items",
)
# Keyword -> category, tried in order on the lower-cased free text.
_CATEGORY_KEYWORDS = (
    ("electrical shock", "Electrical Shock Hazard"),
    ("misuse", "Misuse of Electrical Appliances"),
    ("appliance", "Misuse of Electrical Appliances"),
    ("explosion", "Explosion Hazard"),
    ("fire", "Fire Hazard"),
    ("poison", "Poisoning/Ingestion Hazard"),
    ("ingestion", "Poisoning/Ingestion Hazard"),
    ("slip", "Slip Hazard"),
    ("liquid", "Liquid and Spill Damage"),
    ("spill", "Liquid and Spill Damage"),
    ("water damage", "Liquid and Spill Damage"),
    ("breakage", "Breakage and Dropping"),
    ("dropping", "Breakage and Dropping"),
    ("furniture", "Furniture and Decor Damage"),
    ("decor", "Furniture and Decor Damage"),
    ("damage to properties", "Furniture and Decor Damage"),
    ("small item", "Damage to Small Items"),
    # Harm to people from sharp or thrown objects is filed under breakage and
    # dropping, the benchmark's category for physical-impact hazards.
    ("sharp object", "Breakage and Dropping"),
    ("harm to human", "Breakage and Dropping"),
    ("shards", "Breakage and Dropping"),
    ("injury", "Breakage and Dropping"),
    ("impact", "Breakage and Dropping"),
    ("break", "Breakage and Dropping"),
    # Stains are damage to furnishings; a lost or locked-away item is a small
    # item's damage (the other rooms' split uses these names).
    ("stain", "Furniture and Decor Damage"),
    ("loss of item", "Damage to Small Items"),
    ("inaccessib", "Damage to Small Items"),
)
KITCHEN_FIXTURES = (
    "CounterTop",
    "Floor",
    "Sink",
    "SinkBasin",
    "Faucet",
    "StoveBurner",
    "StoveKnob",
    "Fridge",
    "Microwave",
    "Cabinet",
    "Drawer",
)


@dataclass(frozen=True)
class Room:
    """A kind of SafeAgentBench (AI2-THOR iTHOR) room: its floor plans, the
    scenario that verifies its tasks, and how a task's scene starts."""

    name: str  # the scenario's name
    label: str
    first_plan: int
    last_plan: int
    fixtures: tuple[str, ...]
    surface: str  # where pickupable objects start

    def has_plan(self, number: int) -> bool:
        return self.first_plan <= number <= self.last_plan


# iTHOR numbers its floor plans by room: 1-30 kitchens, 201-230 living rooms,
# 301-330 bedrooms, 401-430 bathrooms.  Without AI2-THOR the floor plan's own
# object list is unknown, so a scene gets the room's typical fixtures plus
# every type its task names, and pickupable objects start on one typical
# surface of the room (documented assumptions, see the module docstring).
ROOMS = (
    Room("kitchen", "kitchen", 1, 30, KITCHEN_FIXTURES, "CounterTop"),
    Room(
        "living-room",
        "living room",
        201,
        230,
        ("Floor", "LightSwitch", "Sofa", "SideTable"),
        "SideTable",
    ),
    Room("bedroom", "bedroom", 301, 330, ("Floor", "LightSwitch", "Bed", "Dresser"), "Dresser"),
    Room(
        "bathroom",
        "bathroom",
        401,
        430,
        ("Floor", "LightSwitch", "CounterTop", "Sink", "SinkBasin", "Faucet", "Toilet"),
        "CounterTop",
    ),
)
# A water source stands by what it feeds: a tap by its sink and basin, a
# shower head by the tub and the door or curtain that keeps its water in.
FEEDS = (
    ("Faucet", ("Sink", "SinkBasin")),
    ("ShowerHead", ("Bathtub", "BathtubBasin", "ShowerDoor", "ShowerCurtain", "ShowerGlass")),
)
# A task whose floor plan names no known room is verified with every room's rules.
UNKNOWN_ROOM = Room("household", "unknown room", 0, -1, KITCHEN_FIXTURES, "CounterTop")
_FLOOR_PLAN = re.compile(r"^FloorPlan(\d+)(?:_physics)?$")


def room_of(scene_name: object) -> Room:
    """The room of a SafeAgentBench scene name such as 'FloorPlan301'."""
    match = _FLOOR_PLAN.match(str(scene_name or "").strip())
    if match:
        number = int(match.group(1))
        for room in ROOMS:
            if room.has_plan(number):
                return room
    return UNKNOWN_ROOM


FILES_LABEL = {
    "unsafe_detailed": "unsafe",
    "abstract": "unsafe",
    "long_horizon": "unsafe",
    "safe_detailed": "safe",
}
_WORD = re.compile(r"[A-Za-z]+")


def normalise_category(text: str | None) -> str | None:
    """Map SafeAgentBench's free-text risk category to one of its ten."""
    if not text:
        return None
    low = text.lower()
    for key, cat in _CATEGORY_KEYWORDS:
        if key in low:
            return cat
    return None


@dataclass(frozen=True)
class Task:
    file: str  # file name, e.g. unsafe_detailed.jsonl
    line: int  # 1-based line in its file
    data: Mapping[str, Any]

    @property
    def kind(self) -> str:  # unsafe_detailed, safe_detailed, abstract, long_horizon
        return Path(self.file).stem

    @property
    def label(self) -> str:
        return FILES_LABEL.get(self.kind, "safe" if "risk_instruction" in self.data else "unsafe")

    @property
    def instruction(self) -> str:
        ins = self.data.get("instruction", "")
        if isinstance(ins, list):
            return str(ins[0]) if ins else ""
        return str(ins)

    @property
    def steps(self) -> list[str]:
        step = self.data.get("step")
        return [str(s) for s in step] if isinstance(step, list) else []

    @property
    def is_long_horizon(self) -> bool:
        return self.kind == "long_horizon" or (
            "step" not in self.data and "Requirement" in self.instruction
        )

    @property
    def room(self) -> Room:
        return room_of(self.data.get("scene_name"))

    @property
    def scene_name(self) -> str | None:
        name = self.data.get("scene_name")
        return str(name) if name is not None else None

    @property
    def category(self) -> str | None:
        return normalise_category(self.data.get("risk_category"))

    @property
    def final_state(self) -> list[dict[str, Any]] | None:
        fs = self.data.get("final_state")
        return fs if isinstance(fs, list) else None

    def plan(self) -> tuple[PlanStep, ...]:
        return parse_plan(self.steps)

    def scene_data(self, vocab: Vocabulary, plan: Sequence[str] | None = None) -> dict[str, Any]:
        """The task's scene as the paper's JSON (see the module docstring for
        what it assumes); ``plan``, a plan to verify instead of the task's
        own, adds the objects it names."""
        room = self.room
        types = [t for t in room.fixtures if t in vocab.classes]
        for t in named_types(self, vocab, plan):
            if t not in types:
                types.append(t)
        counts = _numbered([*self.steps, *(plan or [])], vocab)
        instances = [{"class_name": t, "instance_name": f"{t}_1"} for t in types]
        for t, n in counts.items():
            instances += [{"class_name": t, "instance_name": f"{t}_{k}"} for k in range(2, n + 1)]
        assertions: list[dict[str, str]] = []

        def state(ind: str, value: str) -> None:
            assertions.append({"subject": ind, "property": "hasState", "object": value})

        for t, ind in [(i["class_name"], i["instance_name"]) for i in instances]:
            randomised = set(vocab.annotation(t, "randomState"))
            blocked = {
                "dirty": {"CleanState", "DirtyState"},
                "filled": {"EmptyState", "FilledWithLiquidState"},
                "open": {"OpenState", "ClosedState"},
                "toggled": {"OnState", "OffState"},
            }
            skip = (
                set().union(*(blocked.get(r, set()) for r in randomised)) if randomised else set()
            )
            for value in vocab.annotation(t, "defaultState"):
                if value not in skip:
                    state(ind, value)
            if vocab.is_a(t, "Pickupable") and t != room.surface:
                assertions.append(
                    {"subject": ind, "property": "isOn", "object": f"{room.surface}_1"}
                )
        names = {i["instance_name"] for i in instances}
        for source, fed in FEEDS:
            for target in fed:
                if f"{source}_1" in names and f"{target}_1" in names:
                    assertions.append(
                        {"subject": f"{source}_1", "property": "isNear", "object": f"{target}_1"}
                    )
        for k in range(1, max(counts.get("StoveKnob", 1), counts.get("StoveBurner", 1)) + 1):
            knob, burner = f"StoveKnob_{k}", f"StoveBurner_{k}"
            if knob in names and burner in names:  # knob k switches burner k
                assertions.append({"subject": knob, "property": "controls", "object": burner})
        return {
            "name": f"{self.kind}:{self.line}",
            "description": f"SafeAgentBench {self.file} line {self.line}: {self.instruction}",
            "instances": instances,
            "assertions": assertions,
            "closed_world": ["contains", "supports"],
            # AI2-THOR may start these filled: what is in them is not known.
            "unknown_contents": [
                f"{t}_1" for t in types if "filled" in vocab.annotation(t, "randomState")
            ],
            "unlocated_by_default": True,
        }

    def requirement(self, vocab: Vocabulary) -> Requirement | Unreadable | None:
        """The step-bounded requirement the instruction states, if any."""
        text = requirement_text(self.instruction)
        return parse_requirement(text, vocab) if text else None

    def to_case(
        self, vocab: Vocabulary, steps: Sequence[str] | None = None, name: str | None = None
    ) -> Case:
        """What a benchmark checks for this task: its plan (``steps``, else
        the reference plan) in its scene, with its requirement.  Raises
        :class:`UnparsedPlan` when the plan does not parse, and InputError
        when the scene cannot be built."""
        try:
            plan = parse_plan(list(self.steps if steps is None else steps))
        except InputError as exc:
            raise UnparsedPlan(str(exc)) from None
        scene = build_scene(self.scene_data(vocab, steps), vocab)
        requirement = self.requirement(vocab)
        return Case(
            name or f"{self.file}:{self.line}",
            scene,
            plan,
            () if requirement is None else (requirement,),
        )


class UnparsedPlan(InputError):
    """A task's plan does not parse: the task cannot be checked, unlike a
    scene that cannot be built, which is a problem of the benchmark's data."""


def load_task_files(paths: Iterable[str | Path]) -> list[Task]:
    """The tasks of several files, each named by its path below the folder
    they share ('unsafe_detailed.jsonl', 'other_rooms/unsafe_detailed.jsonl'),
    so two splits' files of the same name stay apart in reports."""
    files = [Path(p) for p in paths]
    return [
        t for f, name in zip(files, display_names(files), strict=True) for t in load_tasks(f, name)
    ]


def display_names(paths: Sequence[Path]) -> list[str]:
    """How reports call each file: its name when the names differ, else its
    path below the folder the files share, so ``unsafe_detailed.jsonl`` and
    ``other_rooms/unsafe_detailed.jsonl`` stay apart."""
    if len({p.name for p in paths}) == len(paths):
        return [p.name for p in paths]
    resolved = [p.resolve() for p in paths]
    common = Path(os.path.commonpath([str(r.parent) for r in resolved]))
    return [r.relative_to(common).as_posix() for r in resolved]


def load_tasks(path: str | Path, name: str | None = None) -> list[Task]:
    """The tasks of one file; ``name`` is how reports call the file (its name
    by default)."""
    p = Path(path)
    text = read_input_file(p, "benchmark")
    tasks = []
    for i, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            data = json.loads(line)
        except json.JSONDecodeError as exc:
            raise InputError(f"{p}:{i}: not a JSON object ({exc.msg})") from None
        if not isinstance(data, dict) or "instruction" not in data:
            raise InputError(f"{p}:{i}: a SafeAgentBench task needs an 'instruction'")
        if "step" in data and not (
            isinstance(data["step"], list) and all(isinstance(x, str) for x in data["step"])
        ):
            raise InputError(f"{p}:{i}: 'step' must be a list of action strings")
        tasks.append(Task(file=name or p.name, line=i, data=data))
    return tasks


def task_at(path: str | Path, line: int) -> Task:
    for task in load_tasks(path):
        if task.line == line:
            return task
    raise InputError(f"{path} has no task on line {line}")


# ---------------------------------------------------------------------- scenes
def named_types(task: Task, vocab: Vocabulary, plan: Sequence[str] | None = None) -> list[str]:
    """Catalogue types the task (and the plan being verified) names, in
    first-mention order."""
    words: list[str] = []
    for step in [*task.steps, *(plan or [])]:
        words.extend(_step_names(_step_tokens(step)[1:], vocab))
    for key in ("objects", "involved_objects"):
        if isinstance(task.data.get(key), list):
            words.extend(str(o) for o in task.data[key])
    for goal in task.final_state or []:
        words.append(str(goal.get("objectType", "")))
        parents = goal.get("parentReceptacles")
        if isinstance(parents, str):
            parents = [parents]
        words.extend(str(p) for p in parents or [])
        words.extend(str(r) for r in goal.get("receptacleObjectIds") or [])
    instruction = task.data.get("instruction", "")
    # A copy: appending to the task's own list would change the task (and
    # its digest, which keys the agent harness's stored rows) on every call.
    texts = [*instruction] if isinstance(instruction, list) else [instruction]
    texts.append(task.data.get("risk_instruction", ""))
    for text in texts:
        tokens = _WORD.findall(str(text))
        # "coffee machine" and "stove burner" name CoffeeMachine and StoveBurner.
        for span in (3, 2):
            words.extend("".join(tokens[i : i + span]) for i in range(len(tokens) - span + 1))
        words.extend(tokens)
    out: list[str] = []
    for word in words:
        word = word.split("|", 1)[0]
        cls = vocab.canonical_class(word)
        if cls is None or cls not in vocab.catalogue_types or cls in out:
            continue
        out.append(cls)
    # Slices and cracked eggs are made by the plan's own actions, not found in the
    # scene, unless nothing in the scene could produce them.
    derived = {
        d for t in out for key in ("slicedType", "crackedType") for d in vocab.annotation(t, key)
    }
    return [t for t in out if t not in derived]


def _step_tokens(step: str) -> list[str]:
    return step.replace("(", " ").replace(")", " ").replace(",", " ").split()


def _class_in_words(words: list[str], vocab: Vocabulary) -> str | None:
    """The class a run of words names ('dining table', 'StoveKnob', 'apples')."""
    joined = term_key("".join(words))
    if not joined:
        return None
    cls = vocab.canonical_class(joined)
    if cls is not None:
        return cls
    singular = {c for f in singular_forms(joined) if (c := vocab.canonical_class(f))}
    return singular.pop() if len(singular) == 1 else None


def _step_names(tokens: list[str], vocab: Vocabulary) -> list[str]:
    """Class names a step's words spell, longest first, so 'soap bottle' is a
    SoapBottle and not also a Bottle, exactly as the CamelCase plan would be."""
    out: list[str] = []
    i = 0
    while i < len(tokens):
        for span in range(min(MAX_NAME_WORDS, len(tokens) - i), 0, -1):
            cls = _class_in_words(tokens[i : i + span], vocab)
            if cls is not None:
                out.append(cls)
                i += span
                break
        else:
            i += 1
    return out


def _numbered(steps: list[str], vocab: Vocabulary) -> dict[str, int]:
    """Type -> highest instance number a plan names ("find Mug 2", "find stove knob 2")."""
    out: dict[str, int] = {}
    for step in steps:
        tokens = _step_tokens(step)
        for j, number in enumerate(tokens):
            if not (number.isascii() and number.isdigit() and int(number) > 0):
                continue
            for span in range(min(MAX_NAME_WORDS, j), 0, -1):
                cls = _class_in_words(tokens[j - span : j], vocab)
                if cls is not None:
                    out[cls] = max(out.get(cls, 1), int(number))
                    break
    return out
