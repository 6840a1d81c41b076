"""Minimal explanations: which facts (and which background axioms) a finding needs.

Black-box deletion over a reasoner: start from the facts connected to the
classified individual, drop each fact in a fixed order and keep it out if the
finding is still entailed.  The result is minimal (every fact is needed) and
deterministic.  Assumptions and defaults are tried for removal first, so a
proof that can do without them does.

:class:`Explainer` turns a reasoner's answer into a
:class:`~virf.verify.findings.Finding`: the proof, the background it needs,
whether it is definite, the causal message and the questions an uncertain
finding raises.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass

from virf.ontology.tbox import UnsafeStateConcept, Vocabulary
from virf.reasoning import Engine, Oracle, Proof
from virf.schema import BackgroundKnowledge, Fact, FactKind, Phase, Provenance
from virf.verify.deletion import Hint, Reader, checked_proof, drop_greedily, one_at_a_time
from virf.verify.findings import Finding, inconsistency
from virf.verify.questions import rule_questions
from virf.world.actions import portion_source
from virf.world.state import WorldState

_DROP_FIRST = {
    Provenance.ASSUMED: 0,
    Provenance.DEFAULT: 1,
    Provenance.PLAN: 2,
    Provenance.SCENE: 3,
}


def _component(
    facts: Mapping[Fact, Provenance], start: set[str], tbox_individuals: frozenset[str]
) -> list[Fact]:
    """Facts about individuals linked to ``start`` through ABox relations.

    Entailment of a class assertion depends only on this component; TBox
    individuals (OnState, Metal) are shared leaves and are not walked through.
    """
    # A graph search, not repeated passes over the facts: a chain of n
    # objects would need up to n passes.
    links: dict[str, set[str]] = {}  # relations, both ways; TBox individuals are not entered
    members: dict[str, set[str]] = {}  # closures, from the subject to its members
    for f in facts:
        if f.kind is FactKind.OBJECT:
            links.setdefault(f.subject, set()).add(f.object)
            links.setdefault(f.object, set()).add(f.subject)
        elif f.kind is FactKind.CLOSURE:
            members.setdefault(f.subject, set()).update(f.members)
    reach = set(start)
    todo = list(start)
    while todo:
        x = todo.pop()
        found = [y for y in links.get(x, ()) if y not in tbox_individuals]
        found += members.get(x, ())
        for y in found:
            if y not in reach:
                reach.add(y)
                todo.append(y)
    return [
        f
        for f in facts
        if f.subject in reach
        or (f.kind is FactKind.OBJECT and f.object in reach)
        or f.subject in tbox_individuals
    ]


def minimize(
    facts: Mapping[Fact, Provenance],
    holds: Callable[[list[Fact]], bool],
    start: set[str],
    vocab: Vocabulary,
    prove: Callable[[list[Fact], list[Fact]], Hint[Fact] | None] | None = None,
    each: Callable[[list[Fact], list[Fact], list[bool]], Iterable[bool]] | None = None,
) -> list[Fact]:
    """A minimal subset of ``facts`` for which ``holds`` is still true.
    ``prove(kept, order)`` may name facts of ``kept`` that suffice (a hint,
    tested), and ``each`` answer the tests of a proof's facts together (see
    :func:`drop_greedily`)."""

    def by_order(pool: Iterable[Fact]) -> list[Fact]:
        # (By the facts' kept sort keys: comparing facts calls a Python method.)
        return sorted(pool, key=lambda f: (_DROP_FIRST[facts[f]], f.sort_key))

    ordered = by_order(_component(facts, start, vocab.individuals))

    def hint(kept: list[Fact]) -> Hint[Fact] | None:
        return prove(kept, ordered) if prove else None

    # The component suffices when a proof inside it does (entailment is
    # monotone): the proof the search starts from answers that question too,
    # one model instead of two.
    first = checked_proof(ordered, hint, holds) if start and prove is not None else None
    asked = first is not None
    if not asked and (not start or not holds(ordered)):
        ordered = by_order(facts)
    elif prove is not None:
        asked = True  # the pool's proof was asked for: none that helps
    return Fact.sorted(drop_greedily(ordered, holds, hint if prove else None, each, first, asked))


def needed_background(
    engine: Engine,
    facts: list[Fact],
    concept: str,
    individual: str,
    vocab: Vocabulary,
    *,
    deadline: float | None = None,
    hint: Hint[str] | None = None,
    oracle: Reader[str] | None = None,
) -> list[str]:
    """Background axiom ids the entailment needs, given the minimal facts.
    Each engine call stops at ``deadline`` (see :mod:`virf.reasoning`).
    ``hint`` may name axioms of a proof from these facts (tested before it
    is used, as every proof is).  ``oracle`` may tell whether the facts
    entail the finding without some of the axioms (see :class:`Reader`)."""
    names: set[str] = {concept}
    for f in facts:
        names.update((f.subject, f.predicate))
        # Facts are stored in one direction of an inverse pair (supports),
        # while an axiom may read the other (the reach chain isOn o isNear).
        inverse = vocab.inverses.get(f.predicate)
        if inverse is not None:
            names.add(inverse)
        names.update(f.members if f.kind is FactKind.CLOSURE else (f.object,))
        if f.kind is FactKind.TYPE:
            names.update(vocab.ancestors.get(f.object, ()))
    for usc in vocab.uscs.values():
        if usc.name == concept:
            names.update(w.strip("(),") for w in usc.definition.split())
    # Grow the signature through axioms that mention it (Pot -> hasMaterial value Metal
    # -> Metal -> hasProperty value Conductive), then test each candidate.  A
    # disjointness axiom is a candidate but does not grow the signature: its other
    # classes matter only if something is in them, which an axiom grown from the
    # signature must say (listing all materials would pull in every material's
    # attributes and triple the entailment tests).
    candidates = _grown(names, vocab)
    every = frozenset(candidates)

    def holds(kept: list[str]) -> bool:
        return engine.entails(
            facts, concept, individual, without=every - set(kept), deadline=deadline
        )

    order = sorted(candidates)

    def prove(kept: list[str]) -> Hint[str] | None:
        found = engine.proof(
            facts, concept, individual, without=every - set(kept), order=order, deadline=deadline
        )
        if found is None:
            return None
        return Hint(found.axioms, found.needed_axioms, _axioms_reader(found.oracle))

    def each(kept: list[str], rest: list[str], tested: list[bool]) -> Iterator[bool]:
        dropped = every - set(kept) - set(rest)
        return engine.entails_each_without(
            facts, dropped, rest, tested, concept, individual, deadline=deadline
        )

    if oracle is not None and oracle.decide(0) is True:
        return one_at_a_time(order, 0, oracle, holds)
    first = checked_proof(order, lambda _: hint, holds, holding=True) if hint is not None else None
    return drop_greedily(order, holds, prove, each, first, asked=first is not None)


def _grown(names: set[str], vocab: Vocabulary) -> list[str]:
    """The background axioms that mention ``names``, grown through those
    whose subject is named (see :func:`needed_background`): the least set
    closed under both, found from an index of the axioms by name."""
    by_name, subject_of = _signature_index(vocab)
    background = vocab.background
    names = set(names)
    found: set[str] = set()
    todo = list(names)
    while todo:
        name = todo.pop()
        for ident in by_name.get(name, ()):
            if ident in found:
                continue
            subject, signature = subject_of[ident], background[ident].signature
            if (subject is None or subject in names) and not signature.isdisjoint(names):
                found.add(ident)
                if subject is not None:
                    for n in signature - names:
                        names.add(n)
                        todo.append(n)
    return sorted(found)


_Index = tuple[dict[str, list[str]], dict[str, str | None], list[str]]
_INDEX: dict[int, tuple[Vocabulary, _Index]] = {}


def _axiom_order(vocab: Vocabulary) -> list[str]:
    """The background axiom ids in order, sorted once per vocabulary (a
    finding's proof ranks them all: sorting them each time cost a twentieth
    of an explanation).  Read only."""
    return _background_index(vocab)[2]


def _signature_index(vocab: Vocabulary) -> tuple[dict[str, list[str]], dict[str, str | None]]:
    """Background axiom ids by each name in their signature and by their
    subject, and each axiom's subject (None for a disjointness, which joins
    when any of its classes is named but names none of the others)."""
    by_name, subject_of, _ = _background_index(vocab)
    return by_name, subject_of


def _background_index(vocab: Vocabulary) -> _Index:
    """The background axioms indexed once per vocabulary (see
    :func:`_signature_index` and :func:`_axiom_order`)."""
    found = _INDEX.get(id(vocab))
    if found is None or found[0] is not vocab:
        by_name: dict[str, list[str]] = {}
        subject_of: dict[str, str | None] = {}
        for ident, ax in sorted(vocab.background.items()):
            subject = ax.text.split(" ", 1)[0]
            subject_of[ident] = None if subject.startswith("DisjointClasses") else subject
            # An axiom joins once a name of its signature and its subject are
            # both named: index it under both, so either arrival finds it.  A
            # subject inside the signature is itself such a name, so the
            # subject's arrival is the only one that matters: indexing it under
            # every name made each common name (hasMaterial, Metal) walk
            # hundreds of axioms that could not join yet.
            keys = (
                {subject}
                if subject_of[ident] and subject in ax.signature
                else ax.signature | ({subject} if subject_of[ident] else set())
            )
            for n in keys:
                by_name.setdefault(n, []).append(ident)
        found = (vocab, (by_name, subject_of, sorted(vocab.background)))
        _INDEX[id(vocab)] = found
    return found[1]


def background_knowledge(
    ids: Sequence[str], defaults: Sequence[Fact], vocab: Vocabulary
) -> list[BackgroundKnowledge]:
    """The background axioms ``ids``, then the catalogue ``defaults`` a proof used."""
    return [
        BackgroundKnowledge(id=b, text=vocab.background[b].text, source=vocab.background[b].source)
        for b in ids
    ] + [
        BackgroundKnowledge(
            id=f"DEFAULT-{f.subject}-{f.object}",
            text=f"{f.render()} (typical material of its class; the scene states none)",
            source="VIRF kitchen catalogue (typicalMaterial)",
        )
        for f in defaults
    ]


@dataclass(frozen=True)
class Explainer:
    """Explains findings with one verification's reasoner and deadline.

    Every engine call stops at ``deadline``; ``tick`` is called between the
    calls of a minimisation and raises once the verification is out of time
    (the verifier decides how a timeout is reported)."""

    engine: Engine
    vocab: Vocabulary
    deadline: float
    tick: Callable[[], object]
    # False: no background axioms in the proofs (batch runs that only need
    # verdicts: the message and the report's causal chain go without them).
    background: bool = True

    def finding(
        self,
        usc: UnsafeStateConcept,
        ind: str,
        step: int,
        phase: Phase,
        snapshot: Mapping[Fact, Provenance],
        *,
        full: bool = True,
    ) -> Finding:
        """``ind`` is an instance of ``usc`` in ``snapshot``.  Without ``full``,
        a definite finding is only confirmed (one entailment test without the
        assumed facts) and carries no triggering facts."""
        if full:
            return self._explained(usc, ind, step, phase, snapshot)
        known = [f for f, p in snapshot.items() if p is not Provenance.ASSUMED]
        definite = usc.kind != "uncertainty" and self.engine.entails(
            known, usc.name, ind, deadline=self.deadline
        )
        if not definite:  # uncertain findings are rare; their questions need the proof
            return self._explained(usc, ind, step, phase, snapshot)
        message = f"{usc.trigger_reason[:1].upper()}{usc.trigger_reason[1:]} ({ind})."
        return Finding(usc, step, phase, ind, definite, [], dict(snapshot), [], message)

    def _explained(
        self,
        usc: UnsafeStateConcept,
        ind: str,
        step: int,
        phase: Phase,
        snapshot: Mapping[Fact, Provenance],
    ) -> Finding:
        def holds(fs: list[Fact]) -> bool:
            self.tick()
            return self.engine.entails(fs, usc.name, ind, deadline=self.deadline)

        last: list[Proof | None] = [None]
        asked: list[list[Fact]] = [[]]  # the facts the last proof was asked of
        # The axioms are ranked after the facts, in the background search's
        # order: the fact search's last proof then also serves as that
        # search's first (one proof fewer per finding), while every choice
        # between facts is made as before.
        axioms = _axiom_order(self.vocab) if self.background else []

        def prove(kept: list[Fact], order: list[Fact]) -> Hint[Fact] | None:
            self.tick()
            found = self.engine.proof(
                kept, usc.name, ind, order=[*order, *axioms], deadline=self.deadline
            )
            last[0] = found
            asked[0] = list(kept)
            if found is None:
                return None
            oracle = found.oracle
            reader: Reader[Fact] | None = None
            if oracle is not None:
                reader = Reader(lambda fs: oracle.mask(fs, ()), oracle.decide)
            return Hint(found.facts, found.needed_facts, reader)

        def each(kept: list[Fact], rest: list[Fact], tested: list[bool]) -> Iterator[bool]:
            self.tick()
            return self.engine.entails_each(
                kept, rest, tested, usc.name, ind, deadline=self.deadline
            )

        facts = minimize(snapshot, holds, {ind}, self.vocab, prove, each)
        proof = last[0]
        background_ids = (
            needed_background(
                self.engine,
                facts,
                usc.name,
                ind,
                self.vocab,
                deadline=self.deadline,
                hint=(
                    Hint(proof.axioms, proof.needed_axioms)
                    if proof is not None and proof.facts == set(facts)
                    else None
                ),
                oracle=_without_axioms(proof, asked[0], facts),
            )
            if self.background
            else []
        )
        assumed = [f for f in facts if snapshot[f] is Provenance.ASSUMED]
        defaults = [f for f in facts if snapshot[f] is Provenance.DEFAULT]
        background = background_knowledge(background_ids, defaults, self.vocab)
        definite = usc.kind != "uncertainty" and not assumed
        questions = (
            []
            if definite
            else rule_questions(
                usc,
                ind,
                [_behind(f, snapshot) for f in facts],
                [_behind(f, snapshot) for f in assumed],
                step,
                self.vocab,
            )
        )
        chain = "; ".join(f.render() for f in facts if snapshot[f] is not Provenance.DEFAULT)
        extra = "; ".join(b.text for b in background)
        message = f"{usc.trigger_reason[:1].upper()}{usc.trigger_reason[1:]}: {chain}"
        if extra:
            message += f"; background knowledge: {extra}"
        message += f". Hence {ind} is an instance of {usc.name}."
        return Finding(
            usc, step, phase, ind, definite, facts, dict(snapshot), background, message, questions
        )

    def inconsistency(self, snapshot: Mapping[Fact, Provenance], k: int) -> Finding:
        """Snapshot ``k`` is inconsistent: find a minimal contradiction in it."""

        def contradicts(fs: list[Fact]) -> bool:
            self.tick()
            return not self.engine.consistent(fs, deadline=self.deadline)

        return inconsistency(minimize(snapshot, contradicts, set(), self.vocab), snapshot, k)


def _axioms_reader(oracle: Oracle | None, base: int = 0) -> Reader[str] | None:
    """An oracle's questions about axioms left out (and the ``base`` mask)."""
    if oracle is None:
        return None
    return Reader(lambda axioms: oracle.mask((), axioms), lambda m: oracle.decide(base | m))


def _without_axioms(
    proof: Proof | None, asked: list[Fact], facts: list[Fact]
) -> Reader[str] | None:
    """The oracle of a proof asked of ``asked``, for ``facts`` (fewer) with
    some axioms left out."""
    oracle = None if proof is None else proof.oracle
    if oracle is None:
        return None
    kept = set(facts)
    base = oracle.mask([f for f in asked if f not in kept], ())
    return None if base is None else _axioms_reader(oracle, base)


def note_onset(
    f: Finding, states: Sequence[WorldState], closed: Sequence[Mapping[Fact, Provenance]]
) -> None:
    """Say in a final-state finding's message since when it has held: the
    earliest step from which its facts hold in every state to the end
    (``closed``: each state's closure facts)."""
    n = len(states) - 1
    onset = n
    for k in range(n, -1, -1):
        facts, closures = states[k].facts, closed[k]
        if all(x in facts or x in closures for x in f.facts):
            onset = k
        else:
            break
    f.message += f" It holds from step {onset} until the plan ends."


def _behind(f: Fact, snapshot: Mapping[Fact, Provenance]) -> Fact:
    """The scene's assumption a plan-made one follows from, which is what the
    user can answer: 'Acid_from_Vinegar_1 hasMaterial Acid' is only assumed
    because 'Vinegar_1 hasMaterial Acid' is."""
    objects = {g.subject for g in snapshot if g.kind is FactKind.TYPE}
    source = portion_source(f.subject, objects)
    if source is None:
        return f
    origin = Fact(source, f.predicate, f.object, f.kind)
    return origin if snapshot.get(origin) is Provenance.ASSUMED else f
