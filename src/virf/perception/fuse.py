"""From the views' readings to one scene graph, and from it to a scene.

* Association: the same object across views is the one of the same
  catalogue type at the same rank from the left (views taken from one side
  of a room keep that order), unless stage 1 gave ids that say otherwise.
* Votes: a reading at or above the confidence threshold counts.  States of
  one object that cannot all be true (on in one view, off in another) are
  all written into the scene: the ontology makes them a contradiction, which
  the tutor reports as UNKNOWN with the question of which is wrong.
  Materials that differ (metal in one view, plastic in another) are each
  written as an assumed possibility, and a hazard that needs one is UNKNOWN
  with the question of what the object is made of.  Nothing is silently
  picked.
* Uncertainty is kept: below the threshold a material is unknown
  (UnknownMaterial), a fill state unknown (UnknownFillState), any other
  state or relation an *assumed* fact (a hazard that needs it is UNKNOWN,
  with it as the question), and the contents of a receptacle stay open.
  Above it, what a surface seen with confidence holds is taken as complete
  (``closed_world``); a container's contents never are, since a camera
  rarely sees inside one.
* A place is the one thing a scene cannot hold twice (an object is on one
  thing).  When views disagree on it, the place most views saw is kept as
  an assumed fact and the disagreement is reported; a hazard that would
  follow from the other place is not seen, which ``disagreements`` says.
"""

from __future__ import annotations

import re
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Final

from virf.errors import InputError
from virf.names import term_key
from virf.ontology.tbox import Vocabulary
from virf.perception.cascade import ViewReading, find_label
from virf.perception.catalogue import Catalogue, Match
from virf.perception.graph import (
    GraphObject,
    GraphRelation,
    Reading,
    SceneGraph,
    Sighting,
    TypeMatch,
    ViewInfo,
)
from virf.perception.replies import Detection
from virf.perception.terms import CHILD_FIRST, RELATIONS, material_term, state_term
from virf.world.scene import build_scene

DEFAULT_THRESHOLD: Final = 0.5
PLACES: Final = ("isOn", "isInside", "isHeldBy")
FILL_STATES: Final = frozenset({"FilledWithLiquidState", "EmptyState"})


@dataclass(frozen=True)
class Perception:
    graph: SceneGraph
    scene: dict[str, Any]  # the scene file the tutor reads (docs/scenes.md)


def _sure(confidence: float | None, threshold: float) -> bool:
    return confidence is None or confidence >= threshold


def _least(*values: float | None) -> float | None:
    known = [v for v in values if v is not None]
    return min(known) if known else None


def _shown(confidence: float | None) -> str:
    return "no confidence given" if confidence is None else f"confidence {confidence:g}"


def _base_name(label: str, vocab: Vocabulary) -> str:
    """An instance name for an object no catalogue type fits: its label in
    CamelCase (``garden gnome`` -> ``GardenGnome``)."""
    parts = re.findall(r"[A-Za-z0-9]+", re.sub(r"[\s_#-]*\d+$", "", label))
    base = "".join(p[:1].upper() + p[1:] for p in parts) or "Object"
    if not base[0].isalpha() or vocab.term_by_key(term_key(base)) is not None:
        base = "Seen" + base
    return base[:100]


@dataclass
class _Object:
    type: str | None
    label: str
    match: Match
    sightings: list[tuple[int, Any]] = field(default_factory=list)  # (view index, SeenObject)
    name: str = ""

    @property
    def centre(self) -> float:
        """Mean x-centre over the views that boxed it (unboxed: rightmost)."""
        centres = [_centre(o.detection) for _, o in self.sightings]
        boxed = [c for c in centres if c != float("inf")]
        return sum(boxed) / len(boxed) if boxed else float("inf")


def _centre(detection: Detection) -> float:
    box = detection.bbox
    return (box[0] + box[2]) / 2 if box is not None else float("inf")


def _weight(relation: GraphRelation) -> float:
    """A relation's confidence, a reading without one counting as sure."""
    return 1.0 if relation.confidence is None else relation.confidence


class _Fusion:
    def __init__(
        self,
        readings: Sequence[ViewReading],
        catalogue: Catalogue,
        vocab: Vocabulary,
        threshold: float,
    ) -> None:
        self.readings = readings
        self.catalogue = catalogue
        self.vocab = vocab
        self.threshold = threshold
        self.disagreements: list[str] = []
        self.notes: list[str] = []
        self.assertions: list[dict[str, Any]] = []

    def sure(self, confidence: float | None) -> bool:
        return _sure(confidence, self.threshold)

    # -- objects ---------------------------------------------------------

    def objects(self) -> list[_Object]:
        matches: dict[str, Match] = {}
        groups: dict[str, dict[int, list[Any]]] = defaultdict(lambda: defaultdict(list))
        first: dict[str, tuple[str | None, str, Match]] = {}
        for vi, reading in enumerate(self.readings):
            for seen in reading.objects:
                category = seen.detection.category
                if category not in matches:
                    matches[category] = self.catalogue.match(category)
                m = matches[category]
                key = m.type or "label:" + term_key(_base_name(category, self.vocab))
                groups[key][vi].append(seen)
                first.setdefault(key, (m.type, category, m))
        out: list[_Object] = []
        for key in sorted(groups):
            cls, label, m = first[key]
            made: list[_Object] = []
            per_view = sorted(groups[key].items())
            # Ids name one object across views only when every view gives
            # one to every object of the kind, each id once per view; partial
            # ids would split one object in two and hide a disagreement.
            ids = [[s.detection.track for s in seen_list] for _, seen_list in per_view]
            tracked = all(
                None not in view_ids and len(set(view_ids)) == len(view_ids) for view_ids in ids
            )
            if not tracked and any(t is not None for view_ids in ids for t in view_ids):
                self.notes.append(
                    f"the ids given to {label} are missing or repeated in a view; "
                    "its objects are matched across views by position instead"
                )
            tracks: dict[str, _Object] = {}
            for vi, seen_list in per_view:
                if tracked:
                    for seen in seen_list:
                        track = str(seen.detection.track)
                        if track not in tracks:
                            tracks[track] = _Object(cls, label, m)
                            made.append(tracks[track])
                        tracks[track].sightings.append((vi, seen))
                    continue
                ordered = sorted(seen_list, key=lambda s: (_centre(s.detection), s.index))
                for rank, seen in enumerate(ordered):
                    if rank == len(made):
                        made.append(_Object(cls, label, m))
                    made[rank].sightings.append((vi, seen))
            made.sort(key=lambda o: (o.centre, o.sightings[0][0], o.sightings[0][1].index))
            base = cls or _base_name(label, self.vocab)
            for j, obj in enumerate(made, start=1):
                obj.name = f"{base}_{j}"
            out.extend(made)
        for obj in out:
            low = [
                f"{self.readings[vi].view.name} ({_shown(s.detection.confidence)})"
                for vi, s in obj.sightings
                if not self.sure(s.detection.confidence)
            ]
            if low and len(low) == len(obj.sightings):
                self.notes.append(
                    f"{obj.name} was seen only below the confidence threshold ({', '.join(low)}); "
                    "it is kept, because a missed object can hide a hazard"
                )
            if obj.type is None:
                score = f" (closest type {obj.match.runner_up}" + (
                    f", similarity {obj.match.score:g})" if obj.match.score is not None else ")"
                )
                self.notes.append(
                    f"{obj.name}: no catalogue type fits '{obj.label}'{score}; "
                    "it is a PhysicalObject, known by what was seen of it"
                )
        return out

    # -- attributes ------------------------------------------------------

    def readings_of(self, obj: _Object) -> tuple[list[Reading], list[Reading]]:
        mats: list[Reading] = []
        states: list[Reading] = []
        for vi, seen in obj.sightings:
            view = self.readings[vi].view.name
            attrs = seen.attributes
            if attrs is None:
                self.notes.append(f"{obj.name} in {view}: {seen.problem}; its material is unknown")
                mats.append(Reading(value="UnknownMaterial", said="", confidence=None, view=view))
                continue
            if attrs.material is not None:
                m = material_term(attrs.material.value, self.vocab)
                if m is None:
                    self.notes.append(
                        f"{obj.name} in {view}: material '{attrs.material.value}' is not one the "
                        "knowledge base knows; taken as unknown"
                    )
                    m = "UnknownMaterial"
                mats.append(
                    Reading(
                        value=m,
                        said=attrs.material.value,
                        confidence=attrs.material.confidence,
                        view=view,
                    )
                )
            for s in attrs.states:
                st = state_term(s.value, self.vocab)
                as_material = material_term(s.value, self.vocab) if st is None else None
                if as_material not in (None, "UnknownMaterial"):
                    # 'metallic' said as a state is a material (the paper's noise test).
                    assert as_material is not None
                    mats.append(
                        Reading(value=as_material, said=s.value, confidence=s.confidence, view=view)
                    )
                    continue
                if st is None:
                    self.notes.append(
                        f"{obj.name} in {view}: state '{s.value}' is not one the knowledge base "
                        "knows; left out"
                    )
                    continue
                states.append(Reading(value=st, said=s.value, confidence=s.confidence, view=view))
        return mats, states

    def state(self, subject: str, prop: str, obj: str, assumed: bool = False) -> None:
        entry: dict[str, Any] = {"subject": subject, "property": prop, "object": obj}
        if assumed:
            entry["assumed"] = True
        if entry not in self.assertions:
            self.assertions.append(entry)

    def needs_material(self, obj: _Object) -> bool:
        """Whether the scene must say what ``obj`` is made of: a thing whose
        type implies no material (food and liquids are their own matter)."""
        classes = frozenset({obj.type or "PhysicalObject"})
        return (
            self.vocab.any_is_a(classes, "PhysicalObject")
            and not self.vocab.any_is_a(classes, "FoodItem")
            and not self.vocab.any_is_a(classes, "Liquid")
            and not self.vocab.materials_of(classes)
        )

    def attributes(self, obj: _Object, mats: list[Reading], states: list[Reading]) -> None:
        if not self.vocab.any_is_a(frozenset({obj.type or "PhysicalObject"}), "PhysicalObject"):
            if mats:  # a person has no material; a reading of one is noise
                self.notes.append(f"{obj.name} is a {obj.type}: its material readings are left out")
            mats = []
        sure_mats = sorted(
            {r.value for r in mats if self.sure(r.confidence) and r.value != "UnknownMaterial"}
        )
        unsure = sorted(
            {r.value for r in mats if not self.sure(r.confidence)} - {"UnknownMaterial"}
        )
        if sure_mats and set(unsure) - set(sure_mats):
            self.notes.append(
                f"{obj.name}: {' / '.join(sorted(set(unsure) - set(sure_mats)))} was read below the "
                f"threshold against a sure {' / '.join(sure_mats)}; the sure reading stands"
            )
        # Sure readings that differ are possibilities, not facts: an object
        # may be made of several materials (glass with a metal cap), so two
        # readings are no contradiction, and taking both as facts would
        # decide a hazard ("metal in the microwave") on one view's word.
        for m in sure_mats:
            self.state(obj.name, "hasMaterial", m, assumed=len(sure_mats) > 1)
        if len(sure_mats) > 1:
            self.disagreements.append(
                f"{obj.name}: material read as {' and '.join(sure_mats)} "
                f"({self._who(mats, set(sure_mats))}); each is kept as a possibility, so the "
                "tutor asks what it is made of"
            )
        elif not sure_mats and (mats or self.needs_material(obj)):
            # Nothing sure was said: not the catalogue's typical material
            # (a mug is usually ceramic) but a question.
            self.state(obj.name, "hasMaterial", "UnknownMaterial")
        sure_states = sorted({r.value for r in states if self.sure(r.confidence)})
        for st in sure_states:
            self.state(obj.name, "hasState", st)
        clashes = sorted(
            {
                tuple(sorted((a, b)))
                for a in sure_states
                for b in sure_states
                if b in self.vocab.excluded_by(a)
            }
        )
        for a, b in clashes:
            self.disagreements.append(
                f"{obj.name}: read as {a} and {b} ({self._who(states, {a, b})}); both are kept, "
                "so the tutor asks which is wrong"
            )
        for st in sorted({r.value for r in states} - set(sure_states)):
            if any(st in self.vocab.excluded_by(s) for s in sure_states):
                self.notes.append(
                    f"{obj.name}: {st} was read below the threshold against a sure "
                    f"{' / '.join(s for s in sure_states if st in self.vocab.excluded_by(s))}; "
                    "the sure reading stands"
                )
                continue
            if st in FILL_STATES:
                if not FILL_STATES & set(sure_states):
                    self.state(obj.name, "hasState", "UnknownFillState")
            else:
                self.state(obj.name, "hasState", st, assumed=True)

    def _who(self, readings: list[Reading], values: set[str]) -> str:
        return "; ".join(
            f"{r.view}: {r.said or r.value}"
            + (f" at {r.confidence:g}" if r.confidence is not None else "")
            for r in readings
            if r.value in values and self.sure(r.confidence)
        )

    # -- relations -------------------------------------------------------

    def relations(self, objects: list[_Object]) -> list[GraphRelation]:
        name_of = {(vi, seen.index): obj.name for obj in objects for vi, seen in obj.sightings}
        out: list[GraphRelation] = []
        for vi, reading in enumerate(self.readings):
            view = reading.view.name
            labels = [o.label for o in reading.objects]
            for loc in reading.locations:
                said = f"{loc.first} {loc.relationship} {loc.second}"
                ends = [find_label(loc.first, labels), find_label(loc.second, labels)]
                if None in ends:
                    missing = loc.first if ends[0] is None else loc.second
                    self.notes.append(
                        f"{view}: '{said}' names '{missing}', which is not one of the view's "
                        f"labels ({', '.join(labels)}); left out"
                    )
                    continue
                prop = RELATIONS.get(term_key(loc.relationship))
                if prop is None:
                    self.notes.append(
                        f"{view}: '{said}': relationship '{loc.relationship}' is not one of "
                        "isOn, isInside, isNear, isHeldBy; left out"
                    )
                    continue
                a, b = (reading.objects[i] for i in ends if i is not None)
                subject, obj = name_of[(vi, a.index)], name_of[(vi, b.index)]
                if prop in CHILD_FIRST:
                    subject, obj, prop = obj, subject, CHILD_FIRST[prop]
                if subject == obj:
                    self.notes.append(f"{view}: '{said}' relates an object to itself; left out")
                    continue
                confidence = _least(loc.confidence, a.detection.confidence, b.detection.confidence)
                rel = GraphRelation(
                    subject=subject,
                    relation=prop,
                    object=obj,
                    confidence=confidence,
                    view=view,
                    said=said,
                )
                if rel not in out:
                    out.append(rel)
        return out

    def places(self, relations: list[GraphRelation]) -> set[str]:
        """Write each object's place and the nearness facts; returns the
        objects whose place was in doubt."""
        doubtful: set[str] = set()
        by_child: dict[str, dict[tuple[str, str], list[GraphRelation]]] = defaultdict(
            lambda: defaultdict(list)
        )
        view_rank = {r.view.name: i for i, r in enumerate(self.readings)}
        for rel in relations:
            if rel.relation in PLACES:
                by_child[rel.subject][(rel.relation, rel.object)].append(rel)
        chosen: dict[str, tuple[str, str, bool]] = {}
        for child in sorted(by_child):
            options = sorted(
                by_child[child].items(),
                key=lambda kv: (
                    -len({r.view for r in kv[1]}),
                    -max(_weight(r) for r in kv[1]),
                    min(view_rank[r.view] for r in kv[1]),
                    kv[0],
                ),
            )
            (prop, parent), seen = options[0]
            assumed = not any(self.sure(r.confidence) for r in seen)
            if len(options) > 1:
                assumed = True
                doubtful |= {child, *(p for (_, p), _ in options)}
                said = "; ".join(
                    f"{', '.join(sorted({r.view for r in rs}))}: {p} {o}" for (p, o), rs in options
                )
                self.disagreements.append(
                    f"{child}: its place differs ({said}); {prop} {parent} is kept as an "
                    "assumption, so a hazard that needs it is asked about, but one that would "
                    "follow from the other place is not seen"
                )
            chosen[child] = (prop, parent, assumed)
        # A cycle (A on B, B on A) cannot be; its least sure link goes.
        for child in sorted(chosen):
            if child not in chosen:  # its link closed an earlier cycle and went
                continue
            path = [child]
            node = chosen[child][1]
            while node in chosen and node not in path:
                path.append(node)
                node = chosen[node][1]
            if node in path and node in chosen:
                cycle = path[path.index(node) :]
                weakest = min(
                    cycle,
                    key=lambda c: max(_weight(r) for r in by_child[c][chosen[c][:2]]),
                )
                p, o, _ = chosen.pop(weakest)
                doubtful.add(weakest)
                self.disagreements.append(
                    f"{weakest} {p} {o} would close a cycle ({' and '.join(cycle)}); left out"
                )
        held: dict[str, list[str]] = defaultdict(list)
        for child, (prop, parent, _) in sorted(chosen.items()):
            if prop == "isHeldBy":
                held[parent].append(child)
        for holder, things in sorted(held.items()):
            if len(things) < 2:
                continue
            # A hand holds one thing: the surest reading stays, as an assumption.
            surest = max(
                things,
                key=lambda c: max(_weight(r) for r in by_child[c][chosen[c][:2]]),
            )
            for other in things:
                if other != surest:
                    chosen.pop(other)
                    doubtful.add(other)
            chosen[surest] = (*chosen[surest][:2], True)
            doubtful.add(holder)
            self.disagreements.append(
                f"{holder} is read as holding {' and '.join(things)}; one thing is held at a "
                f"time, so {surest} is kept as an assumption and the others have no place"
            )
        for child, (prop, parent, assumed) in sorted(chosen.items()):
            self.state(child, prop, parent, assumed)
        near: dict[tuple[str, str], list[GraphRelation]] = defaultdict(list)
        for rel in relations:
            if rel.relation == "isNear":
                near[(rel.subject, rel.object)].append(rel)
        for (a, b), rels in sorted(near.items()):
            if (b, a) in near and (b, a) < (a, b):
                continue  # said both ways: one fact
            sure = any(self.sure(r.confidence) for r in rels + near.get((b, a), []))
            self.state(a, "isNear", b, assumed=not sure)
        return doubtful


def fuse(
    readings: Sequence[ViewReading],
    catalogue: Catalogue,
    vocab: Vocabulary,
    *,
    threshold: float = DEFAULT_THRESHOLD,
    open_contents: bool = False,
    source: str = "",
) -> Perception:
    """One scene graph and one scene from every view's readings (the
    threshold is checked by ``perceive``, before any model call)."""
    if not any(r.objects for r in readings):
        raise InputError(
            "the vision model saw no objects in "
            + ", ".join(r.view.name for r in readings)
            + "; there is no scene to verify"
        )
    f = _Fusion(readings, catalogue, vocab, threshold)
    objects = f.objects()
    graph_objects = []
    for obj in objects:
        mats, states = f.readings_of(obj)
        f.attributes(obj, mats, states)
        graph_objects.append(
            GraphObject(
                name=obj.name,
                type=obj.type or "PhysicalObject",
                label=obj.label,
                match=TypeMatch(
                    how=obj.match.how, score=obj.match.score, runner_up=obj.match.runner_up
                ),
                seen=tuple(
                    Sighting(
                        view=f.readings[vi].view.name,
                        index=s.index,
                        label=s.label,
                        category=s.detection.category,
                        bbox=s.detection.bbox,
                        confidence=s.detection.confidence,
                    )
                    for vi, s in obj.sightings
                ),
                materials=tuple(mats),
                states=tuple(states),
            )
        )
    relations = f.relations(objects)
    doubtful = f.places(relations)
    views = ", ".join(r.view.name for r in readings)
    scene: dict[str, Any] = {
        "name": "perceived",
        "description": f"Perceived from {views}" + (f" by {source}" if source else ""),
        "instances": [
            {"class_name": o.type or "PhysicalObject", "instance_name": o.name} for o in objects
        ],
        "assertions": f.assertions,
    }
    try:
        built = build_scene(scene, vocab)
    except InputError as exc:
        raise InputError(f"the perceived scene cannot be read: {exc}") from None
    closed = []
    for o in objects:
        classes = built.objects.get(o.name, frozenset())
        sure_seen = all(f.sure(s.detection.confidence) for _, s in o.sightings)
        into = [r for r in relations if r.object == o.name and r.relation in PLACES]
        if not sure_seen or o.name in doubtful or not all(f.sure(r.confidence) for r in into):
            continue
        # What is on a surface is in view; what is in a container (a mug of
        # coffee, a drawer) mostly is not, so a container's contents stay open.
        if vocab.any_is_a(classes, "SurfaceReceptacle"):
            closed.append(f"supports:{o.name}")
    if closed and not open_contents:
        scene["closed_world"] = closed
    graph = SceneGraph(
        threshold=threshold,
        views=tuple(
            ViewInfo(
                name=r.view.name,
                sha256=r.view.image.digest,
                width=r.view.width,
                height=r.view.height,
                boxes=r.boxes,
            )
            for r in readings
        ),
        objects=tuple(graph_objects),
        relations=tuple(relations),
        disagreements=tuple(f.disagreements),
        notes=tuple(f.notes),
    )
    build_scene(scene, vocab)  # the closures name declared objects: checked, never assumed
    return Perception(graph, scene)
