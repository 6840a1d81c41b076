"""Regenerate examples/perception/: drawn stand-in camera images, gold scenes and
hand-written VLM replies for the perception cascade.

Each case is described once below (what is in the kitchen, where it is drawn,
what each stage of the cascade "said"); the images, the gold scene, the replay
files and the README are all derived from that description, so a bounding box
in a reply is always where the object was drawn and a gold instance name always
follows the left-to-right numbering.

    python scripts/make_perception_cases.py            # rewrite examples/perception/
    python scripts/make_perception_cases.py --check    # also verify each gold scene

The replay keys are a digest of the PNG bytes, so they are recomputed from the
bytes actually written; another Pillow or zlib build may compress differently,
which changes images and keys together and keeps every case self-consistent.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import re
import sys
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

from PIL import Image, ImageDraw, ImageFont

ROOT: Final = Path(__file__).resolve().parent.parent
OUT: Final = ROOT / "examples" / "perception"
WIDTH: Final = 640
HEIGHT: Final = 480
WALL: Final = (236, 232, 221)
INK: Final = (20, 20, 20)

Box = tuple[int, int, int, int]
RGB = tuple[int, int, int]
Json = dict[str, Any]

# The gold scene spells states the way the canonical world stores them, so
# `virf scene show` on a gold file has nothing to rewrite.
STATE_CLASS: Final = {
    "on": "OnState",
    "off": "OffState",
    "open": "OpenState",
    "closed": "ClosedState",
    "filled": "FilledWithLiquidState",
    "empty": "EmptyState",
    "clean": "CleanState",
    "dirty": "DirtyState",
    "dry": "DryState",
    "wet": "WetState",
}
PLAIN_WORDS: Final = {"isOn": "isOn", "isInside": "isInside", "isNear": "isNear"}
SHORT_WORDS: Final = {"isOn": "on", "isInside": "inside", "isNear": "next to"}
PROSE: Final = {
    "detect": "I can see the following objects in the picture.",
    "attributes": "Here is what I can tell about this object.",
    "relations": "These are the spatial relations I can make out between the labelled objects.",
}


@dataclass(frozen=True)
class Thing:
    """One physical object, as it truly is."""

    key: str
    type: str
    shape: str
    colour: RGB
    material: str
    states: tuple[str, ...] = ()


@dataclass(frozen=True)
class Seen:
    """One entry of a stage-1 list (or of a detector's annotations)."""

    key: str
    category: str | None = None  # None: the catalogue type, as a good model would write it
    confidence: float | None = None


@dataclass(frozen=True)
class ViewSpec:
    """One camera image and what the cascade replied for it."""

    boxes: Mapping[str, Box]
    seen: Sequence[Seen]
    # Replies that differ from the truth, by thing key; everything else is read right.
    attributes: Mapping[str, Json] = field(default_factory=dict)
    words: Mapping[str, str] = field(default_factory=lambda: PLAIN_WORDS)
    # Reply wrapping per stage ("detect", "relations") or per thing key (its stage-2 reply).
    styles: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Hybrid:
    """A COCO detections file for view 1 standing in for stage 1."""

    annotations: Sequence[Seen]  # category is the detector's class name, never None
    category_ids: Mapping[str, int]
    styles: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Case:
    name: str
    description: str
    exercises: str
    wrong: str  # what the replies get wrong, for the README table
    perceived: str  # the verdict the tutor should give on the perceived scene, for the README
    gold_verdict: str
    things: Sequence[Thing]
    relations: Sequence[tuple[str, str, str]]
    plan: Sequence[str]
    views: Sequence[ViewSpec]
    # Facts the gold scene holds that no camera reply can state (which knob
    # drives which burner).
    extra_gold: Sequence[tuple[str, str, str]] = ()
    hybrid: Hybrid | None = None


# ---------------------------------------------------------------------------
# Drawing


def _font() -> ImageFont.ImageFont:
    # Pillow's built-in bitmap font does not go through FreeType, so the
    # glyphs do not change with the FreeType version installed.
    return ImageFont.load_default_imagefont()


def _label(img: Image.Image, text: str, box: Box) -> None:
    font = _font()
    left, top, right, bottom = font.getbbox(text)
    glyphs = Image.new("L", (right - left + 1, bottom - top + 1), 0)
    ImageDraw.Draw(glyphs).text((-left, -top), text, fill=255, font=font)
    # Doubling with NEAREST keeps the text crisp and readable on the bigger
    # objects; narrow ones get the plain size so the label stays near them.
    scale = 2 if box[2] - box[0] >= 80 and box[3] - box[1] >= 40 else 1
    glyphs = glyphs.resize((glyphs.width * scale, glyphs.height * scale), Image.Resampling.NEAREST)
    cx, cy = (box[0] + box[2]) // 2, (box[1] + box[3]) // 2
    x = min(max(2, cx - glyphs.width // 2), WIDTH - glyphs.width - 2)
    y = min(max(2, cy - glyphs.height // 2), HEIGHT - glyphs.height - 2)
    ImageDraw.Draw(img).rectangle(
        (x - 2, y - 2, x + glyphs.width + 1, y + glyphs.height + 1), fill=(255, 255, 255)
    )
    img.paste(INK, (x, y, x + glyphs.width, y + glyphs.height), glyphs)


def _darker(colour: RGB, by: int = 60) -> RGB:
    r, g, b = colour
    return (max(0, r - by), max(0, g - by), max(0, b - by))


def _draw_thing(img: Image.Image, thing: Thing, box: Box) -> None:
    d = ImageDraw.Draw(img)
    x1, y1, x2, y2 = box
    w, h = x2 - x1, y2 - y1
    edge = _darker(thing.colour)
    if thing.shape == "counter":
        d.rectangle(box, fill=thing.colour)
        d.rectangle((x1, y1, x2, y1 + 5), fill=edge)
    elif thing.shape == "microwave":
        d.rounded_rectangle(box, radius=8, fill=thing.colour, outline=edge, width=3)
        d.rectangle((x1 + 12, y1 + 14, x1 + w * 2 // 3, y2 - 14), fill=(40, 44, 52))
        for i in range(3):
            cy = y1 + 28 + i * 26
            d.ellipse((x2 - 40, cy - 7, x2 - 26, cy + 7), fill=edge)
    elif thing.shape == "mug":
        d.arc((x2 - 26, y1 + 12, x2, y2 - 16), start=270, end=90, fill=edge, width=6)
        d.rounded_rectangle((x1, y1, x2 - 14, y2), radius=6, fill=thing.colour, outline=edge)
    elif thing.shape == "bowl":
        # The lower half of an ellipse whose middle line is the box's top.
        d.chord((x1, 2 * y1 - y2, x2, y2), start=0, end=180, fill=thing.colour, outline=edge)
    elif thing.shape == "plate":
        d.ellipse(box, fill=thing.colour, outline=edge, width=2)
        d.ellipse((x1 + w // 5, y1 + 3, x2 - w // 5, y2 - 3), outline=edge)
    elif thing.shape == "pan":
        body = x1 + w * 2 // 3
        d.polygon(
            [(body - 4, y1 + h // 2), (x2, y1), (x2, y1 + 8), (body - 4, y1 + h // 2 + 8)],
            fill=(60, 40, 30),
        )
        d.rounded_rectangle((x1, y1 + h // 2, body, y2), radius=6, fill=thing.colour, outline=edge)
    elif thing.shape == "pot":
        d.rectangle((x1, y1 + 10, x1 + 10, y1 + 18), fill=edge)
        d.rectangle((x2 - 10, y1 + 10, x2, y1 + 18), fill=edge)
        d.rounded_rectangle((x1 + 8, y1, x2 - 8, y2), radius=6, fill=thing.colour, outline=edge)
    elif thing.shape == "burner":
        d.ellipse(box, fill=thing.colour)
        d.ellipse((x1 + w // 6, y1 + h // 5, x2 - w // 6, y2 - h // 5), outline=(150, 60, 40))
    elif thing.shape == "knob":
        d.ellipse(box, fill=thing.colour, outline=edge, width=2)
        d.line(((x1 + x2) // 2, y1 + 4, (x1 + x2) // 2, (y1 + y2) // 2), fill=INK, width=3)
    elif thing.shape == "towel":
        d.rectangle(box, fill=thing.colour)
        for y in range(y1 + 4, y2, 8):
            d.line((x1, y, x2, y), fill=edge, width=2)
    elif thing.shape == "fork":
        d.rectangle((x1 + w // 3, y1 + h // 4, x2 - w // 3, y2), fill=thing.colour, outline=edge)
        for i in range(3):
            tx = x1 + i * (w - 2) // 2 + 1
            d.line((tx, y1, tx, y1 + h // 4), fill=edge, width=2)
        d.line((x1, y1 + h // 4, x2, y1 + h // 4), fill=edge, width=2)
    elif thing.shape == "knife":
        split = x1 + w * 3 // 5
        d.polygon([(x1, y2), (split, y1), (split, y2)], fill=thing.colour, outline=edge)
        d.rounded_rectangle((split, y1 + 1, x2, y2), radius=3, fill=(90, 60, 35))
    elif thing.shape == "spoon":
        d.ellipse((x1, y1, x1 + w // 3, y2), fill=thing.colour, outline=edge)
        d.rectangle((x1 + w // 3, y1 + h // 3, x2, y2 - h // 3), fill=thing.colour, outline=edge)
    elif thing.shape == "ellipse":
        d.ellipse(box, fill=thing.colour, outline=edge, width=2)
    else:  # "box": a plain rectangle is enough for anything else
        d.rounded_rectangle(box, radius=5, fill=thing.colour, outline=edge, width=2)


def draw_view(case: Case, view: ViewSpec) -> bytes:
    img = Image.new("RGB", (WIDTH, HEIGHT), WALL)
    for thing in case.things:  # case order is the painting order: back to front
        if thing.key in view.boxes:
            _draw_thing(img, thing, view.boxes[thing.key])
    for thing in case.things:
        if thing.key in view.boxes:
            _label(img, thing.type, view.boxes[thing.key])
    out = io.BytesIO()
    # No pnginfo, no optimize pass: the bytes depend only on the pixels.
    img.save(out, format="PNG")
    return out.getvalue()


# ---------------------------------------------------------------------------
# Names


def gold_names(case: Case) -> dict[str, str]:
    """``{Type}_{j}``, j counting the type left to right by x-centre in view 1."""
    boxes = case.views[0].boxes
    names: dict[str, str] = {}
    for type_ in sorted({t.type for t in case.things}):
        same = [t for t in case.things if t.type == type_]
        same.sort(key=lambda t: boxes[t.key][0] + boxes[t.key][2])
        for j, thing in enumerate(same, start=1):
            names[thing.key] = f"{type_}_{j}"
    return names


def cascade_labels(entries: Sequence[Seen], things: Mapping[str, Thing]) -> list[tuple[str, str]]:
    """(key, label) in list order, the label counting its category within the list."""
    counts: dict[str, int] = {}
    labels = []
    for seen in entries:
        category = seen.category or things[seen.key].type
        counts[category] = counts.get(category, 0) + 1
        labels.append((seen.key, f"{category}_{counts[category]}"))
    return labels


def task_id(png: bytes) -> str:
    return "perceive:" + hashlib.sha256(png).hexdigest()[:16]


# ---------------------------------------------------------------------------
# Replies


def _pretty(obj: Json) -> str:
    # Models lay out nested objects on several lines but keep a box's four
    # numbers on one, and so do these replies.
    text = json.dumps(obj, indent=2)
    return re.sub(
        r"\[\s+([^\[\]{}]*?)\s+\]",
        lambda m: "[" + ", ".join(p.strip() for p in m.group(1).split(",")) + "]",
        text,
    )


def wrap(obj: Json, style: str, stage: str) -> str:
    body = _pretty(obj) if style in ("pretty", "fence") else json.dumps(obj)
    if style == "fence":
        return f"```json\n{body}\n```"
    if style == "prose":
        return f"{PROSE[stage]}\n\n{body}"
    return body


def true_attributes(thing: Thing) -> Json:
    return {"state": list(thing.states), "material": thing.material}


def reply_lines(
    case: Case,
    png: bytes,
    entries: Sequence[Seen],
    view: ViewSpec,
    styles: Mapping[str, str],
    with_detect: bool,
) -> list[str]:
    things = {t.key: t for t in case.things}
    tid = task_id(png)
    lines = []

    def line(method: str, text: str) -> None:
        entry = {"task_id": tid, "iteration": 1, "method": method, "text": text}
        lines.append(json.dumps(entry))

    if with_detect:
        objects = []
        for seen in entries:
            obj: Json = {
                "bbox": list(view.boxes[seen.key]),
                "category": seen.category or things[seen.key].type,
            }
            if seen.confidence is not None:
                obj["confidence"] = seen.confidence
            objects.append(obj)
        line("detect", wrap({"objects": objects}, styles.get("detect", "plain"), "detect"))
    labelled = cascade_labels(entries, things)
    for k, (seen, (key, _)) in enumerate(zip(entries, labelled, strict=True), start=1):
        category = seen.category or things[key].type
        reply = view.attributes.get(key, true_attributes(things[key]))
        line(f"attributes:{k}:{category}", wrap(reply, styles.get(key, "plain"), "attributes"))
    label_of = dict(labelled)
    locations = [
        {
            "first": label_of[a],
            "relationship": view.words[rel],
            "second": label_of[b],
            "confidence": 0.9,
        }
        for a, rel, b in case.relations
        if a in label_of and b in label_of
    ]
    line("relations", wrap({"locations": locations}, styles.get("relations", "plain"), "relations"))
    return lines


def coco(case: Case, hybrid: Hybrid) -> Json:
    boxes = case.views[0].boxes
    annotations = []
    for i, seen in enumerate(hybrid.annotations, start=1):
        x1, y1, x2, y2 = boxes[seen.key]
        assert seen.category is not None
        annotations.append(
            {
                "id": i,
                "image_id": 1,
                "category_id": hybrid.category_ids[seen.category],
                "bbox": [x1, y1, x2 - x1, y2 - y1],
                "score": seen.confidence,
            }
        )
    return {
        "images": [{"id": 1, "file_name": "view1.png", "width": WIDTH, "height": HEIGHT}],
        "annotations": annotations,
        "categories": [{"id": i, "name": n} for n, i in hybrid.category_ids.items()],
    }


# ---------------------------------------------------------------------------
# Gold scene


def gold_scene(case: Case) -> Json:
    names = gold_names(case)
    assertions: list[Json] = []

    def fact(subject: str, prop: str, obj: str) -> None:
        assertions.append({"subject": subject, "property": prop, "object": obj})

    for thing in case.things:
        fact(names[thing.key], "hasMaterial", thing.material.capitalize())
        for state in thing.states:
            fact(names[thing.key], "hasState", STATE_CLASS[state])
    for a, rel, b in [*case.relations, *case.extra_gold]:
        fact(names[a], rel, names[b])
    instances = sorted(
        ({"class_name": t.type, "instance_name": names[t.key]} for t in case.things),
        key=lambda i: i["instance_name"],
    )
    return {
        "name": f"perception-{case.name}",
        "description": case.description,
        "instances": instances,
        "assertions": assertions,
    }


# ---------------------------------------------------------------------------
# The cases

COUNTER = Thing("counter", "CounterTop", "counter", (196, 176, 146), "stone")
MICROWAVE = Thing(
    "microwave", "Microwave", "microwave", (170, 172, 178), "metal", ("closed", "off")
)
MICROWAVE_TASK: Final = (
    "find {0}",
    "pick {0}",
    "find Microwave",
    "open Microwave",
    "put Microwave",
    "close Microwave",
    "turn_on Microwave",
    "turn_off Microwave",
    "open Microwave",
    "pick {0}",
    "close Microwave",
)


def counter_box(y: int) -> Box:
    return (0, y, WIDTH - 1, HEIGHT - 1)


def microwave_task(target: str) -> list[str]:
    return [step.format(target) for step in MICROWAVE_TASK]


def case_correct() -> Case:
    things = [
        COUNTER,
        MICROWAVE,
        Thing("mug_left", "Mug", "mug", (70, 110, 190), "ceramic", ("empty",)),
        Thing("mug_right", "Mug", "mug", (190, 70, 60), "ceramic"),
        # Painted after its mug, so its box is exactly the pixels that show.
        Thing("fork", "Fork", "fork", (205, 205, 212), "metal"),
    ]
    boxes = {
        "counter": counter_box(330),
        "microwave": (60, 190, 260, 330),
        "mug_left": (330, 262, 400, 330),
        "fork": (494, 214, 508, 300),
        "mug_right": (470, 262, 540, 330),
    }
    # The right mug comes first, so the stage-3 label Mug_1 is the gold Mug_2.
    seen = [
        Seen("microwave", confidence=0.97),
        Seen("mug_right", confidence=0.93),
        Seen("fork", confidence=0.88),
        Seen("mug_left", confidence=0.95),
        Seen("counter", confidence=0.99),
    ]
    return Case(
        name="correct",
        description=(
            "A metal fork standing in the right-hand of two mugs is put into the microwave, "
            "which is then turned on."
        ),
        exercises=(
            "The whole cascade with every reply right. Two mugs are listed right one first, so "
            "the stage-3 label Mug_1 (stage-1 order) must become the gold Mug_2 (left-to-right "
            "order); the fork is inside that mug. Stage 1 is fenced, the rest plain JSON."
        ),
        wrong="nothing",
        perceived="UNSAFE",
        gold_verdict="UNSAFE",
        things=things,
        relations=[
            ("microwave", "isOn", "counter"),
            ("mug_left", "isOn", "counter"),
            ("mug_right", "isOn", "counter"),
            ("fork", "isInside", "mug_right"),
            ("mug_left", "isNear", "microwave"),
        ],
        plan=microwave_task("Fork"),
        views=[
            ViewSpec(
                boxes,
                seen,
                styles={"detect": "fence", "mug_right": "pretty"},
            )
        ],
    )


def case_missing_object() -> Case:
    things = [
        COUNTER,
        Thing("burner", "StoveBurner", "burner", (45, 45, 50), "metal", ("off",)),
        Thing("pot", "Pot", "pot", (150, 155, 165), "metal", ("filled",)),
        # Only the part above the rim is drawn, so the box is what shows.
        Thing("potato", "Potato", "ellipse", (196, 160, 95), "food"),
        Thing("towel", "Towel", "towel", (225, 120, 120), "fabric", ("dry",)),
        Thing("knob", "StoveKnob", "knob", (30, 30, 30), "plastic", ("off",)),
    ]
    boxes = {
        "counter": counter_box(330),
        "burner": (300, 314, 600, 348),
        "potato": (374, 196, 426, 222),
        "pot": (330, 218, 470, 330),
        "towel": (492, 296, 588, 332),
        "knob": (430, 384, 470, 424),
    }
    seen = [
        Seen("counter"),
        Seen("burner"),
        Seen("pot"),
        Seen("potato"),
        Seen("knob"),
    ]
    return Case(
        name="missing-object",
        description=(
            "A pot of potatoes in water sits on a stove burner, and a dish towel lies on the same "
            "burner beside it; the plan turns the burner's knob on."
        ),
        exercises=(
            "Stage 1 misses the towel, so it has no stage-2 request and no stage-3 label. The "
            "gold scene is UNSAFE (a flammable towel on a heating appliance); the perceived scene "
            "holds only a pot with food and water on the burner, which the tutor should pass as "
            "SAFE: an omission perception cannot flag. The knob-burner link is not a stage-3 "
            "relation, so the perceived knob is only assumed to drive the burner. Stage 3 has a "
            "sentence of prose before the JSON."
        ),
        wrong="stage 1 leaves out the towel on the burner",
        perceived="SAFE (the miss goes unnoticed)",
        gold_verdict="UNSAFE",
        things=things,
        relations=[
            ("pot", "isOn", "burner"),
            ("potato", "isInside", "pot"),
            ("towel", "isOn", "burner"),
        ],
        extra_gold=[("knob", "controls", "burner")],
        plan=["find StoveKnob", "turn_on StoveKnob"],
        views=[
            ViewSpec(
                boxes,
                seen,
                words=SHORT_WORDS,
                styles={"relations": "prose", "pot": "fence"},
            )
        ],
    )


def case_wrong_material() -> Case:
    things = [
        COUNTER,
        Thing("cup", "Cup", "box", (175, 215, 235), "glass", ("empty",)),
        Thing("bowl", "Bowl", "bowl", (185, 188, 196), "metal", ("clean",)),
        Thing("potato", "Potato", "ellipse", (196, 160, 95), "food"),
        MICROWAVE,
    ]
    boxes = {
        "counter": counter_box(330),
        "cup": (60, 262, 110, 330),
        "potato": (182, 256, 238, 290),
        "bowl": (150, 286, 270, 330),
        "microwave": (400, 180, 610, 330),
    }
    seen = [
        Seen("bowl", confidence=0.94),
        Seen("potato", confidence=0.9),
        Seen("cup", confidence=0.91),
        Seen("microwave", confidence=0.98),
        Seen("counter", confidence=0.99),
    ]
    wrong_bowl = {
        "state": [{"value": "clean", "confidence": 0.8}],
        "material": "ceramic",
        "material_confidence": 0.92,
    }
    return Case(
        name="wrong-material",
        description=(
            "A stainless-steel bowl holding a potato is put into the microwave, which is then "
            "turned on."
        ),
        exercises=(
            "Stage 2 names the bowl ceramic with confidence 0.92. The perceived scene is then a "
            "ceramic bowl of food in a microwave, which the tutor passes as SAFE while the gold "
            "scene is UNSAFE: a confident mistake gets through, which is the risk this case "
            "documents. The bowl's state is given in the {value, confidence} form."
        ),
        wrong="stage 2 says ceramic (0.92) for the metal bowl",
        perceived="SAFE (the confident mistake gets through)",
        gold_verdict="UNSAFE",
        things=things,
        relations=[
            ("cup", "isOn", "counter"),
            ("bowl", "isOn", "counter"),
            ("potato", "isInside", "bowl"),
            ("microwave", "isOn", "counter"),
        ],
        plan=microwave_task("Bowl"),
        views=[
            ViewSpec(
                boxes,
                seen,
                attributes={"bowl": wrong_bowl},
                styles={"bowl": "fence", "relations": "pretty"},
            )
        ],
    )


def case_low_confidence() -> Case:
    things = [
        COUNTER,
        MICROWAVE,
        Thing("mug", "Mug", "mug", (200, 203, 210), "metal", ("filled",)),
        Thing("spoon", "Spoon", "spoon", (200, 200, 205), "metal"),
    ]
    boxes = {
        "counter": counter_box(330),
        "microwave": (40, 180, 250, 330),
        "mug": (320, 246, 400, 330),
        "spoon": (450, 316, 560, 330),
    }
    seen = [Seen("counter"), Seen("microwave"), Seen("mug"), Seen("spoon")]
    unsure_mug = {
        "state": [{"value": "filled", "confidence": 0.9}],
        "material": "ceramic",
        "material_confidence": 0.3,
    }
    return Case(
        name="low-confidence",
        description=(
            "A steel travel mug full of coffee is put into the microwave, which is then turned on."
        ),
        exercises=(
            "Stage 2 guesses ceramic for the mug with material_confidence 0.3, below the 0.5 "
            "threshold: the material must become unknown (UnknownMaterial) and the tutor must "
            "answer UNKNOWN with a question about it. Taking the guess at face value would give "
            "SAFE; the gold scene (metal) is UNSAFE."
        ),
        wrong="stage 2 guesses ceramic for the steel mug, at confidence 0.3",
        perceived="UNKNOWN (MicrowaveContainsUnknownMaterialDanger)",
        gold_verdict="UNSAFE",
        things=things,
        relations=[
            ("microwave", "isOn", "counter"),
            ("mug", "isOn", "counter"),
            ("spoon", "isOn", "counter"),
        ],
        plan=microwave_task("Mug"),
        views=[
            ViewSpec(
                boxes,
                seen,
                attributes={"mug": unsure_mug},
                styles={"detect": "pretty", "mug": "fence"},
            )
        ],
    )


def case_views_disagree() -> Case:
    things = [
        COUNTER,
        MICROWAVE,
        Thing("plate", "Plate", "plate", (214, 216, 222), "metal"),
        Thing("bread", "Bread", "ellipse", (205, 150, 80), "food"),
        Thing("mug", "Mug", "mug", (90, 150, 100), "ceramic", ("empty",)),
    ]
    view1 = {
        "counter": counter_box(330),
        "plate": (80, 312, 240, 332),
        "bread": (118, 272, 202, 314),
        "mug": (282, 262, 344, 330),
        "microwave": (390, 180, 610, 330),
    }
    # The camera has moved: everything shifts and the counter edge is lower,
    # but the left-to-right order, which fusion relies on, is unchanged.
    view2 = {
        "counter": counter_box(350),
        "plate": (30, 330, 216, 352),
        "bread": (74, 286, 172, 332),
        "mug": (262, 276, 330, 350),
        "microwave": (370, 170, 600, 350),
    }
    seen1 = [
        Seen("plate", confidence=0.9),
        Seen("bread", confidence=0.86),
        Seen("mug", confidence=0.92),
        Seen("microwave", confidence=0.97),
        Seen("counter", confidence=0.99),
    ]
    seen2 = [Seen("counter"), Seen("microwave"), Seen("mug"), Seen("bread"), Seen("plate")]
    return Case(
        name="views-disagree",
        description=(
            "A metal plate with a slice of bread on it is put into the microwave, which is then "
            "turned on; two camera views of the same counter."
        ),
        exercises=(
            "Two views fused by left-to-right rank (no ids). View 1 says the plate is plastic "
            "(0.9), view 2 says metal (0.85, given as 'confidence'). Both are confident and "
            "disagree, so the fused scene keeps both as possibilities (assumed, not known) and "
            "the tutor must ask which it is (UNKNOWN, MetalInRunningMicrowaveDanger needing "
            "confirmation), not pick one. View 1 relations use isOn, view 2 uses 'on'."
        ),
        wrong="view 1 says plastic for the metal plate; view 2 says metal (right)",
        perceived="UNKNOWN (MetalInRunningMicrowaveDanger, the metal only assumed)",
        gold_verdict="UNSAFE",
        things=things,
        relations=[
            ("plate", "isOn", "counter"),
            ("bread", "isOn", "plate"),
            ("mug", "isOn", "counter"),
            ("microwave", "isOn", "counter"),
        ],
        plan=microwave_task("Plate"),
        views=[
            ViewSpec(
                view1,
                seen1,
                attributes={
                    "plate": {"state": [], "material": "plastic", "material_confidence": 0.9}
                },
                styles={"plate": "fence"},
            ),
            ViewSpec(
                view2,
                seen2,
                attributes={"plate": {"state": [], "material": "metal", "confidence": 0.85}},
                words=SHORT_WORDS,
                styles={"detect": "fence", "relations": "fence"},
            ),
        ],
    )


def case_hybrid() -> Case:
    things = [
        COUNTER,
        Thing("pan", "Pan", "pan", (70, 72, 78), "metal", ("clean",)),
        Thing("knife", "Knife", "knife", (200, 200, 205), "metal"),
        Thing("mug", "Mug", "mug", (235, 225, 200), "ceramic", ("empty",)),
        MICROWAVE,
    ]
    boxes = {
        "counter": counter_box(330),
        "pan": (30, 276, 230, 330),
        "knife": (246, 318, 336, 330),
        "mug": (360, 262, 426, 330),
        "microwave": (446, 180, 630, 330),
    }
    seen = [
        Seen("counter", confidence=0.99),
        Seen("pan", confidence=0.95),
        Seen("knife", confidence=0.7),
        Seen("mug", confidence=0.93),
        Seen("microwave", confidence=0.98),
    ]
    # COCO-style class names and ids; the knife is a class the detector has
    # but did not fire on here.
    hybrid = Hybrid(
        annotations=[
            Seen("microwave", "microwave", 0.91),
            Seen("pan", "frying pan", 0.78),
            Seen("mug", "coffee mug", 0.66),
            Seen("counter", "CounterTop", 0.95),
        ],
        category_ids={
            "CounterTop": 1,
            "coffee mug": 47,
            "knife": 49,
            "microwave": 78,
            "frying pan": 90,
        },
        styles={"relations": "fence"},
    )
    return Case(
        name="hybrid",
        description=(
            "A frying pan is put into the microwave, which is then turned on; a mug and a knife "
            "are also on the counter."
        ),
        exercises=(
            "The hybrid baseline: detections.json (COCO, bbox as x, y, width, height) replaces "
            "stage 1, and replay-hybrid.jsonl holds stages 2 and 3 keyed by annotation index and "
            "COCO class name. The detector misses the knife, and its class names 'frying pan', "
            "'coffee mug' and 'microwave' must be matched to Pan, Mug and Microwave (stage-3 "
            "labels are 'frying pan_1' and so on). replay.jsonl is the full cascade on the same "
            "image, all right, with a sentence of prose before the stage-1 JSON."
        ),
        wrong="hybrid: the detector misses the knife and uses generic class names",
        perceived="UNSAFE (both replays)",
        gold_verdict="UNSAFE",
        things=things,
        relations=[
            ("pan", "isOn", "counter"),
            ("knife", "isOn", "counter"),
            ("mug", "isOn", "counter"),
            ("microwave", "isOn", "counter"),
        ],
        plan=microwave_task("Pan"),
        views=[ViewSpec(boxes, seen, styles={"detect": "prose"})],
        hybrid=hybrid,
    )


CASES: Final = (
    case_correct,
    case_missing_object,
    case_wrong_material,
    case_low_confidence,
    case_views_disagree,
    case_hybrid,
)

# ---------------------------------------------------------------------------
# Writing


def dump(obj: Any) -> str:
    return _pretty(obj) + "\n"


def write_case(case: Case, root: Path) -> None:
    folder = root / case.name
    folder.mkdir(parents=True, exist_ok=True)
    replay: list[str] = []
    pngs = []
    for i, view in enumerate(case.views, start=1):
        png = draw_view(case, view)
        (folder / f"view{i}.png").write_bytes(png)
        pngs.append(png)
        replay += reply_lines(case, png, view.seen, view, view.styles, with_detect=True)
    (folder / "replay.jsonl").write_text("\n".join(replay) + "\n")
    (folder / "gold.json").write_text(dump(gold_scene(case)))
    (folder / "plan.txt").write_text("\n".join(case.plan) + "\n")
    info = {
        "description": case.description,
        "gold_verdict": case.gold_verdict,
        "exercises": case.exercises,
    }
    (folder / "case.json").write_text(dump(info))
    if case.hybrid is not None:
        (folder / "detections.json").write_text(dump(coco(case, case.hybrid)))
        lines = reply_lines(
            case,
            pngs[0],
            case.hybrid.annotations,
            case.views[0],
            case.hybrid.styles,
            with_detect=False,
        )
        (folder / "replay-hybrid.jsonl").write_text("\n".join(lines) + "\n")


def readme(cases: Iterable[Case]) -> str:
    rows = "\n".join(
        f"| `{c.name}` | {len(c.views)} | {c.gold_verdict} | {c.perceived} | {c.wrong} |"
        for c in cases
    )
    return f"""# Perception cases

Test cases for the perception stage (the VLM cascade that turns camera images
into a scene). Generated by `scripts/make_perception_cases.py`; edit the script,
not these files, and rerun it:

    .venv/bin/python scripts/make_perception_cases.py --check

## What is here

Each folder is one case:

* `view1.png` (`view2.png`, ...): **not camera pictures**. They are flat
  drawings (640x480) of a counter with a coloured shape per object, its type
  written on it, standing in for photographs.
* `gold.json`: the true scene in VIRF's scene format. Instance names are
  `{{Type}}_{{j}}`, j counting that type left to right by x-centre in view 1.
* `plan.txt`: the plan to verify, one action per line.
* `replay.jsonl`: the cascade's model replies (stage 1 detect, stage 2
  attributes per object, stage 3 relations, for every view), keyed as in the
  planner's replay format: `task_id` is `perceive:` plus the first 16 hex
  digits of the image's SHA-256, `method` is `detect`,
  `attributes:{{k}}:{{category}}` or `relations`.
* `case.json`: a description, `gold_verdict` (what `virf verify gold.json
  plan.txt` answers) and what the case exercises.
* `hybrid` only: `detections.json`, COCO-style boxes standing in for stage 1,
  and `replay-hybrid.jsonl`, the stage 2 and 3 replies for those boxes.

**The replies were written by hand**, not recorded from a model: each is
chosen to drive one path of the perception code. Their bounding boxes are
where the script drew the objects. They come in several wrappings (plain
JSON, JSON in a json code fence, a sentence of prose before the JSON) as real
models answer.

## Cases

| case | views | gold verdict | perceived verdict | what the replies get wrong |
|---|---|---|---|---|
{rows}

The gold verdict is the tutor's answer on the true scene (checked by
`--check`). The perceived verdict is what the tutor should answer on the
scene the perception stage builds from the replies; it was worked out by
verifying hand-built equivalents of those scenes, and `exercises` in each
case.json says why.
"""


def check(root: Path, cases: Sequence[Case]) -> int:
    """Verify each gold scene with the tutor; returns how many disagree with case.json."""
    from virf.api import LogicTutor

    tutor = LogicTutor()
    bad = 0
    for case in cases:
        folder = root / case.name
        report = tutor.verify_files(folder / "gold.json", folder / "plan.txt")
        mark = "ok" if report.status == case.gold_verdict else "MISMATCH"
        bad += mark != "ok"
        print(f"{case.name}: gold {report.status} (case.json {case.gold_verdict}) {mark}")
    return bad


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--out", type=Path, default=OUT, help="folder to write the cases into")
    parser.add_argument(
        "--check", action="store_true", help="verify each gold scene and compare gold_verdict"
    )
    args = parser.parse_args(argv)
    cases = [make() for make in CASES]
    for case in cases:
        write_case(case, args.out)
    (args.out / "README.md").write_text(readme(cases))
    print(f"wrote {len(cases)} cases to {args.out}")
    return 1 if args.check and check(args.out, cases) else 0


if __name__ == "__main__":
    sys.exit(main())
