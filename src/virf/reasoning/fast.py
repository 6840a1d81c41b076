"""The fast engine: exact answers from a lower and an upper bound, with the
reference reasoner behind it.

For a question "is ``x`` an instance of ``C``?" over ``TBox + facts``:

* the **lower bound** is the least model of the Horn rules compiled from the
  knowledge-base axioms (:mod:`virf.reasoning.program`).  Rules are sound, so a
  clash there proves inconsistency, and a query that holds there *with certain
  semantics* (negation only where adding the negated fact derives a clash,
  ``only`` and ``max 0`` only through closure facts) is entailed;
* the **upper bound** is a candidate model: the same least model, possibly
  extended with assertions chosen to falsify the query.  It counts only after
  every axiom the rules do not capture has been checked on it, so a query that
  is false there is not entailed.

When the bounds meet, the answer is exact.  When they do not (the candidate
is not a model, or no falsifying extension is found), or when the TBox uses a
construct outside the fragment (detected when the engine is built), or the
input asserts a query or sink class, the question goes to the reference
engine.  Every fallback is counted in :meth:`FastEngine.stats`.

The model is built by :mod:`virf.reasoning.chase`; a query is read over it
by :mod:`virf.reasoning.evaluate`.
"""

from __future__ import annotations

import threading
from collections import Counter
from collections.abc import Callable, Collection, Iterable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any, NamedTuple

from virf.errors import VirfError
from virf.ontology.fragment import Expr, Fragment
from virf.ontology.tbox import TBox
from virf.reasoning import (
    Classification,
    DeadlineExceeded,
    Engine,
    Proof,
    ReasonerFailure,
    check_deadline,
    make_engine,
    until,
)
from virf.reasoning.batch import halving
from virf.reasoning.chase import ChaseLimit, Model
from virf.reasoning.derive import atom_of
from virf.reasoning.evaluate import Evaluator, Fallback, checks
from virf.reasoning.instances import Instances
from virf.reasoning.kept import Core, Kept, individuals
from virf.reasoning.necessity import needed, proof_bits, with_needs
from virf.reasoning.prior import Atoms, Prior, Reads, Values, Wheres, atoms
from virf.reasoning.program import Program, compile_program
from virf.reasoning.proof import NoProof, Prover
from virf.schema import Fact, FactKind

# Names the engine uses for itself; an input name starting like one of these
# could be confused with them, so such an input goes to the reference engine.
_INTERNAL = ("owl:", "aux:", "{", "undefined:", "_:")
# Fewer questions than this are asked one by one: halving costs its own
# bookkeeping (and switching axioms on re-applies their rules to the whole
# model), which a handful of questions do not repay.
BATCH_FROM = 6


_NONE: frozenset[str] = frozenset()

# Atoms a step may add to the shared model and still have its answers kept
# for the next step (see classify_shared).
_PRIOR_AT_MOST = 1000


class Step(NamedTuple):
    """What a step's classification keeps for the next: the atoms it grew
    the core by, its answers, each concept's candidates, and the candidates
    of the definitions it read."""

    grown: Atoms
    values: Values
    wheres: Wheres
    reads: Reads


def fragment_of(tbox: TBox) -> Fragment:
    """The TBox as fast-engine terms (compiled with the knowledge artifact)."""
    return tbox.fragment


class FastEngine(Engine):
    """Exact answers without a DL reasoner for the fragment VIRF's ontology uses."""

    complete = True
    name = "fast"

    def __init__(self, tbox: TBox, timeout_s: float = 30.0) -> None:
        super().__init__(tbox, timeout_s)
        self.fragment = fragment_of(tbox)
        self._programs: dict[frozenset[str], Program] = {}
        self._reference: Engine | None = None
        self._counts: Counter[str] = Counter()
        self._lock = threading.Lock()
        self._core: Core | None = None  # see sharing()
        self._kept = Kept()  # the model sharing() grows, kept between blocks
        self._instances: Instances | None = None  # see instances
        # The last step classify_shared grew the core by, with that core.
        self._last: tuple[Core, Step] | None = None
        # A block's first step, by the state of its core: the next block on
        # the same core (the same plan again, or a repair of it) starts from
        # it, as its later steps start from the step before.
        self._first: tuple[tuple[Any, ...], Step] | None = None
        self._query_ids = frozenset(
            a.id for a in self.fragment.query_axiom.values() if a.id is not None
        )
        # Classes the input may not assert: the rules do not define them.
        self._defined = self.fragment.sinks | self.fragment.query_defs.keys()

    # ------------------------------------------------------------------ plumbing
    @property
    def reference(self) -> Engine:
        if self._reference is None:
            try:
                self._reference = make_engine("reference", self.tbox, self.timeout_s)
            except VirfError as exc:
                # No Java here (or the modules would not load): the question
                # has no answer, which the verifier reports as ERROR.
                raise ReasonerFailure(
                    f"the fast engine needed the reference reasoner, which cannot start: {exc}"
                ) from None
        return self._reference

    def program(self, without: frozenset[str]) -> tuple[Program, frozenset[str]]:
        """Rules for the knowledge base minus ``without``: the shared program
        with those axioms' rules switched off, or, when an axiom shaped facts
        or the role hierarchy, a program compiled without it."""
        full = self._programs.get(frozenset())
        if full is None:
            full = compile_program(self.fragment, frozenset())
            self._programs[frozenset()] = full
        shaping = without & full.structural
        if not shaping:
            return full, without
        # Only the structural axioms need a program of their own; the rules
        # of the others are switched off in it, so an explanation that tries
        # many sets of axioms compiles a program per set of structural ones.
        prog = self._programs.get(shaping)
        if prog is None:
            prog = compile_program(self.fragment, shaping)
            if len(self._programs) > 64:
                self._programs = {frozenset(): full}
            self._programs[shaping] = prog
        return prog, without - shaping

    @contextmanager
    def _model(
        self, facts: list[Fact], without: frozenset[str]
    ) -> Iterator[tuple[Model, Evaluator]]:
        """The least model of the facts, for the block's duration only."""
        if self.fragment.problems:
            raise Fallback("TBox outside the fragment: " + self.fragment.problems[0])
        core = self._core
        if not without and core is not None and core.facts.issubset(facts):
            with self._grown(core, [f for f in facts if f not in core.facts]) as grown:
                yield grown
            return
        prog, disabled = self.program(without)
        with prog.scratch(disabled) as m:
            self._load(m, facts)
            yield m, Evaluator(m, self._definitions(without), self.fragment.sinks)

    @contextmanager
    def _grown(self, core: Core, extra: list[Fact]) -> Iterator[tuple[Model, Evaluator]]:
        """The core's model grown with ``extra`` (facts outside the core), for
        the block's duration only.  The rules are monotone: the core's least
        model grown with the other facts is the least model of all of them."""
        m = core.model
        token = m.begin()
        try:
            self._load(m, extra)
            yield m, Evaluator(m, self.fragment.query_defs, self.fragment.sinks)
        finally:
            m.rollback(token)

    def _load(self, m: Model, facts: list[Fact]) -> None:
        """Add the facts to the model and apply the rules."""
        # One pass: facts are only queued here; the rules (and the closure
        # checks) run afterwards, over all of them.
        for f in facts:
            members = f.members
            if (
                f.subject.startswith(_INTERNAL)
                or f.predicate.startswith(_INTERNAL)
                or (
                    any(n.startswith(_INTERNAL) for n in members)
                    if members
                    else f.object.startswith(_INTERNAL)
                )
            ):
                raise Fallback(f"the input name in '{f.render()}' looks like an internal name")
            if f.kind is FactKind.TYPE:
                if f.object in self._defined:
                    raise Fallback(f"the input asserts the defined class {f.object}")
                m.cls(f.subject, f.object)
            elif f.kind is FactKind.OBJECT:
                m.role((f.predicate, False), f.subject, f.object)
            elif f.kind is FactKind.DATA:
                m.datum(f.subject, f.predicate, f.object == "true")
            else:
                m.close(f.subject, f.predicate, frozenset(members))
        m.run()

    @contextmanager
    def sharing(self, facts: Collection[Fact], *, deadline: float | None = None) -> Iterator[None]:
        """Grow the model of ``facts`` once; a question in the block whose
        facts include them starts from it, and adds only the rest.

        The model is kept after the block, rolled back to the facts it shares
        with earlier blocks (:mod:`virf.reasoning.kept`): verifying another
        plan in the same scene grows it by what differs.  A block that starts
        while another holds it builds a model of its own."""
        with self._lock:
            core: Core | None = None
            kept = self._kept if not self._kept.held else None
            if facts and not self.fragment.problems:
                shared = frozenset(facts)
                prog = self.program(frozenset())[0]
                try:
                    with until(deadline):
                        if kept is not None:
                            m = kept.grow(prog, shared, self._load)
                        else:
                            m = prog.model()
                            self._load(m, Fact.sorted(shared))
                except (Fallback, ChaseLimit, DeadlineExceeded):
                    pass  # the questions will meet it themselves, one by one
                else:
                    if m.clash is None:
                        core = (
                            kept.core(m, shared)
                            if kept is not None
                            else Core(m, shared, individuals(shared))
                        )
            before, self._core = self._core, core
        try:
            yield
        finally:
            with self._lock:
                # Blocks of two threads may end out of order: leave a newer core alone.
                if self._core is core:
                    self._core = before
                    self._last = None
                if kept is not None and kept.held:
                    kept.release()

    def _definitions(self, without: frozenset[str]) -> dict[str, Expr]:
        """Query definitions minus the removed ones.  A query class whose
        definition is removed is a class no axiom constrains: it gets a name
        no rule mentions, so it is empty in the model and assertable."""
        frag = self.fragment
        removed = without & self._query_ids
        if not removed:
            return frag.query_defs
        return {
            q: (e if frag.query_axiom[q].id not in removed else ("C", f"undefined:{q}"))
            for q, e in frag.query_defs.items()
        }

    def _answer(self, exact: Callable[[], Any], fallback: Callable[[], Any]) -> Any:
        with self._lock:
            self._counts["calls"] += 1
            try:
                return exact()
            except (Fallback, ChaseLimit) as why:
                self._counts["fallbacks"] += 1
                self._counts[f"fallback: {why}"] += 1
        return fallback()

    # ------------------------------------------------------------------ engine API
    def _classify(self, facts: list[Fact], concepts: list[str]) -> Classification:
        def exact() -> Classification:
            with self._model(facts, frozenset()) as (m, ev):
                return self.instances(m, ev, individuals(facts), concepts)

        result: Classification = self._answer(
            exact, lambda: self.reference._classify(facts, concepts)
        )
        return result

    def classify_shared(
        self,
        shared: frozenset[Fact],
        extra: Collection[Fact],
        concepts: Sequence[str],
        *,
        deadline: float | None = None,
    ) -> Classification:
        """Grows the block's model with ``extra`` alone: a step costs what it
        adds, not what the scene holds."""
        core = self._core
        if core is None or core.facts is not shared or self.fragment.problems:
            return super().classify_shared(shared, extra, concepts, deadline=deadline)
        if not self.tbox.vocabulary.classes.issuperset(concepts):
            return super().classify_shared(shared, extra, concepts, deadline=deadline)
        added = Fact.sorted(f for f in extra if f not in shared)

        def exact() -> Classification:
            if self._core is not core:  # another thread's block replaced it
                raise Fallback("the shared model changed")
            m, defs, sinks = core.model, self.fragment.query_defs, self.fragment.sinks
            token = m.begin()
            try:
                self._load(m, added)
                assert m.journal is not None
                # A step that changes much (a box moved with a thousand in it)
                # leaves little an earlier answer could be kept for.
                small = len(m.journal) - token[0] <= _PRIOR_AT_MOST
                grown = atoms(m, token[0]) if small else frozenset()
                # The previous step grew the same core: where the two steps'
                # atoms differ is all that can change an answer.
                last = self._last
                if last is None and core.state is not None:
                    first = self._first
                    if first is not None and first[0] == core.state:
                        last = (core, first[1])
                        self._counts["first steps from an earlier block"] += 1
                prior = None
                before = None
                reads = None
                if small and last is not None and last[0] is core:
                    step = last[1]
                    prior = Prior(step.values, defs, sinks, step.grown ^ grown)
                    touched = self.instances.touched(prior, m)
                    before = (step.wheres, touched)
                    reads = (step.reads, touched)
                ev = Evaluator(m, defs, sinks, prior, reads)
                wheres: Wheres = {}
                found = self.instances(
                    m, ev, core.individuals | individuals(added), concepts, before, wheres
                )
                kept = Step(grown, ev.values, wheres, ev.reads()) if small else None
                if self._last is None and core.state is not None:
                    self._first = None if kept is None else (core.state, kept)
                self._last = None if kept is None else (core, kept)
                return found
            finally:
                m.rollback(token)

        def fallback() -> Classification:
            return self.reference._classify(Fact.sorted(shared | set(added)), list(concepts))

        with until(deadline):
            check_deadline(f"before the {self.name} engine classified the facts")
            result: Classification = self._answer(exact, fallback)
        return result

    @property
    def instances(self) -> Instances:
        """Reads the instances of concepts off a grown model (built when
        first asked for: it needs the compiled program)."""
        if self._instances is None:
            lazy = self.program(frozenset())[0].lazy
            self._instances = Instances(self.fragment, lazy)
        return self._instances

    def _entails(
        self, facts: list[Fact], concept: str, individual: str, without: frozenset[str]
    ) -> bool:
        def exact() -> bool:
            if individual.startswith(_INTERNAL):
                raise Fallback(f"the individual '{individual}' looks like an internal name")
            with self._model(facts, without) as (m, ev):
                if individual not in m.types:  # before the model check: it is part of the model
                    m.element(individual)
                    m.run()
                if m.clash is not None:
                    return True
                bad = ev.violations(checks(m))
                if bad is not None:
                    raise Fallback(f"candidate model violates: {bad}")
                return ev.decide(concept, individual)

        result: bool = self._answer(
            exact,
            lambda: self.reference._entails(facts, concept, individual, without),
        )
        return result

    def entails_each(
        self,
        kept: Sequence[Fact],
        items: Sequence[Fact],
        tested: Sequence[bool],
        concept: str,
        individual: str,
        *,
        deadline: float | None = None,
    ) -> Iterator[bool]:
        """The questions answered on one model of ``kept``, halving the items
        (:func:`~virf.reasoning.batch.halving`): an item is added about log n
        times instead of n times (a chain of a hundred facts, each tested,
        cost a hundred models)."""
        if individual.startswith(_INTERNAL) or sum(tested) < BATCH_FROM:
            return super().entails_each(kept, items, tested, concept, individual, deadline=deadline)

        def add(m: Model, chosen: list[int]) -> None:
            self._load(m, Fact.sorted({items[i] for i in chosen}))

        def exact() -> list[bool]:
            with until(deadline), self._model(Fact.sorted(set(kept)), frozenset()) as (m, _):
                return halving(m, tested, add, lambda m: self._decided(m, concept, individual))

        def one_by_one() -> list[bool]:
            return list(
                super(FastEngine, self).entails_each(
                    kept, items, tested, concept, individual, deadline=deadline
                )
            )

        result: list[bool] = self._answer(exact, one_by_one)
        return iter(result)

    def entails_each_without(
        self,
        facts: Sequence[Fact],
        dropped: Collection[str],
        items: Sequence[str],
        tested: Sequence[bool],
        concept: str,
        individual: str,
        *,
        deadline: float | None = None,
    ) -> Iterator[bool]:
        """The questions answered on one model of the facts, halving the axioms
        as :meth:`entails_each` halves facts: a half's axioms are switched
        back on (:meth:`Model.enable`) and off again after.  Structural
        axioms need programs of their own, so a search that tests one asks
        one question at a time."""

        def one_by_one() -> Iterator[bool]:
            return super(FastEngine, self).entails_each_without(
                facts, dropped, items, tested, concept, individual, deadline=deadline
            )

        full = self.program(frozenset())[0]
        if (
            individual.startswith(_INTERNAL)
            or set(items) & full.structural
            or sum(tested) < BATCH_FROM
        ):
            return one_by_one()

        def add(m: Model, chosen: list[int]) -> None:
            m.enable(frozenset(items[i] for i in chosen))
            m.run()

        def exact() -> list[bool]:
            prog, disabled = self.program(frozenset(dropped) | frozenset(items))
            with until(deadline), prog.scratch(disabled) as m:
                self._load(m, Fact.sorted(set(facts)))
                return halving(m, tested, add, lambda m: self._decided(m, concept, individual))

        result: list[bool] = self._answer(exact, lambda: list(one_by_one()))
        return iter(result)

    def _decided(self, m: Model, concept: str, individual: str) -> bool:
        """Is ``concept(individual)`` entailed by the facts in ``m`` (grown,
        with the rules of ``m.disabled`` off)?"""
        token = m.begin()
        try:
            if individual not in m.types:
                m.element(individual)
                m.run()
            if m.clash is not None:
                return True
            ev = Evaluator(m, self._definitions(m.disabled), self.fragment.sinks)
            bad = ev.violations(checks(m))
            if bad is not None:
                raise Fallback(f"candidate model violates: {bad}")
            return ev.decide(concept, individual)
        finally:
            m.rollback(token)

    def _consistent(self, facts: list[Fact], without: frozenset[str]) -> bool:
        def exact() -> bool:
            with self._model(facts, without) as (m, ev):
                if m.clash is not None:
                    return False
                bad = ev.violations(checks(m))
                if bad is not None:
                    raise Fallback(f"candidate model violates: {bad}")
                return True

        result: bool = self._answer(exact, lambda: self.reference._consistent(facts, without))
        return result

    def proof(
        self,
        facts: Iterable[Fact],
        concept: str,
        individual: str,
        *,
        without: Collection[str] = (),
        order: Sequence[object] = (),
        deadline: float | None = None,
    ) -> Proof | None:
        """One derivation read off the least model of ``facts`` (see
        :mod:`virf.reasoning.proof`), when the query is certain there; None
        otherwise, or when the proof needs what the search does not trace (a
        universal, a number restriction, a clash not of a class)."""
        frag = self.fragment
        if frag.problems:
            return None
        given = Fact.sorted(set(facts))
        inputs = {atom_of(f): f for f in given}
        rank = dict(zip(order, range(len(order)), strict=True))
        with until(deadline), self._lock:
            prog, disabled = self.program(frozenset(without))
            try:
                with prog.scratch(disabled) as m:
                    self._load(m, given)
                    if individual not in m.types:
                        m.element(individual)
                        m.run()
                    if m.clash is not None:
                        return None
                    ev = Evaluator(m, self._definitions(frozenset(without)), frag.sinks)
                    if not ev.certain(("C", concept), individual):
                        return None
                    args = (m, frag, ev.defs, inputs, rank, concept, individual, frozenset(without))
                    known = None
                    # A proof read off the graph names only the axioms ranked.
                    if rank.keys() >= self.tbox.vocabulary.background.keys():
                        # Every item wanted: the claims serve the backward
                        # search's proof too, if the graph's is not one.
                        known = needed(*args)
                        read = with_needs(None, known, order)
                        if read is not None:
                            return read
                    prover = Prover(m, frag, ev.defs, inputs, rank, ev.certain, ev.impose)
                    found = prover.proof(concept, individual)
                    if known is None:
                        known = needed(*args, wanted=proof_bits(found, rank))
                    return with_needs(found, known, order)
            except (Fallback, ChaseLimit, NoProof, RecursionError):
                return None

    def stats(self) -> dict[str, int]:
        with self._lock:
            return dict(self._counts)

    @contextmanager
    def counting(self) -> Iterator[Counter[str]]:
        """Stats of the calls made inside the block."""
        before = Counter(self._counts)
        delta: Counter[str] = Counter()
        try:
            yield delta
        finally:
            delta.update(self._counts)
            delta.subtract(before)
