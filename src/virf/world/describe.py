"""What ``virf scene show`` prints: a scene's canonical world as plain data."""

from __future__ import annotations

from typing import Any

from virf.ontology.lexicon import propose
from virf.schema import Fact, FactKind, Provenance
from virf.world.scene import Scene


def describe_scene(scene: Scene) -> dict[str, Any]:
    """The canonical world the reader built, as plain data (``virf scene show``):
    per object its types, states, materials and relations, each with where it
    came from (the scene, a catalogue default, an open-world assumption) and,
    where the scene wrote it differently, how it was written."""

    def entry(f: Fact, prov: Provenance) -> dict[str, str]:
        out = {"value": f.object, "from": prov.value}
        written = scene.spelling.get(f)
        if written is not None:
            out["written"] = written.render()
            out["canonical"] = f.render()
        return out

    objects: dict[str, Any] = {}
    for ind in (*scene.order, *sorted(set(scene.objects) - set(scene.order))):
        objects[ind] = {
            "types": sorted(scene.objects[ind]),
            "states": [],
            "materials": [],
            "properties": [],
            "relations": [],
            "data": {},
        }
    value_keys = {"hasState": "states", "hasMaterial": "materials", "hasProperty": "properties"}
    for f, prov in scene.facts.items():
        if f.subject not in objects:
            continue
        obj = objects[f.subject]
        if f.kind is FactKind.DATA:
            obj["data"][f.predicate] = f.object
        elif f.predicate in value_keys:
            obj[value_keys[f.predicate]].append(entry(f, prov))
        elif f.kind is FactKind.OBJECT:
            rel = entry(f, prov)
            rel["relation"] = f.predicate
            obj["relations"].append(rel)
    others = sorted(
        {f.subject for f in scene.facts if f.subject not in objects and f.kind is FactKind.TYPE}
    )
    return {
        "name": scene.name,
        "agent": scene.agent,
        "objects": objects,
        "value_individuals": {
            ind: sorted(f.object for f in scene.facts if f.subject == ind) for ind in others
        },
        "closed_world": sorted(scene.closed_world),
        "unknown_contents": sorted(scene.unknown_contents),
        "unlocated_by_default": scene.unlocated_by_default,
        "referents": dict(scene.referents),
        "open_world_objects": {
            ind: {
                "written": word,
                "proposal": propose(word).describe(),
                "hypotheses": sorted(
                    f.render()
                    for f, p in scene.facts.items()
                    if f.subject == ind and p is Provenance.ASSUMED
                ),
            }
            for ind, word in scene.open_world.items()
        },
        "open_world_markers": sorted(
            f.render()
            for f, p in scene.facts.items()
            if p is Provenance.ASSUMED
            or f.object in ("UnknownMaterial", "UnknownFillState", "UnknownLiquid")
        ),
    }
