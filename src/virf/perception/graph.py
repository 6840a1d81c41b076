"""The Rich Semantic Scene Graph: what perception saw, before it is a scene.

Every item keeps the view it came from and the model's confidence, so a
user can see why the scene says what it says (``virf perceive --graph``).
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class ViewInfo(_Frozen):
    name: str
    sha256: str
    width: int
    height: int
    boxes: str  # "vlm" (stage 1) or "detector" (the hybrid baseline)


class Sighting(_Frozen):
    view: str
    index: int  # the object's place in the view's detection list, from 1
    label: str  # as the view's stage 3 was told it
    category: str  # as the model or detector named it
    bbox: tuple[float, float, float, float] | None
    confidence: float | None


class Reading(_Frozen):
    """A state or material as one view reported it."""

    value: str  # the ontology term (Metal, OnState), or the model's word if none fits
    said: str  # the model's word
    confidence: float | None
    view: str


class TypeMatch(_Frozen):
    how: str  # name, embedding or none
    score: float | None = None
    runner_up: str | None = None


class GraphObject(_Frozen):
    name: str  # the scene's instance name
    type: str  # a catalogue type, or PhysicalObject
    label: str  # the model's word for it
    match: TypeMatch
    seen: tuple[Sighting, ...]
    materials: tuple[Reading, ...]
    states: tuple[Reading, ...]


class GraphRelation(_Frozen):
    subject: str
    relation: str
    object: str
    confidence: float | None
    view: str
    said: str  # the model's triple, in its words


class SceneGraph(_Frozen):
    threshold: float
    views: tuple[ViewInfo, ...]
    objects: tuple[GraphObject, ...]
    relations: tuple[GraphRelation, ...]
    # Where views disagree or a reading was set aside; each says what became of it.
    disagreements: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
