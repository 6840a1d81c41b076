"""What the reader adds where a scene is silent: a type's start states and
typical materials (applied only when the scene states none), the possible
materials and the open-world markers (UnknownMaterial, UnknownFillState,
UnknownContentsState) as assumed facts, and the devices a control is assumed
to control.  Each fact is marked DEFAULT or ASSUMED, never SCENE.
"""

from __future__ import annotations

from virf.ontology.tbox import Vocabulary
from virf.schema import Fact, Provenance


def apply_default_states(
    objects: dict[str, frozenset[str]], facts: dict[Fact, Provenance], vocab: Vocabulary
) -> None:
    """States a type starts in (a fridge is closed, a toaster off) when the
    scene says nothing about that state or its opposite."""
    stated: dict[str, set[str]] = {}
    for f in facts:
        if f.predicate == "hasState":
            stated.setdefault(f.subject, set()).add(f.object)
    for ind, cs in objects.items():
        have = stated.get(ind, set())
        for cls in sorted(cs):
            for default in vocab.annotation(cls, "defaultState"):
                if not have & (vocab.excluded_by(default) | {default}):
                    facts[Fact(ind, "hasState", default)] = Provenance.DEFAULT
                    have = have | {default}


def assume_controls(
    objects: dict[str, frozenset[str]],
    order: tuple[str, ...],
    facts: dict[Fact, Provenance],
    vocab: Vocabulary,
) -> None:
    """A control whose device the scene does not name (a stove knob without a
    'controls' fact) is assumed to control every device of its type: hazards
    that follow are then UNKNOWN, with the assumption as the question."""
    stated = {f.subject for f in facts if f.predicate == "controls"}
    for ind in order:
        if ind in stated:
            continue
        for cls in sorted(objects[ind]):
            for device_type in vocab.annotation(cls, "controlsType"):
                for device in order:
                    if vocab.any_is_a(objects[device], device_type):
                        facts[Fact(ind, "controls", device)] = Provenance.ASSUMED


def mark_unknown_fill(
    objects: dict[str, frozenset[str]], facts: dict[Fact, Provenance], vocab: Vocabulary
) -> None:
    """A liquid container whose fill state the scene does not give gets an
    explicit UnknownFillState marker (AI2-THOR randomises it)."""
    fill_known = {
        f.subject
        for f in facts
        if f.predicate == "hasState"
        and f.object in ("FilledWithLiquidState", "EmptyState", "UnknownFillState")
    }
    for ind, cs in objects.items():
        if ind not in fill_known and vocab.any_is_a(cs, "LiquidContainer"):
            facts[Fact(ind, "hasState", "UnknownFillState")] = Provenance.ASSUMED


def mark_unknown_contents(
    objects: dict[str, frozenset[str]],
    facts: dict[Fact, Provenance],
    vocab: Vocabulary,
    closed: frozenset[str],
    unknown_contents: frozenset[str],
) -> None:
    """A receptacle or vessel whose contents the scene does not list
    completely gets an explicit UnknownContentsState marker: a toilet or a
    bucket may already hold a cleaner nobody mentioned."""
    for ind, cs in objects.items():
        if not (vocab.any_is_a(cs, "ContainerReceptacle") or vocab.any_is_a(cs, "LiquidContainer")):
            continue
        listed = "contains" in closed or f"contains:{ind}" in closed
        if not listed or ind in unknown_contents:
            facts[Fact(ind, "hasState", "UnknownContentsState")] = Provenance.ASSUMED


def apply_material_knowledge(
    objects: dict[str, frozenset[str]], facts: dict[Fact, Provenance], vocab: Vocabulary
) -> None:
    """Typical-material defaults, possible materials, then unknown-material
    markers, for objects whose scene states no material.

    A Mug is ceramic *unless the scene says otherwise*: OWL has no defaults, so
    the default is applied here.  A Vase may be ceramic, glass or metal (AI2-THOR's
    vases differ): each possibility is an ASSUMED fact, so a hazard that needs
    one is UNKNOWN and asks what the vase is made of, never UNSAFE or SAFE.  An
    object whose material is still unknown gets an explicit UnknownMaterial
    marker (an ASSUMED fact): the open world made visible, so that uncertainty
    rules can ask about it.
    """
    stated: dict[str, set[str]] = {}
    for f in facts:
        if f.predicate == "hasMaterial":
            stated.setdefault(f.subject, set()).add(f.object)
    for ind, cs in objects.items():
        if not vocab.any_is_a(cs, "PhysicalObject") or vocab.any_is_a(cs, "Liquid"):
            continue
        if stated.get(ind):
            continue
        typical = vocab.typical_materials(cs)
        possible = vocab.possible_materials(cs)
        for m in typical:
            facts[Fact(ind, "hasMaterial", m)] = Provenance.DEFAULT
        for m in possible:
            facts.setdefault(Fact(ind, "hasMaterial", m), Provenance.ASSUMED)
        if not (typical or possible or vocab.materials_of(cs) or vocab.any_is_a(cs, "FoodItem")):
            facts[Fact(ind, "hasMaterial", "UnknownMaterial")] = Provenance.ASSUMED
