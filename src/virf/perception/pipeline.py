"""``perceive``: camera images in, a scene graph and a scene out."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from virf.errors import InputError
from virf.ontology.tbox import Vocabulary
from virf.perception.cascade import Cascade
from virf.perception.catalogue import Catalogue
from virf.perception.detections import detections_for, load_detections
from virf.perception.fuse import DEFAULT_THRESHOLD, Perception, fuse
from virf.perception.images import BBOX_UNITS, load_view
from virf.planner import Apprentice, Deadline
from virf.verify.questions import materials

MAX_VIEWS = 32


def perceive(
    images: Sequence[str | Path],
    vlm: Apprentice,
    vocab: Vocabulary,
    *,
    detections: str | Path | None = None,
    threshold: float = DEFAULT_THRESHOLD,
    open_contents: bool = False,
    bbox_units: str = "pixels",
    deadline: Deadline | None = None,
    progress: Callable[[str], None] | None = None,
    catalogue: Catalogue | None = None,
) -> Perception:
    """Run the cascade (or, with ``detections``, the hybrid baseline) on
    every view and fuse the views into one scene.  Every input is checked
    before the first model call."""
    if not images:
        raise InputError("no images: give one or more camera images of the scene")
    if len(images) > MAX_VIEWS:
        raise InputError(f"{len(images)} images; at most {MAX_VIEWS} views of one scene")
    if bbox_units not in BBOX_UNITS:
        raise InputError(f"bbox units '{bbox_units}' are unknown; choose {', '.join(BBOX_UNITS)}")
    if not 0 <= threshold <= 1:
        raise InputError(f"confidence threshold {threshold!r} must be from 0 to 1")
    views = [load_view(p) for p in images]
    names = [v.name for v in views]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise InputError(f"two images are named {twice[0]}; views are told apart by file name")
    boxes = load_detections(detections) if detections is not None else None
    per_view = (
        [detections_for(boxes, v.name, str(detections)) for v in views]
        if boxes is not None
        else [None] * len(views)
    )
    catalogue = catalogue or Catalogue(vocab)
    cascade = Cascade(
        vlm,
        catalogue,
        materials(vocab),
        bbox_units=bbox_units,
        deadline=deadline,
        progress=progress,
    )
    readings = [cascade.read(v, found) for v, found in zip(views, per_view, strict=True)]
    return fuse(
        readings,
        catalogue,
        vocab,
        threshold=threshold,
        open_contents=open_contents,
        source=vlm.label,
    )
