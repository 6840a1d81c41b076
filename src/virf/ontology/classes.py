"""The classes a scene can use, with what the knowledge base says of each.

What ``virf kb classes`` lists: every object type, person, state, material
and property (``hasProperty`` attribute) of a scenario, each with its parents,
its materials (those every instance has, the typical ones a scene's silence
defaults to, the possible ones the tutor asks about), its affordances (what
the simulator lets a plan do with it) and its properties, inherited ones
included.  Read from the compiled knowledge, without Java.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Final

from virf.errors import InputError
from virf.ontology.build import AFFORDANCES, RECEPTACLES
from virf.ontology.fragment import Expr, Fragment
from virf.ontology.suggest import (
    CLASS_KINDS,
    Kinds,
    Ranked,
    check_kind,
    class_kind,
    listed_classes,
    rank_classes,
)
from virf.ontology.tbox import TBox, Vocabulary

# The classes that say what an object type affords (the catalogue's
# pickupable, openable, ... and its receptacle kinds).
AFFORDANCE_CLASSES: Final = frozenset(
    {cls for cls, _ in AFFORDANCES.values()} | set(RECEPTACLES.values())
)
_HAS_PROPERTY: Final = ("hasProperty", False)


@dataclass(frozen=True)
class ClassInfo:
    """One class as ``virf kb classes`` shows it."""

    name: str
    kind: str  # one of CLASS_KINDS
    parents: tuple[str, ...]  # the told superclasses, affordances aside
    synonyms: tuple[str, ...]  # other names a scene may write for it
    catalogue: str  # the object-type catalogue it comes from, or ""
    materials: tuple[str, ...]  # every instance is made of these
    typical_materials: tuple[str, ...]  # what a scene that says nothing gets
    possible_materials: tuple[str, ...]  # some instances: asked about, never assumed
    affordances: tuple[str, ...]  # every instance affords these
    may_afford: tuple[str, ...]  # some instances do, the simulator neither assumes nor refuses
    properties: tuple[str, ...]  # hasProperty attributes, its own and its materials'
    comment: str

    def to_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "kind": self.kind,
            "parents": list(self.parents),
            "synonyms": list(self.synonyms),
            "catalogue": self.catalogue or None,
            "materials": {
                "always": list(self.materials),
                "typical": list(self.typical_materials),
                "possible": list(self.possible_materials),
            },
            "affordances": list(self.affordances),
            "may_afford": list(self.may_afford),
            "properties": list(self.properties),
            "comment": self.comment,
        }


@dataclass(frozen=True)
class _Told:
    """What the axioms say of named classes directly."""

    parents: Mapping[str, frozenset[str]]
    properties: Mapping[str, frozenset[str]]


def _conjuncts(e: Expr) -> tuple[Expr, ...]:
    return tuple(p for part in e[1] for p in _conjuncts(part)) if e[0] == "and" else (e,)


def _told(fragment: Fragment) -> _Told:
    """``C SubClassOf P`` and ``C SubClassOf hasProperty value A``, also as
    conjuncts of a superclass or of a definition (``ElectricalDevice
    EquivalentTo PhysicalObject and hasProperty value ElectricallyPowered``)."""
    parents: dict[str, set[str]] = defaultdict(set)
    properties: dict[str, set[str]] = defaultdict(set)

    def note(cls: str, sup: Expr) -> None:
        for part in _conjuncts(sup):
            if part[0] == "C":
                parents[cls].add(part[1])
            elif part[0] == "value" and part[1] == _HAS_PROPERTY:
                properties[cls].add(part[2])

    for ax in fragment.axioms:
        if ax.kind == "sub" and ax.args[0][0] == "C":
            note(ax.args[0][1], ax.args[1])
        elif ax.kind == "eq" and len(ax.args[0]) == 2:
            named = [e for e in ax.args[0] if e[0] == "C"]
            other = [e for e in ax.args[0] if e[0] != "C"]
            if len(named) == 1 and len(other) == 1:
                note(named[0][1], other[0])
    return _Told(
        {k: frozenset(v) for k, v in parents.items()},
        {k: frozenset(v) for k, v in properties.items()},
    )


def _most_specific(vocab: Vocabulary, classes: Iterable[str]) -> tuple[str, ...]:
    pool = set(classes)
    return tuple(
        sorted(c for c in pool if not any(c in vocab.ancestors.get(o, ()) for o in pool - {c}))
    )


def _info(vocab: Vocabulary, told: _Told, synonyms: Mapping[str, list[str]], cls: str) -> ClassInfo:
    own = {cls} | set(vocab.ancestors.get(cls, ()))
    materials = vocab.materials_of({cls})
    properties = {p for c in own for p in told.properties.get(c, ())}
    for material in materials:
        for c in {material} | set(vocab.ancestors.get(material, ())):
            properties |= told.properties.get(c, frozenset())
    parents = set(told.parents.get(cls, ())) - AFFORDANCE_CLASSES - {cls}
    if not parents:  # defined by a union ('Coffee or Wine or Oil'): what it was classified under
        parents = {
            a
            for a in own - AFFORDANCE_CLASSES - {cls}
            if cls not in vocab.ancestors.get(a, ())  # an equivalent class is no parent
        }
    return ClassInfo(
        name=cls,
        kind=class_kind(vocab, cls) or "",
        parents=_most_specific(vocab, parents),
        synonyms=tuple(sorted(synonyms.get(cls, ()))),
        catalogue=", ".join(vocab.annotation(cls, "catalogue")),
        materials=tuple(sorted(materials)),
        typical_materials=vocab.typical_materials({cls}),
        possible_materials=vocab.possible_materials({cls}),
        affordances=tuple(sorted(a for a in AFFORDANCE_CLASSES if a != cls and a in own)),
        may_afford=tuple(sorted(set(vocab.annotation(cls, "mayAfford")))),
        properties=tuple(sorted(properties)),
        comment=" ".join(vocab.annotation(cls, "comment")),
    )


def class_listing(tbox: TBox, kinds: Kinds = None) -> tuple[ClassInfo, ...]:
    """The classes of ``kinds`` (one, several, None for all), by kind then name."""
    vocab = tbox.vocabulary
    told = _told(tbox.fragment)
    synonyms: dict[str, list[str]] = defaultdict(list)
    for alias, target in vocab.class_synonyms.items():
        synonyms[target].append(alias)
    rows = [_info(vocab, told, synonyms, c) for c in listed_classes(vocab, kinds)]
    return tuple(sorted(rows, key=lambda r: (CLASS_KINDS.index(r.kind), r.name)))


def find_classes(
    tbox: TBox, kind: str | None = None, search: str | None = None, limit: int | None = None
) -> list[tuple[ClassInfo, Ranked | None]]:
    """What ``virf kb classes`` shows: the classes of ``kind`` (None for
    every kind) by kind and name, or with ``search`` the nearest to its words
    by spelling and meaning first; at most ``limit`` of them."""
    check_kind(kind)
    listing = class_listing(tbox, kind)
    if search is None:
        return [(info, None) for info in listing[:limit]]
    if not search.strip():
        raise InputError("--search needs words to look for, such as --search 'hair dryer'")
    by_name = {info.name: info for info in listing}
    return [(by_name[r.name], r) for r in rank_classes(search, tbox.vocabulary, kind)[:limit]]


def classes_document(
    tbox: TBox, kind: str | None, search: str | None, rows: list[tuple[ClassInfo, Ranked | None]]
) -> dict[str, Any]:
    """``virf kb classes --json``: the scenario, the query and the classes."""
    return {
        "scenario": tbox.scenario,
        "kind": kind,
        "search": search,
        "classes": [
            {
                **info.to_json(),
                **(
                    {}
                    if match is None
                    else {
                        "score": match.score,
                        "meaning": match.meaning,
                        "spelling": match.spelling,
                    }
                ),
            }
            for info, match in rows
        ],
    }
