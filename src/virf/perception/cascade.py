"""The paper's VLM cascade, one view at a time (Appendix C).

1. detect: the whole image, every object of the catalogue's categories;
2. attributes: one request per object, with the object's crop, for its
   states and material;
3. relations: the whole image again, with the view's object labels, for
   how the objects are placed.

The hybrid baseline replaces step 1 with a detector's boxes.  Every request
goes through an :class:`~virf.planner.Apprentice`, the planner's own client:
so retries, the run log and replay (``--vlm replay:FILE``) work as they do
for plans.  Calls are keyed by the view's content (``View.key``) and the
step: ``detect``, ``attributes:K:CATEGORY`` (K counts the view's objects
from 1), ``relations``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Final, Literal, TypeVar

from virf.errors import EnvironmentProblem
from virf.files import read_prompt
from virf.names import term_key
from virf.perception.catalogue import Catalogue
from virf.perception.images import View, crop, pixel_box
from virf.perception.replies import (
    Attributes,
    Detection,
    Location,
    UnreadableReply,
    read_attributes,
    read_detections,
    read_locations,
)
from virf.planner import Apprentice, Attachment, Deadline, Purpose

STATE_WORDS: Final = (
    "on, off, open, closed, hot, cold, wet, dry, dirty, clean, broken, sliced, cooked, "
    "filled, empty, sealed"
)
RELATIONSHIP_WORDS: Final = "isOn, isInside, isNear, isHeldBy"
_T = TypeVar("_T")
# Far more than a room shows, far fewer than would make stage 2 run for hours.
MAX_OBJECTS: Final = 300


def prompt(name: str) -> str:
    return read_prompt("virf.perception", f"{name}.txt")


@dataclass(frozen=True)
class SeenObject:
    """One object of one view, with what stage 2 said of it."""

    index: int  # 1-based, in the view's detection order
    label: str  # unique in the view: what stage 3 calls it
    detection: Detection
    attributes: Attributes | None  # None: the reply could not be read
    problem: str = ""


@dataclass(frozen=True)
class ViewReading:
    view: View
    boxes: Literal["vlm", "detector"]
    objects: tuple[SeenObject, ...]
    locations: tuple[Location, ...]


def labels(detections: Sequence[Detection]) -> list[str]:
    """``Mug_1``, ``Mug_2``, ``CounterTop_1``: each category counted in order."""
    counts: dict[str, int] = {}
    out = []
    for d in detections:
        counts[d.category] = counts.get(d.category, 0) + 1
        out.append(f"{d.category}_{counts[d.category]}")
    return out


class Cascade:
    def __init__(
        self,
        vlm: Apprentice,
        catalogue: Catalogue,
        materials: Sequence[str],
        *,
        bbox_units: str = "pixels",
        deadline: Deadline | None = None,
        progress: Callable[[str], None] | None = None,
    ) -> None:
        self.vlm = vlm
        self.catalogue = catalogue
        self.materials = ", ".join([*(m.lower() for m in materials), "unknown"])
        self.bbox_units = bbox_units
        self.deadline = deadline
        self.progress = progress or (lambda _: None)

    def read(self, view: View, detections: Sequence[Detection] | None = None) -> ViewReading:
        """Stages 1-3 on one view (stage 1 skipped when a detector gave boxes)."""
        boxes: Literal["vlm", "detector"] = "vlm" if detections is None else "detector"
        if detections is None:
            self.progress(f"{view.name}: detect")
            text = self._ask(
                view,
                "detect",
                prompt("detect").format(
                    categories=", ".join(self.catalogue.types),
                    width=view.width,
                    height=view.height,
                ),
                [view.image],
            )
            detections = self._read(view, "detect", read_detections, text)
        if len(detections) > MAX_OBJECTS:
            # Each object costs a request: a runaway list would cost thousands.
            raise UnreadableReply(
                f"{view.name}: {len(detections)} objects were listed; at most {MAX_OBJECTS} "
                "per view are described"
            )
        names = labels(detections)
        # A detector's boxes are COCO pixels whatever the model's convention.
        units = self.bbox_units if boxes == "vlm" else "pixels"
        regions = [pixel_box(d.bbox, view, units) for d in detections]
        unboxed = [d.category for d, r in zip(detections, regions, strict=True) if r is None]
        objects = []
        for k, (detection, label, region) in enumerate(
            zip(detections, names, regions, strict=True), start=1
        ):
            if region is None and unboxed.count(detection.category) > 1:
                # Without boxes, two objects of one category get the same
                # question and the same answer: neither reading is this one's.
                objects.append(
                    SeenObject(
                        k,
                        label,
                        detection,
                        None,
                        f"no box tells it from the other {detection.category} objects of the "
                        "view, so it was not described",
                    )
                )
                continue
            self.progress(f"{view.name}: attributes of {label}")
            objects.append(self._attributes(view, k, label, detection, region))
        locations: tuple[Location, ...] = ()
        if objects:
            self.progress(f"{view.name}: relations")
            text = self._ask(
                view,
                "relations",
                prompt("relations").format(
                    labels="[" + ", ".join(names) + "]", relationships=RELATIONSHIP_WORDS
                ),
                [view.image],
            )
            locations = self._read(view, "relations", read_locations, text)
        return ViewReading(view, boxes, tuple(objects), locations)

    def _attributes(
        self,
        view: View,
        k: int,
        label: str,
        detection: Detection,
        box: tuple[int, int, int, int] | None,
    ) -> SeenObject:
        # Without a usable box the model sees the whole view; the prompt names
        # the category, which is the only one of its kind without a box.
        image = crop(view, box, f"{view.name}#{label}") if box else view.image
        text = self._ask(
            view,
            f"attributes:{k}:{detection.category}",
            prompt("attributes").format(
                label=detection.category, states=STATE_WORDS, materials=self.materials
            ),
            [image],
        )
        try:
            return SeenObject(k, label, detection, read_attributes(text))
        except UnreadableReply as exc:
            # Fail closed, not loud: the object stays, its material unknown,
            # so the tutor asks about it instead of assuming anything.
            return SeenObject(k, label, detection, None, f"attributes reply unreadable: {exc}")

    def _ask(self, view: View, method: str, text: str, images: list[Attachment]) -> str:
        proposal = self.vlm.propose(
            [{"role": "user", "content": text}],
            task_id=view.key,
            iteration=1,
            method=method,
            purpose=Purpose.PERCEIVE,
            deadline=self.deadline,
            images=images,
        )
        if not proposal.ok or proposal.text is None:
            raise EnvironmentProblem(
                f"{view.name}: the vision model gave no usable {method.split(':')[0]} reply: "
                f"{proposal.reason}"
            )
        return proposal.text

    @staticmethod
    def _read(view: View, stage: str, reader: Callable[[str], _T], text: str) -> _T:
        try:
            return reader(text)
        except UnreadableReply as exc:
            raise UnreadableReply(f"{view.name}: the {stage} reply cannot be read: {exc}") from None


def find_label(label: str, names: Sequence[str]) -> int | None:
    """Which of a view's objects a stage-3 label means (None: none of them).

    Exact first, then ignoring case and separators; a bare category (``Mug``)
    means the view's only object of it."""
    if label in names:
        return names.index(label)
    key = term_key(label)
    hits = [i for i, n in enumerate(names) if term_key(n) == key]
    if len(hits) == 1:
        return hits[0]
    bare = [i for i, n in enumerate(names) if term_key(n.rpartition("_")[0]) == key]
    return bare[0] if len(bare) == 1 else None
