"""The fast engine answers exactly as the reference engine, and refuses what it cannot do.

Engine-level checks: consistency, classification of every USC, and entailment
with background axioms removed, on hand-made corner cases and on random fact
sets drawn with hypothesis.  Report-level equivalence lives in
``test_equivalence.py``.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from virf.api import LogicTutor
from virf.ontology.tbox import load_tbox
from virf.reasoning import Engine, make_engine
from virf.reasoning.chase import Model
from virf.reasoning.fast import FastEngine, fragment_of
from virf.reasoning.program import compile_program
from virf.schema import Fact, FactKind

FULL = os.environ.get("VIRF_FULL") == "1"
FIXTURES = Path(__file__).parent / "fixtures"


def T(s: str, c: str) -> Fact:
    return Fact(s, "type", c, FactKind.TYPE)


def R(s: str, p: str, o: str) -> Fact:
    return Fact(s, p, o)


def C(s: str, p: str, *members: str) -> Fact:
    return Fact.closure(s, p, members)


def D(s: str, p: str, v: bool) -> Fact:
    return Fact(s, p, "true" if v else "false", FactKind.DATA)


@pytest.fixture(scope="module")
def engines(tutor: LogicTutor, reference_tutor: LogicTutor) -> tuple[FastEngine, Engine]:
    fast = make_engine("fast", tutor.tbox)
    assert isinstance(fast, FastEngine)
    return fast, reference_tutor.engine


def same_answers(fast: FastEngine, ref: Engine, facts: list[Fact]) -> None:
    concepts = sorted(fast.tbox.vocabulary.uscs)
    assert fast.consistent(facts) == ref.consistent(facts)
    assert fast.classify(facts, concepts) == ref.classify(facts, concepts)


def test_the_shipped_tbox_is_inside_the_fragment(tutor: LogicTutor) -> None:
    frag = fragment_of(tutor.tbox)
    assert frag.exact, frag.problems
    # Every hazard defined by a class expression is evaluated as a query.
    complex_uscs = {
        u for u, c in tutor.tbox.vocabulary.uscs.items() if " EquivalentTo " in c.definition
    }
    atomic = {u for u in complex_uscs if c_is_atomic(tutor.tbox.vocabulary.uscs[u].definition)}
    assert complex_uscs - atomic <= set(frag.query_defs)
    assert "UnsafeStateConcept" in frag.sinks
    assert compile_program(frag, frozenset()).checks == []


def c_is_atomic(definition: str) -> bool:
    _, _, right = definition.partition(" EquivalentTo ")
    return right.strip().isidentifier()


def test_a_construct_outside_the_fragment_is_refused_at_load() -> None:
    tbox = load_tbox("kitchen", (str(FIXTURES / "outside-fragment.omn"),))
    fast = make_engine("fast", tbox)
    assert isinstance(fast, FastEngine)
    frag = fragment_of(tbox)
    assert not frag.exact
    assert any("FunctionalObjectProperty" in p for p in frag.problems), frag.problems
    ref = make_engine("reference", tbox)
    facts = [T("Fridge_1", "Fridge"), R("Fridge_1", "hasState", "OpenState")]
    got = fast.classify(facts, ["ColdStorageLeftOpenDanger"])
    assert got == ref.classify(facts, ["ColdStorageLeftOpenDanger"])
    assert got.instances == {"ColdStorageLeftOpenDanger": ("Fridge_1",)}
    # Every question went to the reference engine.
    assert fast.stats()["fallbacks"] == fast.stats()["calls"] == 1


@pytest.mark.parametrize(
    ("module", "facts"),
    [
        ("builtin-nothing.omn", [T("g", "ImpossibleGadget")]),
        ("builtin-thing.omn", [T("r", "Robot"), R("r", "hasState", "OffState")]),
    ],
)
def test_builtin_classes_are_never_ignored(module: str, facts: list[Fact]) -> None:
    tbox = load_tbox("kitchen", (str(FIXTURES / module),))
    frag = fragment_of(tbox)
    assert "owl:Nothing" not in frag.sinks and "owl:Thing" not in frag.query_defs
    fast, ref = make_engine("fast", tbox), make_engine("reference", tbox)
    assert fast.consistent(facts) == ref.consistent(facts) is False


@pytest.mark.parametrize("name", ["owl:Nothing", "_:fresh1", "aux:0", "{Metal}", "undefined:X"])
def test_names_like_internal_ones_go_to_the_reference(
    name: str, engines: tuple[FastEngine, Engine]
) -> None:
    fast, ref = engines
    facts = [T("x", name), T("Pot_1", "MetallicObject"), R("Pot_1", "isNear", "x")]
    with fast.counting() as delta:
        same_answers(fast, ref, facts)
    assert delta["fallbacks"] == 2


def test_nested_trials_keep_the_outer_journal(engines: tuple[FastEngine, Engine]) -> None:
    fast, _ = engines
    with fast._model([T("F", "Fridge")], frozenset()) as (m, _):
        outer = m.begin()
        m.cls("F", "Apple")
        inner = m.begin()
        m.cls("F", "Mug")
        m.run()
        m.rollback(inner)
        assert m.journal is not None  # the inner rollback must not stop the recording
        m.cls("F", "Bowl")
        m.run()
        m.rollback(outer)
        assert m.journal is not None  # the question's own journal goes on
        assert "Fridge" in m.types["F"]
        assert not {"Apple", "Mug", "Bowl"} & m.types["F"]
    # Back to the TBox's own journal (kept for proofs), the question's gone.
    assert m.journal is not None and len(m.journal) == m.base_mark
    assert "F" not in m.types  # the question's facts are gone with it


def test_a_question_leaves_the_shared_model_as_it_found_it(
    engines: tuple[FastEngine, Engine],
) -> None:
    """Every question grows the TBox's model and rolls it back: nothing of
    one question, closures and fresh witnesses included, reaches the next."""
    fast, _ = engines
    prog, disabled = fast.program(frozenset())

    def shape(m: Model) -> tuple[object, ...]:
        return (
            {x: frozenset(ts) for x, ts in m.types.items()},
            {a: frozenset(xs) for a, xs in m.members.items()},
            # A role's table may stay, empty: there are only so many roles.
            {p: {x: frozenset(ys) for x, ys in t.items()} for p, t in m.succ.items() if t},
            {p: {x: frozenset(ys) for x, ys in t.items()} for p, t in m.pred.items() if t},
            {x: dict(t) for x, t in m.data.items()},
            dict(m.closures),
            dict(m.witness),
            m.fresh,
            m.version,
            m.clash,
        )

    with prog.scratch(disabled) as m:
        before = shape(m)
    facts = [
        T("Pot_1", "Pot"),
        T("Stove_1", "StoveBurner"),
        R("Pot_1", "isOnTopOf", "Stove_1"),
        C("Pot_1", "contains"),
    ]
    fast.classify(facts, ["StoveBurner"])
    fast.entails(facts, "StoveBurner", "Pot_1")
    with prog.scratch(disabled) as m:
        assert shape(m) == before
        fresh = m.new_element()
    with prog.scratch(disabled) as m:
        assert m.new_element() == fresh  # witnesses are named alike every time


def test_asserting_a_query_class_falls_back(engines: tuple[FastEngine, Engine]) -> None:
    fast, ref = engines
    facts = [T("X_1", "ColdStorageLeftOpenDanger")]
    with fast.counting() as delta:
        same_answers(fast, ref, facts)
    assert delta["fallbacks"] == 2


CORNER_CASES = {
    "open fridge": [T("F", "Fridge"), R("F", "hasState", "OpenState")],
    "contradictory states": [
        T("F", "Fridge"),
        R("F", "hasState", "OpenState"),
        R("F", "hasState", "ClosedState"),
    ],
    "burner with an unknown thing": [
        T("B", "StoveBurner"),
        T("Thing_1", "PhysicalObject"),
        R("B", "supports", "Thing_1"),
        R("B", "hasState", "OnState"),
    ],
    "burner with an apple (disjoint from cookware)": [
        T("B", "StoveBurner"),
        T("A", "Apple"),
        R("B", "supports", "A"),
    ],
    "lit burner, nothing on it, closed": [
        T("B", "StoveBurner"),
        R("B", "hasState", "OnState"),
        C("B", "supports"),
    ],
    "lit burner, nothing on it, open world": [
        T("B", "StoveBurner"),
        R("B", "hasState", "OnState"),
    ],
    "closure contradicts an asserted successor": [
        T("B", "StoveBurner"),
        T("P", "Pot"),
        R("B", "supports", "P"),
        C("B", "supports"),
    ],
    "closure names a different object (equality possible)": [
        T("M", "Microwave"),
        T("Mug_1", "Mug"),
        T("Bowl_1", "Bowl"),
        R("M", "contains", "Mug_1"),
        C("M", "contains", "Bowl_1"),
        R("M", "hasState", "OnState"),
    ],
    "running microwave with an empty closed vessel": [
        T("M", "Microwave"),
        T("Mug_1", "Mug"),
        R("M", "contains", "Mug_1"),
        C("M", "contains", "Mug_1"),
        R("Mug_1", "hasState", "EmptyState"),
        C("Mug_1", "contains"),
        R("M", "hasState", "OnState"),
    ],
    "metal fork inside a bowl in a running microwave (transitive encloses)": [
        T("M", "Microwave"),
        T("Bowl_1", "Bowl"),
        T("Fork_1", "Fork"),
        R("M", "contains", "Bowl_1"),
        R("Bowl_1", "contains", "Fork_1"),
        R("M", "hasState", "OnState"),
    ],
    "pour onto a lit stove": [
        T("S5", "PourAction"),
        T("B", "StoveBurner"),
        R("S5", "hasTarget", "B"),
    ],
    "unlocated target": [
        T("S1", "PickAction"),
        T("A", "Apple"),
        R("S1", "hasTarget", "A"),
        D("A", "isLocated", False),
    ],
    "two values of a functional data property": [
        T("A", "Apple"),
        D("A", "isLocated", False),
        D("A", "isLocated", True),
    ],
    "asserted metallic object without a material": [
        T("X", "MetallicObject"),
        T("T", "Toaster"),
        R("T", "contains", "X"),
        R("T", "hasState", "OnState"),
    ],
    # Found in review: closures whose members are not linked (explanations drop
    # facts one by one and produce exactly these) once crashed the
    # falsification search through nested journals.
    "closure with unlinked members under a lit burner": [
        T("B", "StoveBurner"),
        R("B", "hasState", "OnState"),
        T("P", "Pot"),
        R("B", "supports", "P"),
        C("P", "contains", "Metal", "y"),
    ],
    "running microwave whose closure lists an untyped vessel": [
        T("M", "Microwave"),
        R("M", "hasState", "OnState"),
        C("M", "contains", "Cup_1", "Mug_1"),
        T("Cup_1", "Cup"),
        R("Cup_1", "hasState", "EmptyState"),
        C("Cup_1", "contains"),
        R("Mug_1", "hasState", "EmptyState"),
        C("Mug_1", "contains"),
    ],
    "unknown material in a running microwave": [
        T("M", "Microwave"),
        T("Box_1", "Box"),
        R("Box_1", "hasMaterial", "UnknownMaterial"),
        R("M", "contains", "Box_1"),
        R("M", "hasState", "OnState"),
    ],
}


@pytest.mark.parametrize("name", sorted(CORNER_CASES))
def test_corner_cases_match_the_reference(name: str, engines: tuple[FastEngine, Engine]) -> None:
    fast, ref = engines
    same_answers(fast, ref, CORNER_CASES[name])


def test_entailment_without_background_axioms(engines: tuple[FastEngine, Engine]) -> None:
    fast, ref = engines
    facts = [
        T("S5", "PourAction"),
        T("L", "LightSwitch"),
        R("S5", "hasTarget", "L"),
        T("M", "Mug"),
        R("S5", "hasPatient", "M"),
        R("M", "hasState", "FilledWithLiquidState"),
    ]
    vocab = fast.tbox.vocabulary
    rule = "LiquidPouredOntoElectricalDanger"
    ids = [
        b
        for b in sorted(vocab.background)
        if "LightSwitch" in b or rule in b or b in ("MECH-HoldsLiquid", "MECH-LiveDevice")
    ]
    assert "MECH-HoldsLiquid" in ids and "KIT-LightSwitch-property-ElectricallyPowered" in ids
    assert fast.entails(facts, rule, "S5")
    for removed in [(), *[(b,) for b in ids]]:
        got = fast.entails(facts, rule, "S5", without=removed)
        assert got == ref.entails(facts, rule, "S5", without=removed), removed


# ---------------------------------------------------------------------- random fact sets
def _pools(tbox_vocab: object) -> dict[str, list[str]]:
    from virf.ontology.tbox import Vocabulary

    assert isinstance(tbox_vocab, Vocabulary)
    v = tbox_vocab
    objects = sorted(
        c
        for c in v.classes
        if v.is_a(c, "PhysicalObject") and c in v.class_materials and c not in v.uscs
    )
    return {
        "objects": objects,
        "actions": sorted(c for c in v.classes if c.endswith("Action") and v.is_a(c, "Action")),
        "states": sorted(i for i in v.individuals if i.endswith("State")),
        "materials": sorted(i for i in v.individuals if v.is_a(i, "Material")),
    }


OBJ_PROPS = ("contains", "supports", "isNear", "touched", "isHolding", "controls", "encloses")


@st.composite
def fact_sets(draw: st.DrawFn, pools: dict[str, list[str]]) -> list[Fact]:
    n = draw(st.integers(2, 6))
    names = [f"o{i}" for i in range(n)]
    facts = [T(x, draw(st.sampled_from(pools["objects"]))) for x in names]
    for x in names:
        for _ in range(draw(st.integers(0, 2))):
            facts.append(R(x, "hasState", draw(st.sampled_from(pools["states"]))))
        if draw(st.booleans()):
            facts.append(R(x, "hasMaterial", draw(st.sampled_from(pools["materials"]))))
        if draw(st.integers(0, 4)) == 0:
            facts.append(D(x, "isLocated", draw(st.booleans())))
    for _ in range(draw(st.integers(0, 6))):
        a, b = draw(st.sampled_from(names)), draw(st.sampled_from(names))
        facts.append(R(a, draw(st.sampled_from(OBJ_PROPS)), b))
    if draw(st.booleans()):
        facts.append(T("act", draw(st.sampled_from(pools["actions"]))))
        for role in ("hasTarget", "hasPatient"):
            if draw(st.booleans()):
                facts.append(R("act", role, draw(st.sampled_from(names))))
        if draw(st.booleans()):
            facts += [T("Robot_1", "Robot"), R("act", "hasAgent", "Robot_1")]
            facts.append(R("Robot_1", "isHolding", draw(st.sampled_from(names))))
    for x in names:
        for prop in ("contains", "supports"):
            if draw(st.integers(0, 3)) == 0:
                succ = sorted({f.object for f in facts if f.subject == x and f.predicate == prop})
                if succ and draw(st.integers(0, 3)) == 0:
                    succ = succ[1:]  # sometimes a closure that an asserted fact breaks
                if draw(st.integers(0, 3)) == 0:  # members that are not linked, or not objects
                    succ += draw(st.lists(st.sampled_from([*names, "Metal", "y"]), max_size=2))
                facts.append(C(x, prop, *sorted(set(succ))))
    return facts


RANDOM = settings(
    max_examples=400 if FULL else 40,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


def test_random_fact_sets_match_the_reference(engines: tuple[FastEngine, Engine]) -> None:
    fast, ref = engines
    pools = _pools(fast.tbox.vocabulary)
    background = sorted(fast.tbox.vocabulary.background)

    @RANDOM
    @given(fact_sets(pools), st.data())
    def check(facts: list[Fact], data: st.DataObject) -> None:
        same_answers(fast, ref, facts)
        concept = data.draw(st.sampled_from(sorted(fast.tbox.vocabulary.uscs)))
        individual = data.draw(st.sampled_from(sorted({f.subject for f in facts})))
        without = data.draw(st.lists(st.sampled_from(background), max_size=3))
        assert fast.entails(facts, concept, individual, without) == ref.entails(
            facts, concept, individual, without
        )

    check()


def test_a_shared_core_gives_the_same_answers(engines: tuple[FastEngine, Engine]) -> None:
    """Questions answered from the model of a shared part of their facts
    (Engine.sharing) get the answers they get from scratch: the rules are
    monotone.  Some questions leave part of the core out: those start over."""
    fast, _ = engines
    pools = _pools(fast.tbox.vocabulary)
    concepts = sorted(fast.tbox.vocabulary.uscs)

    @RANDOM
    @given(fact_sets(pools), st.data())
    def check(facts: list[Fact], data: st.DataObject) -> None:
        core = data.draw(st.lists(st.sampled_from(facts), unique=True))
        extra = data.draw(st.lists(st.sampled_from(facts), unique=True))
        individual = data.draw(st.sampled_from(sorted({f.subject for f in facts})))
        concept = data.draw(st.sampled_from(concepts))
        plain = (
            fast.consistent(facts),
            fast.classify(facts, concepts),
            fast.entails(facts, concept, individual),
            fast.entails(extra, concept, individual),  # may lack part of the core
        )
        with fast.counting() as plain_calls:
            fast.classify(facts, concepts)
        with fast.sharing(core):
            shared = (
                fast.consistent(facts),
                fast.classify(facts, concepts),
                fast.entails(facts, concept, individual),
                fast.entails(extra, concept, individual),
            )
            with fast.counting() as shared_calls:
                fast.classify(facts, concepts)
        assert shared == plain
        assert shared_calls["fallbacks"] == plain_calls["fallbacks"]

    check()


def test_a_block_on_the_same_core_starts_from_the_block_before(
    engines: tuple[FastEngine, Engine],
) -> None:
    """A plan verified again, or repaired, shares its facts with the last
    one: the first step of its block starts from the first step of the block
    before (its later steps start from the step before them), and gets the
    answers it gets from scratch.  A block on other facts in between starts
    the next one over."""
    fast, _ = engines
    pools = _pools(fast.tbox.vocabulary)
    concepts = sorted(fast.tbox.vocabulary.uscs)
    started: list[tuple[bool, int]] = []  # (a block in between, first steps reused)

    @RANDOM
    @given(fact_sets(pools), st.data())
    def check(facts: list[Fact], data: st.DataObject) -> None:
        core = frozenset(data.draw(st.lists(st.sampled_from(facts), min_size=2, unique=True)))
        blocks = [
            data.draw(st.lists(st.lists(st.sampled_from(facts), unique=True), min_size=1))
            for _ in range(2)
        ]
        between = data.draw(st.booleans())
        expected = [[fast.classify([*core, *step], concepts) for step in b] for b in blocks]
        with fast.sharing(core):
            first = [fast.classify_shared(core, step, concepts) for step in blocks[0]]
        if between:
            other = core - {min(core)}
            with fast.sharing(other):
                fast.classify_shared(other, [], concepts)
        with fast.counting() as calls, fast.sharing(core):
            second = [fast.classify_shared(core, step, concepts) for step in blocks[1]]
        assert [first, second] == expected
        if fast.consistent(core):
            started.append((between, calls["first steps from an earlier block"]))

    check()
    again = [n for between, n in started if not between]
    assert again and sum(again) > len(again) // 2, again
    assert not any(n for between, n in started if between)


def test_a_closure_that_comes_after_its_edge_is_still_a_clash(
    engines: tuple[FastEngine, Engine],
) -> None:
    """The core holds 'Fridge_1 contains Apple_1'; the question adds 'Fridge_1
    contains nothing'.  The rules saw the edge before the closure existed,
    so the closure itself must find it, without asking the reference engine."""
    fast, ref = engines
    edge = R("Fridge_1", "contains", "Apple_1")
    facts = [T("Fridge_1", "Fridge"), T("Apple_1", "Apple"), edge, C("Fridge_1", "contains")]
    assert ref.consistent(facts) is False
    core = [T("Fridge_1", "Fridge"), T("Apple_1", "Apple"), edge]
    with fast.sharing(core), fast.counting() as delta:
        assert fast.consistent(facts) is False
    assert delta["fallbacks"] == 0, dict(delta)
