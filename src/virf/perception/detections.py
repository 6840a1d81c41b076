"""Boxes from an object detector, for the paper's hybrid baseline.

Any detector can feed it through the COCO format most of them export::

    {"images": [{"id": 1, "file_name": "view1.jpg"}],
     "annotations": [{"image_id": 1, "category_id": 3,
                      "bbox": [x, y, width, height], "score": 0.82}],
     "categories": [{"id": 3, "name": "mug"}]}

Boxes are COCO's ``[x, y, width, height]`` in pixels; ``score`` (optional)
becomes the detection's confidence.  Images are matched to views by file name.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from virf.errors import InputError, clip, closest, read_json_file
from virf.perception.replies import Detection


def _number(value: Any) -> bool:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:  # an integer of 400 digits
        return False


def _id(value: Any) -> bool:
    """COCO ids are numbers or strings; ``true`` would equal 1 as a key."""
    return isinstance(value, int | str) and not isinstance(value, bool)


def load_detections(path: str | Path) -> dict[str, tuple[Detection, ...]]:
    """Image file name -> its detections, in the file's order."""
    where = f"detections file {path}"
    data = read_json_file(path, "detections")
    if not isinstance(data, dict) or not all(
        isinstance(data.get(k), list) for k in ("images", "annotations", "categories")
    ):
        raise InputError(
            f"{where} must be COCO JSON with 'images', 'annotations' and 'categories' lists"
        )
    names: dict[Any, str] = {}
    for n, image in enumerate(data["images"], start=1):
        if (
            not isinstance(image, dict)
            or not _id(image.get("id"))
            or not isinstance(image.get("file_name"), str)
        ):
            raise InputError(
                f"{where}: images[{n}] needs a number or string 'id' and a 'file_name'"
            )
        name = Path(image["file_name"]).name
        if image["id"] in names:
            raise InputError(f"{where}: images[{n}] repeats the id {clip(repr(image['id']))}")
        if name in names.values():
            # Views are told apart by file name: two images of one name would merge.
            raise InputError(f"{where}: images[{n}] repeats the file name {clip(name)}")
        names[image["id"]] = name
    categories: dict[Any, str] = {}
    for n, cat in enumerate(data["categories"], start=1):
        if (
            not isinstance(cat, dict)
            or not _id(cat.get("id"))
            or not isinstance(cat.get("name"), str)
        ):
            raise InputError(f"{where}: categories[{n}] needs a number or string 'id' and a 'name'")
        if cat["id"] in categories:
            raise InputError(f"{where}: categories[{n}] repeats the id {clip(repr(cat['id']))}")
        categories[cat["id"]] = " ".join(cat["name"].split())
    out: dict[str, list[Detection]] = {name: [] for name in names.values()}
    for n, ann in enumerate(data["annotations"], start=1):
        at = f"{where}: annotations[{n}]"
        if not isinstance(ann, dict):
            raise InputError(f"{at} is not a JSON object")
        if not _id(ann.get("image_id")) or ann.get("image_id") not in names:
            raise InputError(f"{at} names image_id {clip(repr(ann.get('image_id')))}, not listed")
        if not _id(ann.get("category_id")) or ann.get("category_id") not in categories:
            raise InputError(
                f"{at} names category_id {clip(repr(ann.get('category_id')))}, not listed"
            )
        box = ann.get("bbox")
        if not isinstance(box, list) or len(box) != 4 or not all(_number(v) for v in box):
            raise InputError(f"{at}: bbox must be [x, y, width, height]")
        if box[2] < 0 or box[3] < 0:
            raise InputError(f"{at}: bbox width and height must not be negative")
        score = ann.get("score")
        if score is not None and (not _number(score) or not 0 <= score <= 1):
            raise InputError(f"{at}: score must be a number from 0 to 1")
        x, y, w, h = (float(v) for v in box)
        out[names[ann["image_id"]]].append(
            Detection(
                categories[ann["category_id"]],
                (x, y, x + w, y + h),
                None if score is None else float(score),
            )
        )
    return {name: tuple(found) for name, found in out.items()}


def detections_for(
    found: Mapping[str, tuple[Detection, ...]], view: str, path: str
) -> tuple[Detection, ...]:
    if view not in found:
        near = closest(view, found) or sorted(found)[:5]
        raise InputError(
            f"detections file {path} has no image named {view}; it lists {', '.join(near)}"
        )
    return found[view]
