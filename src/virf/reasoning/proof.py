"""Proofs read off the fast engine's least model: which input facts and which
axioms a derived atom rests on.

The model's journal records every atom in the order the rules added it, so
an atom was derived by a rule whose premises all came earlier.  A proof is
found backwards from the query: for each atom, a rule of the program that
concludes it from earlier atoms, down to the input facts and the TBox's own
facts.  No rule is applied again; the search reads the finished model.

A proof is one derivation, not necessarily a minimal one, nor the one a
deletion search over the same facts would keep.  The explainer uses it as a
hint (see :func:`virf.verify.deletion.drop_greedily`): what a proof leaves out
is dropped without asking the reasoner, and the rest is tested as before, so
the explanation is the same with or without it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from typing import Any

from virf.ontology.fragment import Expr, Fragment, Role
from virf.ontology.iri import NOTHING
from virf.reasoning import Proof
from virf.reasoning.chase import Hop, Model
from virf.reasoning.derive import Atom, Derivation, derivations, edge, naming, rules_of
from virf.schema import Fact, FactKind

_LATE = 1 << 30  # the rank of what the caller did not rank
# A proof's worth: the ranks of the ranked items it uses (None: no proof).
Worth = frozenset[int] | None
_FREE: frozenset[int] = frozenset()


def _key(w: Worth) -> tuple[int, ...]:
    """Orders worths as a deletion search prefers proofs: it drops the
    earliest item it can, so of two proofs it keeps the one without the
    earliest item they do not share (comparing only the earliest item of
    each tied whenever both had it, and the search then needed another
    proof).  Sorted ranks, compared as tuples with a last rank above all,
    give that order; no proof is below every proof."""
    return () if w is None else (*sorted(w), _LATE)


def _order(journal: list[tuple[Any, ...]], start: int, end: int | None = None) -> dict[Atom, int]:
    """Where each atom entered the journal (from ``start``)."""
    out: dict[Atom, int] = {}
    for i in range(start, len(journal) if end is None else end):
        entry = journal[i]
        if entry[0] in ("t", "r", "d", "e"):
            out.setdefault(entry, i)
    return out


_BASES: dict[int, tuple[Model, dict[Atom, int]]] = {}


def _base_order(m: Model) -> dict[Atom, int]:
    found = _BASES.get(id(m))
    if found is None or found[0] is not m:
        if len(_BASES) > 64:
            _BASES.clear()
        assert m.journal is not None
        found = (m, _order(m.journal, 0, m.base_mark))
        _BASES[id(m)] = found
    return found[1]


class NoProof(Exception):
    """The search met something it does not trace (the hint is then skipped)."""


class Prover:
    """Backward search over one finished model grown from ``inputs``.

    ``certain`` and ``impose`` are the engine's own reading of a query on
    the model (see :class:`virf.reasoning.evaluate.Evaluator`), so the proof follows
    the branch the engine's answer took."""

    def __init__(
        self,
        m: Model,
        frag: Fragment,
        defs: Mapping[str, Expr],
        inputs: Mapping[Atom, Fact],
        rank: Mapping[object, int],
        certain: Callable[[Expr, str], bool],
        impose: Callable[[Expr, str], None],
        *,
        parent: Prover | None = None,
        start: int = 0,
    ) -> None:
        if m.journal is None:
            raise NoProof("the model keeps no journal")
        self.m, self.frag, self.defs, self.inputs = m, frag, defs, inputs
        # Where a derivation has alternatives, the one whose earliest ranked
        # fact or axiom comes latest: a deletion search tries the early ones
        # first, so that is the proof it is likelier to keep.
        self.rank = rank
        self.certain, self.impose = certain, impose
        self.rules = rules_of(m.prog)
        if parent is None:
            # The TBox's own part of the journal is read once per model.
            base = _base_order(m)
            start = m.base_mark
        new = _order(m.journal, start)
        # A refutation's proof reads the journal its assertion extended.  The
        # layers are looked up by hand, newest first: a ChainMap's get was a
        # third of the time the prover took.
        self.layers: list[dict[Atom, int]] = (
            [new, base] if parent is None else [new, *parent.layers]
        )
        # The input facts naming each element, shared with a refutation's prover.
        self.mentions: dict[str, list[Fact]] = (
            parent.mentions if parent is not None else naming(inputs)
        )
        self.witness_of = {y: key for key, y in m.witness.items()}
        self.closures: dict[tuple[str, str], list[Fact]] = {}
        for f in inputs.values():
            if f.kind is FactKind.CLOSURE:
                self.closures.setdefault((f.subject, f.predicate), []).append(f)
        self.facts: set[Fact] = set()
        self.axioms: set[str] = set()
        self.structure: set[str] = set()  # role hierarchy and chain axioms used
        self.done: set[Atom] = set()
        self.free: set[str] = set(parent.free) if parent else set()  # elements the question adds
        self.assumed: set[Atom] = set()  # what a refutation asserts
        self._valids: dict[Atom, list[Derivation]] = {}
        self._worth: dict[Atom, Worth] = {}

    def proof(self, concept: str, x: str) -> Proof:
        self.free.add(x)
        self.query(("C", concept), x)
        return Proof(frozenset(self.facts), frozenset(self.axioms | self.structure))

    # ------------------------------------------------------------------ query
    def query(self, e: Expr, x: str) -> None:
        """Support for ``e(x)`` holding with certain semantics."""
        m, tag = self.m, e[0]
        if tag == "C":
            name = e[1]
            if name in self.defs:
                self._defined(name)
                self.query(self.defs[name], x)
            else:
                self.atom(("t", x, name))
        elif tag == "and":
            for c in e[1]:
                self.query(c, x)
        elif tag == "or":
            options = [c for c in e[1] if self.certain(c, x)]
            if not options:
                raise NoProof("no disjunct holds")
            self.query(self._best(options, x) if len(options) > 1 else options[0], x)
        elif tag == "some" or (tag == "min" and e[1] == 1):
            role, filler = (e[1], e[2]) if tag == "some" else (e[2], e[3])
            found = [y for y in sorted(m.rsucc(role, x)) if self.certain(filler, y)]
            if not found:
                raise NoProof(f"no {role[0]} successor")
            if role[0] not in m.lazy:
                found.sort(key=lambda y: _key(self.worth(edge(role, x, y))), reverse=True)
            y = found[0]
            self.link(role, x, y)
            self.query(filler, y)
        elif tag == "value":
            self.link(e[1], x, e[2])
        elif tag == "dvalue":
            self.atom(("d", x, e[1], e[2]))
        elif tag == "not":
            self.refute(e[1], x)
        elif tag == "all" or (tag == "max" and e[1] == 0):
            # Every successor is one of the closures' members, and each of
            # them is in the filler (all) or cannot be (max 0).
            role, filler = (e[1], e[2]) if tag == "all" else (e[2], e[3])
            for s in sorted(self._bounded(role, x)):
                if tag == "all":
                    self.query(filler, s)
                else:
                    self.refute(filler, s)
        elif tag != "oneof":
            raise NoProof(f"cannot trace {tag}")

    def _bounded(self, r: Role, x: str) -> frozenset[str]:
        """The closure facts that bound the r-successors of x (as the
        engine's certain reading does, through super-properties), and the
        members they leave."""
        out: frozenset[str] | None = None
        if not r[1]:
            for q in [r, *self.m.prog.supers(r[0])]:
                closures = [] if q[1] else self.closures.get((x, q[0]), [])
                for f in closures:
                    self.facts.add(f)
                    members = frozenset(f.members)
                    out = members if out is None else out & members
                if closures and q != r:
                    self.structure |= self.rules.hierarchy
        if out is None:
            raise NoProof(f"nothing closes the {r[0]} successors of {x}")
        return out

    def _best(self, options: list[Expr], x: str) -> Expr:
        """Of the disjuncts that hold, the one whose proof a deletion search
        keeps (:func:`_key`): the first that held was often one the search
        dropped (a vase's material, where the vase's class suffices), and
        each such proof cost the search another."""
        best, best_key = options[0], None
        for c in options:
            saved = (set(self.facts), set(self.axioms), set(self.structure), set(self.done))
            try:
                self.query(c, x)
            except NoProof:
                continue
            else:
                items = [*self.facts, *self.axioms, *self.structure]
                key = _key(frozenset(r for i in items if (r := self.rank.get(i)) is not None))
                if best_key is None or key > best_key:
                    best, best_key = c, key
            finally:
                self.facts, self.axioms, self.structure, self.done = saved
        return best

    def refute(self, e: Expr, x: str) -> None:
        """Support for ``not e(x)``: asserting ``e(x)`` derives a clash (how
        the engine decides it), traced back through what the assertion adds."""
        if e[0] == "or":
            for c in e[1]:
                self.refute(c, x)
            return
        if e[0] == "C" and e[1] in self.defs:
            self._defined(e[1])
            self.refute(self.defs[e[1]], x)
            return
        m = self.m
        token = m.begin()
        try:
            assert m.journal is not None
            before = len(m.journal)
            self.impose(e, x)
            asserted = len(m.journal)
            m.run()
            clash = next((j for j in m.journal[before:] if j[0] == "t" and j[2] == NOTHING), None)
            if clash is None:
                raise NoProof(f"asserting {e[0]} at {x} derives no unsatisfiable class")
            sub = Prover(
                m,
                self.frag,
                self.defs,
                self.inputs,
                self.rank,
                self.certain,
                self.impose,
                parent=self,
                start=before,
            )
            for entry in m.journal[before:asserted]:
                if entry[0] == "e":
                    sub.free.add(str(entry[1]))
                else:
                    sub.assumed.add(entry)
            sub.atom(clash)
        finally:
            m.rollback(token)
        self.facts |= sub.facts
        self.axioms |= sub.axioms
        self.structure |= sub.structure

    def _defined(self, name: str) -> None:
        ident = self.frag.query_axiom[name].id
        if ident is not None:
            self.axioms.add(ident)

    def link(self, r: Role, x: str, y: str) -> None:
        """Support for the edge r(x, y); a lazy role's is its path."""
        p, backward = r
        if p not in self.m.lazy:
            self.atom(edge(r, x, y))
            return
        via: dict[tuple[str, int], Hop] = {}
        self.m.reach(p, x, backward, via)
        node, state = y, 1
        while (node, state) != (x, 0):
            if (node, state) not in via:
                raise NoProof(f"no path of {p} from {x} to {y}")
            before, state, used = via[(node, state)]
            self.atom(edge(used, before, node))
            node = before
        self.structure |= self.rules.lazy.get(p, self.m.prog.structural)

    # ------------------------------------------------------------------ atoms
    def atom(self, a: Atom) -> None:
        if a in self.done:
            return
        self.done.add(a)
        if a in self.assumed:
            return
        if a in self.inputs:
            self.facts.add(self.inputs[a])
            return
        if a in self.rules.tbox:
            self._axiom(self.rules.tbox[a])
            return
        valid = self._valid(a)
        if not valid:
            raise NoProof(f"no derivation of {a} found")
        premises, tag, structure = max(valid, key=lambda d: _key(self._worth_of(d)))
        self._axiom(tag)
        self.structure |= structure
        for p in premises:
            if p[0] == "e":
                self.element(str(p[1]))
            else:
                self.atom(p)

    def _valid(self, a: Atom) -> list[Derivation]:
        """The derivations of ``a`` from earlier atoms (a derivation cannot
        lean on what it derives) by rules not switched off."""
        hit = self._valids.get(a)
        if hit is None:
            hit = []
            at = self._at(a)
            if at is not None:
                disabled, layers = self.m.disabled, self.layers
                for d in self._derivations(a):
                    if d[1] in disabled:
                        continue
                    for p in d[0]:
                        for layer in layers:
                            i = layer.get(p)
                            if i is not None:
                                break
                        if i is None or i >= at:
                            break
                    else:
                        hit.append(d)
            self._valids[a] = hit
        return hit

    def _at(self, a: Atom) -> int | None:
        """Where ``a`` entered the journal (None: it is not in the model)."""
        for layer in self.layers:
            i = layer.get(a)
            if i is not None:
                return i
        return None

    def worth(self, a: Atom) -> Worth:
        """The ranked facts or axioms (their ranks) of the best proof of ``a``
        found, None when it has none: of a choice of derivations, the one
        whose items a deletion search would keep (:func:`_key`)."""
        if a in self._worth:
            return self._worth[a]
        hit: Worth
        if a in self.assumed:
            hit = _FREE
        elif a in self.inputs:
            hit = self._ranked(self.inputs[a])
        elif a in self.rules.tbox:
            tag = self.rules.tbox[a]
            hit = _FREE if tag is None else self._ranked(tag)
        elif a[0] == "e":
            hit = self._element_worth(str(a[1]))
        else:
            hit = max((self._worth_of(d) for d in self._valid(a)), key=_key, default=None)
        self._worth[a] = hit
        return hit

    def _ranked(self, item: object) -> frozenset[int]:
        r = self.rank.get(item)
        return _FREE if r is None else frozenset((r,))

    def _worth_of(self, d: Derivation) -> Worth:
        premises, tag, _ = d
        parts = [self.worth(p) for p in premises]
        if None in parts:
            return None
        own = _FREE if tag is None else self._ranked(tag)
        return own.union(*[p for p in parts if p is not None])

    def _element_worth(self, x: str) -> Worth:
        if x in self.free:
            return _FREE
        if x in self.witness_of:
            z, r, _ = self.witness_of[x]
            return self.worth(edge(r, z, x))
        mentions = self.mentions.get(x)
        if not mentions:
            return None
        # One mention suffices: the one a deletion search tries last.
        return max((self._ranked(f) for f in mentions), key=_key)

    def _axiom(self, tag: str | None) -> None:
        if tag is not None:
            self.axioms.add(tag)

    def element(self, x: str) -> None:
        """Support for x being in the model at all."""
        key: Atom = ("e", x)
        if key in self.done or x in self.free:
            return
        self.done.add(key)
        if key in self.rules.tbox:
            self._axiom(self.rules.tbox[key])
            return
        if x in self.witness_of:
            z, r, _ = self.witness_of[x]
            self.atom(edge(r, z, x))
            return
        mentions = self.mentions.get(x)
        if not mentions:
            raise NoProof(f"nothing the question says names {x}")
        self.facts.add(max(sorted(mentions), key=lambda f: self.rank.get(f, _LATE)))

    def _derivations(self, a: Atom) -> Iterator[Derivation]:
        return derivations(self.m, self.rules, self.witness_of, a)
