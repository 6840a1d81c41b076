"""Minimal explanations: which facts (and which background axioms) a finding needs.

Black-box deletion over a reasoner: start from the facts connected to the
classified individual, drop each fact in a fixed order and keep it out if the
finding is still entailed.  The result is minimal (every fact is needed) and
deterministic.  Assumptions and defaults are tried for removal first, so a
proof that can do without them does.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

from virf.ontology.tbox import Vocabulary
from virf.reasoning import Engine
from virf.schema import Fact, FactKind, Provenance

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
            members.setdefault(f.subject, set()).update(f.members())
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
) -> list[Fact]:
    """A minimal subset of ``facts`` for which ``holds`` is still true."""
    pool = _component(facts, start, vocab.individuals)
    if not start or not holds(pool):
        pool = list(facts)
    current = sorted(pool, key=lambda f: (_DROP_FIRST[facts[f]], f))
    i = 0
    while i < len(current):
        trial = current[:i] + current[i + 1 :]
        if holds(trial):
            current = trial
        else:
            i += 1
    return sorted(current)


def needed_background(
    engine: Engine,
    facts: list[Fact],
    concept: str,
    individual: str,
    vocab: Vocabulary,
    *,
    deadline: float | None = None,
) -> list[str]:
    """Background axiom ids the entailment needs, given the minimal facts.
    Each engine call stops at ``deadline`` (see :mod:`virf.reasoning`)."""
    names: set[str] = {concept}
    for f in facts:
        names.update((f.subject, f.predicate))
        names.update(f.members() if f.kind is FactKind.CLOSURE else (f.object,))
        if f.kind is FactKind.TYPE:
            names.update(vocab.ancestors.get(f.object, ()))
    for usc in vocab.uscs.values():
        if usc.name == concept:
            names.update(w.strip("(),") for w in usc.definition.split())
    # Grow the signature through axioms that mention it (Pot -> hasMaterial value Metal
    # -> Metal -> hasProperty value Conductive), then test each candidate.
    candidates: list[str] = []
    changed = True
    while changed:
        changed = False
        for ident, ax in sorted(vocab.background.items()):
            if ident not in candidates and ax.signature & names:
                subject = ax.text.split(" ", 1)[0]
                if subject in names or subject.startswith("DisjointClasses"):
                    candidates.append(ident)
                    names |= ax.signature
                    changed = True
    removed: set[str] = set()
    for ident in sorted(candidates):
        if engine.entails(facts, concept, individual, without=removed | {ident}, deadline=deadline):
            removed.add(ident)
    return sorted(set(candidates) - removed)
