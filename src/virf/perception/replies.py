"""The vision model's replies, read as leniently as plans are.

A model prompted as in the paper answers with one JSON object, but real
models wrap it in markdown fences, put a sentence before it, or use a
neighbouring key name (``label`` for ``category``).  All of that is read.
What cannot be read (no JSON object, a box that is not four numbers, a
confidence outside 0..1) is an ``UnreadableReply`` naming the problem, so
that a reply is never taken for an empty scene.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final

from virf.errors import InputError, clip

_FENCE: Final = re.compile(r"```(?:json|JSON)?\s*(.*?)```", re.DOTALL)
_CATEGORY_KEYS: Final = ("category", "label", "name", "class")
_BOX_KEYS: Final = ("bbox", "box", "bounding_box")


class UnreadableReply(InputError):
    """A stage's reply that holds no usable answer."""


@dataclass(frozen=True)
class Seen:
    """A value with the model's confidence in it (None: the model gave none)."""

    value: str
    confidence: float | None = None


@dataclass(frozen=True)
class Detection:
    category: str
    bbox: tuple[float, float, float, float] | None
    confidence: float | None
    track: str | None = None  # the same physical object across views


@dataclass(frozen=True)
class Attributes:
    states: tuple[Seen, ...]
    material: Seen | None


@dataclass(frozen=True)
class Location:
    first: str
    relationship: str
    second: str
    confidence: float | None


def json_object(text: str) -> dict[str, Any]:
    """The first JSON object in ``text``: the whole text, a fenced block, or
    the first ``{`` from which an object parses."""
    candidates = [text.strip(), *(m.strip() for m in _FENCE.findall(text))]
    for candidate in candidates:
        try:
            found = json.loads(candidate)
        except (ValueError, RecursionError):  # ValueError: also an integer of 4,300+ digits
            continue
        if isinstance(found, dict):
            return found
    decoder = json.JSONDecoder()
    for match in re.finditer(r"\{", text):
        try:
            found, _ = decoder.raw_decode(text, match.start())
        except (ValueError, RecursionError):
            continue
        if isinstance(found, dict):
            return found
    raise UnreadableReply(f"the reply holds no JSON object: '{_shown(text)}'")


def _shown(text: str) -> str:
    return clip(" ".join(text.split()), 80)


def _finite(value: Any) -> bool:
    """A JSON number a float can hold (an integer of 400 digits cannot)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


def _confidence(item: Mapping[str, Any], where: str, *keys: str) -> float | None:
    for key in keys:
        if key in item and item[key] is not None:
            value = item[key]
            if not _finite(value) or not 0 <= value <= 1:
                raise UnreadableReply(
                    f"{where}: '{key}' must be a number from 0 to 1, not {value!r}"
                )
            return float(value)
    return None


def _text(item: Mapping[str, Any], keys: Sequence[str], where: str) -> str:
    for key in keys:
        value = item.get(key)
        if isinstance(value, str) and value.strip():
            return " ".join(value.split())
    raise UnreadableReply(f"{where} has no '{keys[0]}' text")


def _list(data: Mapping[str, Any], keys: Sequence[str], what: str) -> list[Any]:
    for key in keys:
        if key in data:
            value = data[key]
            if not isinstance(value, list):
                raise UnreadableReply(f"'{key}' must be a list, not {type(value).__name__}")
            return value
    raise UnreadableReply(f"the reply has no '{keys[0]}' list ({what})")


def read_detections(text: str) -> tuple[Detection, ...]:
    """Stage 1: ``{"objects": [{"bbox": [x1, y1, x2, y2], "category": ...}]}``."""
    items = _list(json_object(text), ("objects", "detections"), "the objects seen")
    out = []
    for n, item in enumerate(items, start=1):
        where = f"object {n}"
        if not isinstance(item, dict):
            raise UnreadableReply(f"{where} is not a JSON object")
        category = _text(item, _CATEGORY_KEYS, where)
        box = next((item[k] for k in _BOX_KEYS if item.get(k) is not None), None)
        bbox: tuple[float, float, float, float] | None = None
        if box is not None:
            if not isinstance(box, list) or len(box) != 4 or not all(_finite(v) for v in box):
                raise UnreadableReply(f"{where}: bbox must be four numbers, not {_shown(str(box))}")
            bbox = (float(box[0]), float(box[1]), float(box[2]), float(box[3]))
        track = item.get("id")
        out.append(
            Detection(
                category,
                bbox,
                _confidence(item, where, "confidence", "score"),
                str(track)
                if isinstance(track, str | int) and not isinstance(track, bool)
                else None,
            )
        )
    return tuple(out)


def _seen(value: Any, where: str, confidence: float | None = None) -> Seen:
    if isinstance(value, str) and value.strip():
        return Seen(" ".join(value.split()), confidence)
    if isinstance(value, dict):
        text = _text(value, ("value", "state", "material", "name"), where)
        own = _confidence(value, where, "confidence", "score")
        return Seen(text, own if own is not None else confidence)
    raise UnreadableReply(f"{where} must be a word, not {_shown(json.dumps(value))}")


def read_attributes(text: str) -> Attributes:
    """Stage 2: ``{"state": [...], "material": "..." or "unknown"}``."""
    data = json_object(text)
    if not any(k in data for k in ("state", "states", "material")):
        raise UnreadableReply("the reply has neither 'state' nor 'material'")
    states_raw: Any = data.get("state", data.get("states", []))
    if isinstance(states_raw, str | dict):
        states_raw = [states_raw]
    if not isinstance(states_raw, list):
        raise UnreadableReply("'state' must be a list of words")
    states = tuple(
        _seen(s, f"state {n}") for n, s in enumerate(states_raw, start=1) if s not in ("", None)
    )
    material = None
    if data.get("material") not in (None, ""):
        confidence = _confidence(data, "the reply", "material_confidence", "confidence")
        material = _seen(data["material"], "material", confidence)
    return Attributes(states, material)


def read_locations(text: str) -> tuple[Location, ...]:
    """Stage 3: ``{"locations": [{"first", "relationship", "second"}]}``."""
    items = _list(
        json_object(text), ("locations", "relations", "relationships"), "the relationships seen"
    )
    out = []
    for n, item in enumerate(items, start=1):
        where = f"relationship {n}"
        if not isinstance(item, dict):
            raise UnreadableReply(f"{where} is not a JSON object")
        out.append(
            Location(
                _text(item, ("first", "subject"), where),
                _text(item, ("relationship", "relation", "predicate"), where),
                _text(item, ("second", "object"), where),
                _confidence(item, where, "confidence", "score"),
            )
        )
    return tuple(out)
