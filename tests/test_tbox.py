"""The safety knowledge base: consistency, rule metadata, provenance, generated module."""

from __future__ import annotations

from typing import Any

import pytest

from virf.ontology.build import kitchen_path, load_catalogue, render_kitchen
from virf.ontology.check import check_tbox
from virf.ontology.tbox import DANGER_LEVELS, USC_KINDS
from virf.schema import Fact, FactKind

CATALOGUE: dict[str, Any] = load_catalogue()["types"]

PAPER_RULES = (
    "UnsafeMicrowaveUsage",
    "ThrowActionDanger",
    "DropActionDanger",
    "BreakActionDanger",
    "DirtyActionDanger",
    "FillWineDanger",
    "PourToUnsafeTargetDanger",
    "LogicalInconsistency_ActionOnUnlocatedObject",
    "LogicalInconsistency_DirectCookAction",
    "LogicalInconsistency_SliceWithHandheldKnife",
    "MicrowaveContainsUnknownMaterialDanger",
    "CupContainsEggDanger",
    "BreadOnHotStoveDanger",
    "ImproperlyFilledRefrigeratorHazard",
    "AmmoniaBleachMixtureHazardDanger",
    "ChildNearSharpObjectDanger",
    "HotOilContainerHazardDanger",
)
GENERALISED_RULES = (
    "MicrowaveEggDanger",
    "MicrowaveContainsMugDanger",
    "CoffeemachineWithTomatoDanger",
    "ForkInToasterDanger",
    "KettleOnStoveDanger",
    "MugOnStoveBurnerDanger",
    "ForkInStoveBurnerDanger",
    "KnifeOnStoveBurnerDanger",
    "EggOnStoveBurnerDanger",
    "ForcefullyClosingDrawerWithEggDanger",
)
METAL_TOOLS = ("Pot", "Pan", "Fork", "Spoon", "Knife", "ButterKnife", "Kettle", "Ladle")


@pytest.fixture(scope="module")
def tbox_check(tutor) -> dict[str, Any]:
    return check_tbox()


@pytest.fixture(scope="module")
def paper_vocab(paper_tutor):
    """The paper's hand-written rules live only in scenario ``paper``."""
    return paper_tutor.tbox.vocabulary


def _short(entity: Any) -> str:
    return str(entity.getIRI().getShortForm())


def _notes(ax: Any) -> dict[str, str]:
    out = {}
    for ann in ax.getAnnotations():
        value = ann.getValue()
        text = str(value.asLiteral().get().getLiteral()) if value.isLiteral() else ""
        out[str(ann.getProperty().getIRI().getShortForm())] = text
    return out


def _axioms(tutor, keep) -> list[tuple[str, str, Any, dict[str, str]]]:
    """(module, axiom type, axiom, annotations) for modules accepted by ``keep``."""
    out = []
    for ont in tutor.tbox.owl.closure:
        module = tutor.tbox.owl.module_name(ont)
        if keep(module):
            for ax in ont.getLogicalAxioms():
                out.append((module, str(ax.getAxiomType()), ax, _notes(ax)))
    return out


def _is_rule_module(module: str) -> bool:
    return module == "kitchen" or module.startswith("safety-")


# ---------------------------------------------------------------- consistency


def test_tbox_is_consistent(tbox_check) -> None:
    assert tbox_check["consistent"] is True
    assert tbox_check["uscs"] >= 30


def test_no_unsatisfiable_usc(tbox_check) -> None:
    assert tbox_check["unsatisfiable_uscs"] == []


def test_every_catalogue_type_is_satisfiable(tutor) -> None:
    unsat = [
        name
        for name in sorted(CATALOGUE)
        if not tutor.engine.consistent([Fact("X_1", "type", name, FactKind.TYPE)])
    ]
    assert unsat == []


# ---------------------------------------------------------------- rule metadata


def test_usc_annotations_complete(vocab) -> None:
    assert vocab.uscs
    for name, u in vocab.uscs.items():
        assert u.name == name
        assert u.id, name
        assert u.kind in USC_KINDS, name
        assert u.category, name
        assert u.danger_level in DANGER_LEVELS, name
        for field in ("description", "safety_warning", "trigger_reason", "suggestion", "source"):
            assert getattr(u, field).strip(), f"{name}: empty {field}"
        assert u.check_at in ("always", "final"), name
        assert u.definition, f"{name} has no '-def' definition axiom"
        assert u.module.startswith("safety-"), name


def test_usc_ids_are_unique(vocab) -> None:
    ids = [u.id for u in vocab.uscs.values()] + [p.id for p in vocab.preconditions.values()]
    assert len(ids) == len(set(ids))


def test_preconditions_used_by_simulator_exist(vocab) -> None:
    for name in (
        "Precondition_HandNotEmpty",
        "Precondition_NothingHeld",
        "Precondition_ReceptacleClosed",
        "Precondition_NotAReceptacle",
        "Precondition_NoPourTarget",
        "Precondition_LacksAffordance",
    ):
        assert name in vocab.preconditions
        assert vocab.preconditions[name].suggestion


@pytest.mark.parametrize("rule", PAPER_RULES)
def test_paper_rule_present(paper_vocab, rule: str) -> None:
    assert rule in {u.id for u in paper_vocab.uscs.values()}


@pytest.mark.parametrize("rule", PAPER_RULES + GENERALISED_RULES)
def test_paper_rule_covered(paper_vocab, rule: str) -> None:
    covering = [
        u.id
        for u in paper_vocab.uscs.values()
        if u.id == rule or rule in [g.strip() for g in u.generalizes.split(",")]
    ]
    assert covering, f"no USC is or generalises {rule}"


# ---------------------------------------------------------------- axiom provenance


def test_every_identified_axiom_has_a_source(tutor) -> None:
    axioms = _axioms(tutor, _is_rule_module)
    assert len(axioms) > 400
    ids = [notes["id"] for _, _, _, notes in axioms if "id" in notes]
    assert len(ids) == len(set(ids)), "duplicate axiom ids"
    for module, kind, _, notes in axioms:
        if "id" in notes:
            assert notes.get("source", "").strip(), (
                f"{module}: {notes['id']} ({kind}) has no source"
            )


def test_kitchen_axioms_identified(tutor) -> None:
    kitchen = _axioms(tutor, lambda m: m == "kitchen")
    for _, kind, ax, notes in kitchen:
        if kind == "SubClassOf":
            sub = ax.getSubClass()
            if not sub.isAnonymous() and _short(sub.asOWLClass()) in CATALOGUE:
                assert "id" in notes, f"catalogue axiom without id: {ax}"
                assert notes.get("kind") == "background"
            elif "id" not in notes:
                # Unidentified axioms only build the category tree between named classes.
                sup = ax.getSuperClass()
                assert not sub.isAnonymous() and not sup.isAnonymous(), str(ax)
                assert _short(sup.asOWLClass()) not in CATALOGUE, str(ax)
        elif kind == "DisjointClasses":
            assert "id" in notes, str(ax)
        elif kind == "EquivalentClasses" and "id" not in notes:
            named = {_short(c) for c in ax.getClassesInSignature()}
            assert not named & set(CATALOGUE), str(ax)
        elif kind == "ClassAssertion":
            # Punning for values: a material is also the individual of its own
            # class (`Individual: :Metal Types: :Metal`), nothing else.
            cls = ax.getClassExpression()
            ind = ax.getIndividual()
            assert not cls.isAnonymous() and ind.isNamed(), str(ax)
            assert _short(cls.asOWLClass()) == _short(ind.asOWLNamedIndividual()), str(ax)
        else:
            assert kind in ("SubClassOf", "DisjointClasses", "EquivalentClasses"), kind


def test_kitchen_background_matches_catalogue(vocab) -> None:
    for name, info in CATALOGUE.items():
        assert f"KIT-{name}-isa-{info['category']}" in vocab.background, name
        for material in info.get("materials", []):
            assert f"KIT-{name}-material-{material}" in vocab.background, name
            assert material in vocab.class_materials.get(name, frozenset()), name
        for prop in info.get("properties", []):
            assert f"KIT-{name}-property-{prop}" in vocab.background, name


def test_safety_modules_structure(tutor, vocab) -> None:
    safety = _axioms(tutor, lambda m: m.startswith("safety-"))
    roots = {"UnsafeStateConcept", "PreconditionViolation"}
    defined = set()
    for module, kind, ax, notes in safety:
        if kind == "EquivalentClasses":
            ident = notes.get("id", "")
            assert ident.endswith("-def"), f"{module}: definition without '-def' id: {ax}"
            stem = ident.removesuffix("-def")
            assert stem in {_short(c) for c in ax.getNamedClasses()}, ident
            defined.add(stem)
        elif "id" not in notes:
            # The only unidentified axioms place a rule class under its root,
            # or (in the acquired module) a class a candidate introduced under
            # its parent, as the candidate's block says.
            assert kind == "SubClassOf", f"{module}: {ax}"
            assert not ax.getSubClass().isAnonymous()
            sub = _short(ax.getSubClass().asOWLClass())
            introduced = any(
                c.startswith("Introduced by candidate") for c in vocab.annotation(sub, "comment")
            )
            assert _short(ax.getSuperClass().asOWLClass()) in roots or (
                module == "safety-acquired" and introduced
            ), str(ax)
    assert set(vocab.uscs) <= defined


def test_kitchen_module_in_sync_with_catalogue() -> None:
    assert render_kitchen(load_catalogue()) == kitchen_path().read_text(encoding="utf-8")


# ---------------------------------------------------------------- composition


@pytest.mark.parametrize("tool", METAL_TOOLS)
def test_metal_tools_are_conductive(vocab, tool: str) -> None:
    assert "MetallicObject" in vocab.ancestors[tool]
    assert "ConductiveObject" in vocab.ancestors[tool]


def test_knife_is_sharp_but_spoon_is_not(vocab) -> None:
    assert vocab.is_a("Knife", "SharpObject")
    assert not vocab.is_a("Spoon", "SharpObject")


def test_non_metal_tableware_is_not_metallic(vocab) -> None:
    for cls in ("Mug", "Plate", "Bowl", "Apple"):
        assert "MetallicObject" not in vocab.ancestors[cls], cls


@pytest.mark.parametrize("cls", ["Mug", "Plate"])
def test_typical_material_is_ceramic(vocab, cls: str) -> None:
    assert vocab.typical_materials({cls}) == ("Ceramic",)
    # A default, not a TBox fact: the class itself does not force a material.
    assert vocab.materials_of({cls}) == frozenset()


def test_bowl_material_is_only_possible(vocab) -> None:
    # AI2-THOR's bowls are ceramic, glass or plastic: no default, no TBox
    # fact, each material a possibility the scene gets as an assumption.
    assert vocab.typical_materials({"Bowl"}) == ()
    assert vocab.possible_materials({"Bowl"}) == ("Ceramic", "Glass", "Plastic")
    assert vocab.materials_of({"Bowl"}) == frozenset()
