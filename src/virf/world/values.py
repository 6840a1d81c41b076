"""States, materials and attributes as a scene writes them, read as the
ontology's value individuals.

A scene may name a value by the class's own individual (``OnState``), by an
individual of the class (``On_1``), by a word (``"closed"``), or give an
object the class as a type; the reader (:func:`virf.world.scene.build_scene`)
stores each as the canonical individual, through the tables and helpers here.
"""

from __future__ import annotations

import re
from collections.abc import Mapping

from virf.errors import closest
from virf.ontology.tbox import Vocabulary

# The property that carries each kind of value individual.
VALUE_PROPERTY = {"State": "hasState", "Material": "hasMaterial", "Attribute": "hasProperty"}
# Words a scene may use as data values of hasState/hasMaterial.
VALUE_WORDS = {
    "on": "OnState",
    "off": "OffState",
    "open": "OpenState",
    "opened": "OpenState",
    "closed": "ClosedState",
    "close": "ClosedState",
    "hot": "HotState",
    "cold": "ColdState",
    "wet": "WetState",
    "dry": "DryState",
    "dirty": "DirtyState",
    "clean": "CleanState",
    "broken": "BrokenState",
    "sliced": "SlicedState",
    "cooked": "CookedState",
    "filled": "FilledWithLiquidState",
    "full": "FilledWithLiquidState",
    "empty": "EmptyState",
    "usedup": "UsedUpState",
    "sealed": "SealedState",
    "lit": "OnState",
    "burning": "OnState",
    "running": "OnState",
    "plugged": "PluggedInState",
    "pluggedin": "PluggedInState",
    "unplugged": "UnpluggedState",
    "unknown": "UnknownMaterial",
    "metallic": "Metal",
}


def near_values(value: str, prop: str, instances: list[str], vocab: Vocabulary) -> list[str]:
    """What an unknown value of ``prop`` may have meant: for a state, the
    states its words or spelling come near ('switched on' -> OnState, 'lite'
    -> OnState, by the word 'lit'); for a material, the materials; else any
    instance or individual."""
    if prop == "hasState":
        words = {w: v for w, v in VALUE_WORDS.items() if v.endswith("State")}
        pool = sorted({*(i for i in vocab.individuals if i.endswith("State")), *words})
    elif prop == "hasMaterial":
        known = set().union(*vocab.class_materials.values(), vocab.material_classes.values())
        pool = sorted(m for m in known if m in vocab.individuals)
        words = {w: v for w, v in VALUE_WORDS.items() if v in pool}
    else:
        return closest(value, instances + sorted(vocab.individuals))
    said = [words[w] for w in re.findall(r"[a-z]+", value.lower()) if w in words]
    near = said + [words.get(n, n) for n in closest(value, pool)]
    return list(dict.fromkeys(near))[:3]


def value_kind(term: str, classes: Mapping[str, set[str]], vocab: Vocabulary) -> str | None:
    """'State', 'Material' or 'Attribute' for a value individual or class."""
    types = classes.get(term) or {term}
    for root in VALUE_PROPERTY:
        if types and all(vocab.is_a(c, root) for c in types):
            return root
    return None


def value_individuals(
    classes: Mapping[str, set[str]], vocab: Vocabulary, used_as_value: set[str]
) -> dict[str, list[str]]:
    """User individuals of state, material or attribute classes, each with the
    canonical individuals it stands for (empty: keep the user's individual,
    because some class of it has no canonical individual).  An individual of
    material classes only is a value only where a scene uses it as one."""
    out: dict[str, list[str]] = {}
    for ind, cs in classes.items():
        kind = value_kind(ind, classes, vocab)
        if kind is None or (kind == "Material" and ind not in used_as_value):
            continue
        specific = most_specific(cs, vocab)
        out[ind] = sorted(specific) if specific <= vocab.individuals else []
    return out


def most_specific(classes: set[str], vocab: Vocabulary) -> set[str]:
    """The classes without a strict subclass among them: the others are implied."""
    return {
        c
        for c in classes
        if not any(d != c and vocab.is_a(d, c) and not vocab.is_a(c, d) for d in classes)
    }
