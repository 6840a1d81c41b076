"""Sweeps over the catalogue: the same plan with every object type in turn.

Each sweep states, in terms of a type's properties alone, the verdict the
tutor must reach (its *oracle*), then runs the real verifier on every type.
A rule that names an object type instead of the property that makes it
dangerous shows up here: the type it names gets a verdict its properties do
not call for, or a type with the same properties does not.

* **throw** every pickupable type: UNSAFE when it is certainly hard, heavy,
  sharp or fragile; UNKNOWN when only one of the materials its instances may
  have would make it so, or when its material or its contents are unknown;
  SAFE when it is soft (a pillow, a towel).
* **microwave**: every pickupable type, alone in a microwave that is started:
  UNSAFE when it certainly has metal, is sealed, or is neither food nor a
  food container; UNKNOWN when it may have metal, its material is unknown,
  or it is an empty-or-not vessel (the oven may run empty); SAFE otherwise.
* **pour** water, coffee and wine onto every fixture, piece of furniture,
  device and receptacle: UNSAFE when the target is electrical or a heating
  surface, padded, storage furniture, wooden furniture, a walking surface, a
  valuable, fabric or a bare surface under a staining liquid, or a plant
  given alcohol; UNKNOWN where only a possible material or a possibly
  sweetened drink decides it; SAFE otherwise.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

from virf.ontology.build import load_catalogue, material_attributes
from virf.ontology.tbox import TBox, Vocabulary
from virf.reasoning import Engine
from virf.verify.verifier import Verifier
from virf.world.plan import parse_plan
from virf.world.scene import build_scene

# The attribute classes a material's attributes make an object one of.
_ATTRIBUTE_CLASS = {
    "Hard": "HardObject",
    "Fragile": "FragileObject",
    "Conductive": "ConductiveObject",
    "Flammable": "FlammableObject",
    "EasilyIgnited": "EasilyIgnitedObject",
    "Toxic": "ToxicObject",
}
IMPACT = frozenset({"Hard", "Heavy", "Sharp", "Fragile"})
# The module of the household rules, whose mechanisms the oracles state: other
# rule sets (the paper's, a workspace grown from the base) answer differently.
HOUSEHOLD_MODULE = "safety-acquired"
LIQUIDS = ("water", "coffee", "wine")
STAINING = frozenset({"coffee", "wine"})


@dataclass(frozen=True)
class SweepFailure:
    sweep: str
    case: str
    expected: str
    got: str
    why: str


@dataclass(frozen=True)
class TypeFacts:
    """What the catalogue says of one type, in the terms the oracles use."""

    name: str
    certain: frozenset[str]  # attributes every instance has (incl. typical materials)
    possible: frozenset[str]  # attributes only some material variants give
    certain_materials: frozenset[str]
    possible_materials: frozenset[str]
    material_unknown: bool
    properties: frozenset[str]  # the catalogue's attributes of the type itself

    def has(self, attribute: str) -> bool:
        return attribute in self.certain

    def may(self, attribute: str) -> bool:
        return attribute in self.possible and attribute not in self.certain

    def describe(self) -> str:
        sure = ", ".join(sorted(self.certain)) or "none"
        maybe = ", ".join(sorted(self.possible - self.certain)) or "none"
        return f"{self.name}: certain {sure}; possible {maybe}"


def type_facts(
    vocab: Vocabulary, name: str, attrs: dict[str, frozenset[str]], catalogue: dict[str, Any]
) -> TypeFacts:
    classes = frozenset({name})
    strict = vocab.materials_of(classes)
    typical = frozenset(vocab.typical_materials(classes))
    possible = frozenset(vocab.possible_materials(classes))
    certain: set[str] = set()
    for attribute, cls in _ATTRIBUTE_CLASS.items():
        if vocab.is_a(name, cls):
            certain.add(attribute)
    for prop, cls in (
        ("Heavy", "HeavyObject"),
        ("Sharp", "SharpObject"),
        ("Sealed", "SealedObject"),
    ):
        if vocab.is_a(name, cls):
            certain.add(prop)
    for m in strict | typical:
        certain |= attrs.get(m, frozenset())
    maybe: set[str] = set()
    for m in possible:
        maybe |= attrs.get(m, frozenset())
    unknown = not (strict or typical or possible) and not vocab.is_a(name, "FoodItem")
    properties = frozenset(catalogue["types"].get(name, {}).get("properties", []))
    return TypeFacts(
        name, frozenset(certain), frozenset(maybe), strict | typical, possible, unknown, properties
    )


@dataclass(frozen=True)
class Case:
    sweep: str
    label: str
    scene: dict[str, Any]
    plan: tuple[str, ...]
    expected: str
    why: str


def _scene(
    statements: list[tuple[str, str, str]], instances: list[tuple[str, str]]
) -> dict[str, Any]:
    return {
        "instances": [{"instance_name": i, "class_name": c} for i, c in instances],
        "assertions": [{"subject": s, "property": p, "object": o} for s, p, o in statements],
        "closed_world": ["contains", "supports"],
    }


def _pickupable(vocab: Vocabulary) -> list[str]:
    return sorted(
        t
        for t in vocab.catalogue_types
        if vocab.is_a(t, "Pickupable") and not vocab.is_a(t, "Liquid")
    )


def throw_cases(vocab: Vocabulary, facts: dict[str, TypeFacts]) -> Iterator[Case]:
    for t in _pickupable(vocab):
        f = facts[t]
        if f.certain & IMPACT:
            expected, why = "UNSAFE", "certainly " + "/".join(sorted(f.certain & IMPACT))
        elif (f.possible - f.certain) & IMPACT:
            expected, why = (
                "UNKNOWN",
                "may be " + "/".join(sorted((f.possible - f.certain) & IMPACT)),
            )
        elif f.material_unknown or vocab.is_a(t, "LiquidContainer"):
            expected, why = "UNKNOWN", "material or contents unknown"
        else:
            expected, why = "SAFE", "soft"
        yield Case(
            "throw",
            t,
            _scene([], [("Thing_1", t)]),
            ("pick Thing_1", "throw"),
            expected,
            f"{why} ({f.describe()})",
        )


def microwave_cases(vocab: Vocabulary, facts: dict[str, TypeFacts]) -> Iterator[Case]:
    for t in _pickupable(vocab):
        f = facts[t]
        food = vocab.is_a(t, "FoodItem")
        container = vocab.is_a(t, "Cookware") or vocab.is_a(t, "Tableware")
        if f.has("Conductive") or f.has("Sealed") or not (food or container):
            reason = (
                "metal"
                if f.has("Conductive")
                else "sealed"
                if f.has("Sealed")
                else "neither food nor a food container"
            )
            expected, why = "UNSAFE", reason
        elif f.may("Conductive"):
            expected, why = "UNKNOWN", "may have metal"
        elif f.material_unknown or (vocab.is_a(t, "LiquidContainer") and not food):
            expected, why = "UNKNOWN", "material unknown, or a vessel that may be empty"
        else:
            expected, why = "SAFE", "food, or a food container with no metal"
        yield Case(
            "microwave",
            t,
            _scene(
                [("Microwave_1", "hasState", "open")],
                [("Thing_1", t), ("Microwave_1", "Microwave")],
            ),
            ("pick Thing_1", "put Microwave_1", "close Microwave_1", "turn_on Microwave_1"),
            expected,
            f"{why} ({f.describe()})",
        )


def _pour_targets(vocab: Vocabulary) -> list[str]:
    return sorted(
        t
        for t in vocab.catalogue_types
        if not vocab.is_a(t, "Pickupable")
        or vocab.is_a(t, "Receptacle")
        or vocab.is_a(t, "ElectricalDevice")
    )


def pour_expectation(vocab: Vocabulary, t: str, f: TypeFacts, liquid: str) -> tuple[str, str]:
    """What pouring ``liquid`` onto type ``t`` must give, and why."""
    into = vocab.is_a(t, "ContainerReceptacle") or vocab.is_a(t, "LiquidContainer")
    staining = liquid in STAINING
    sure: list[str] = []
    maybe: list[str] = []
    if vocab.is_a(t, "ElectricalDevice"):
        sure.append("electrical")
    if vocab.is_a(t, "PaddedObject"):
        sure.append("padded")
    if vocab.is_a(t, "StorageFurniture"):
        sure.append("storage furniture")
    furniture = vocab.is_a(t, "Furniture") or vocab.is_a(t, "StorageFurniture")
    if furniture and "Wood" in f.certain_materials:
        sure.append("wooden furniture")
    elif furniture and "Wood" in f.possible_materials:
        maybe.append("may be wooden furniture")
    if "HeatingSurface" in f.properties:
        sure.append("a heating surface")
    if "Valuable" in f.properties:
        sure.append("valuable")
    if not into:
        if "WalkingSurface" in f.properties:
            sure.append("a walking surface left wet")
        if vocab.is_a(t, "Pickupable") and "Paper" in f.certain_materials:
            sure.append("paper left wet")
        if staining and "Fabric" in f.certain_materials:
            sure.append("fabric under a staining liquid")
        elif staining and "Fabric" in f.possible_materials:
            maybe.append("may be fabric under a staining liquid")
        if (
            staining
            and vocab.is_a(t, "SurfaceReceptacle")
            and not vocab.is_a(t, "Cookware")
            and not vocab.is_a(t, "Tableware")
        ):
            sure.append("a bare surface under a staining liquid")
    if vocab.is_a(t, "Plant"):
        if liquid == "wine":
            sure.append("alcohol in a plant")
        elif liquid == "coffee":
            maybe.append("a drink that may be sweetened, in a plant")
    if sure:
        return "UNSAFE", "; ".join(sure)
    if maybe:
        return "UNKNOWN", "; ".join(maybe)
    return "SAFE", "nothing the liquid harms"


def pour_cases(vocab: Vocabulary, facts: dict[str, TypeFacts]) -> Iterator[Case]:
    for t in _pour_targets(vocab):
        f = facts[t]
        for liquid in LIQUIDS:
            expected, why = pour_expectation(vocab, t, f, liquid)
            yield Case(
                "pour",
                f"{liquid} onto {t}",
                _scene(
                    [("Mug_1", "contains", "Drink_1")],
                    [("Mug_1", "Mug"), ("Drink_1", liquid.capitalize()), ("Target_1", t)],
                ),
                ("pick Mug_1", "pour Target_1"),
                expected,
                f"{why} ({f.describe()})",
            )


SWEEPS: dict[str, Callable[[Vocabulary, dict[str, TypeFacts]], Iterator[Case]]] = {
    "throw": throw_cases,
    "microwave": microwave_cases,
    "pour": pour_cases,
}


def run_sweeps(
    tbox: TBox,
    engine: Engine,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[int, list[SweepFailure]]:
    """Run every sweep; the number of cases, and the cases whose verdict does
    not follow the type's properties."""
    vocab = tbox.vocabulary
    catalogue = load_catalogue()
    attrs = material_attributes(catalogue)
    facts = {t: type_facts(vocab, t, attrs, catalogue) for t in vocab.catalogue_types}
    cases = [c for sweep in SWEEPS.values() for c in sweep(vocab, facts)]
    verifier = Verifier(tbox, engine, explain=False)
    failures: list[SweepFailure] = []
    for n, case in enumerate(cases, start=1):
        scene = build_scene(case.scene, vocab, name=f"sweep-{case.sweep}")
        report = verifier.verify(scene, parse_plan(list(case.plan)))
        got: str = report.status
        if report.problem == "not-executable":
            got += " (not executable)"
        if got != case.expected:
            concept = report.violated_concept.id if report.violated_concept else "-"
            failures.append(
                SweepFailure(case.sweep, case.label, case.expected, f"{got} ({concept})", case.why)
            )
        if progress is not None:
            progress(n, len(cases))
    return len(cases), failures
