"""Proofs read off the fast engine's least model: which input facts and which
axioms a derived atom rests on.

The model's journal records every atom in the order the rules added it, so
an atom was derived by a rule whose premises all came earlier.  A proof is
found backwards from the query: for each atom, a rule of the program that
concludes it from earlier atoms, down to the input facts and the TBox's own
facts.  No rule is applied again; the search reads the finished model.

A proof is one derivation, not necessarily a minimal one, nor the one a
deletion search over the same facts would keep.  The explainer uses it as a
hint (see :func:`virf.verify.explain.drop_greedily`): what a proof leaves out
is dropped without asking the reasoner, and the rest is tested as before, so
the explanation is the same with or without it.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable, Iterator, Mapping
from typing import Any

from virf.ontology.fragment import Expr, Fragment, Role
from virf.ontology.iri import NOTHING, THING
from virf.reasoning import Proof
from virf.reasoning.chase import Hop, Model, nominal
from virf.reasoning.program import Program
from virf.schema import Fact, FactKind

# ("t", x, class) | ("r", property, subject, object) | ("d", x, property, value)
Atom = tuple[object, ...]
# A rule's premises, its axiom id, and the role-hierarchy and chain axioms
# (structural: see Program.structural) the step uses.
Derivation = tuple[list[Atom], str | None, frozenset[str]]
_NONE: frozenset[str] = frozenset()
_NO_TYPES: frozenset[str] = frozenset()
_INDEXES: dict[int, tuple[Program, _Rules]] = {}
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


def atom_of(f: Fact) -> Atom | None:
    """The model atom an input fact adds (None for a closure)."""
    if f.kind is FactKind.TYPE:
        return ("t", f.subject, f.object)
    if f.kind is FactKind.OBJECT:
        return ("r", f.predicate, f.subject, f.object)
    if f.kind is FactKind.DATA:
        return ("d", f.subject, f.predicate, f.object == "true")
    return None


def edge(r: Role, a: str, b: str) -> Atom:
    """The stored atom of ``r(a, b)`` (an inverse role is stored the other way)."""
    return ("r", r[0], b, a) if r[1] else ("r", r[0], a, b)


class _Rules:
    """A program's rules indexed by what they conclude."""

    def __init__(self, prog: Program) -> None:
        self.sub: dict[str, list[tuple[str, str | None]]] = defaultdict(list)
        self.conj: dict[str, list[tuple[tuple[str, ...], str | None]]] = defaultdict(list)
        self.all: dict[str, list[tuple[str, Role, str | None]]] = defaultdict(list)
        self.exists: dict[str, list[tuple[Role, str]]] = defaultdict(list)
        self.data: dict[str, list[tuple[str, bool]]] = defaultdict(list)
        self.some: dict[tuple[Role, str], list[tuple[str, str | None]]] = defaultdict(list)
        self.value: dict[tuple[str, str, bool], list[tuple[str, str | None]]] = defaultdict(list)
        self.dhead: dict[tuple[str, bool], list[tuple[str, str | None]]] = defaultdict(list)
        self.up: dict[str, list[tuple[str, bool]]] = defaultdict(list)
        self.chain: dict[str, list[tuple[Role, Role, bool]]] = defaultdict(list)
        self.tbox: dict[Atom, str | None] = {}
        # Which structural axioms a step rests on: a chain step on its chain
        # (or transitivity), a hierarchy step on every hierarchy axiom (they
        # close over one another), a lazy role's path on what defines it.
        # Naming them all for any such step made every proof that crossed
        # one name axioms the search then dropped, one new proof each.
        self.chains: dict[tuple[Role, Role, Role], frozenset[str]] = defaultdict(frozenset)
        hierarchy: set[str] = set()
        for ax in prog.shaping:
            assert ax.id is not None
            if ax.kind == "chain":
                key = (ax.args[0][0], ax.args[0][1], ax.args[1])
                self.chains[key] = self.chains[key] | {ax.id}
            elif ax.kind == "trans":
                key = (ax.args[0], ax.args[0], ax.args[0])
                self.chains[key] = self.chains[key] | {ax.id}
            elif ax.kind in ("subprop", "inverse", "eqprop", "sym"):
                hierarchy.add(ax.id)
        self.chains = dict(self.chains)
        self.hierarchy = frozenset(hierarchy)
        self.lazy: dict[str, frozenset[str]] = {
            p: self.hierarchy.union(*(ids for k, ids in self.chains.items() if k[2][0] == p))
            for p in prog.lazy
        }
        for a, subs in prog.sub.items():
            for b, tag in subs:
                self.sub[b].append((a, tag))
        # The same, by the subclass too: a general class (PhysicalObject) has
        # hundreds of subclasses, of which an element has a few.
        self.sub_at: dict[str, dict[str, list[tuple[int, str | None]]]] = {}
        for b, subs in self.sub.items():
            by_sub: dict[str, list[tuple[int, str | None]]] = {}
            for k, (a, tag) in enumerate(subs):
                by_sub.setdefault(a, []).append((k, tag))
            self.sub_at[b] = by_sub
        for rules in prog.conj.values():
            for body, head, tag in rules:
                if (body, tag) not in self.conj[head]:
                    self.conj[head].append((body, tag))
        for n, alls in prog.all_by_class.items():
            for r, m, tag in alls:
                self.all[m].append((n, r, tag))
        for filler, pairs in prog.exists_by_filler.items():
            for r, head in pairs:
                self.exists[head].append((r, filler))
        for (d, v), named in prog.data_rule.items():
            for head in named:
                self.data[head].append((d, v))
        for a, somes in prog.some_head.items():
            for r, w, tag in somes:
                self.some[(r, w)].append((a, tag))
        for n, values in prog.value_head.items():
            for r, i, tag in values:
                self.value[(r[0], i, r[1])].append((n, tag))
        for n, data in prog.data_head.items():
            for dp, dv, tag in data:
                self.dhead[(dp, dv)].append((n, tag))
        for p, ups in prog.role_up.items():
            for q, inv in ups:
                self.up[q].append((p, inv))
        for r1, chains in prog.chain_first.items():
            for r2, r3 in chains:
                self.chain[r3[0]].append((r1, r2, r3[1]))
        for fact in prog.facts:
            if fact[0] == "role":
                self.tbox[edge(fact[1], fact[2], fact[3])] = fact[-1]
                for x in fact[2:4]:
                    self.tbox.setdefault(("e", x), fact[-1])
            elif fact[0] == "data":
                self.tbox[("d", fact[1], fact[2], fact[3])] = fact[-1]
                self.tbox.setdefault(("e", fact[1]), fact[-1])
            else:
                self.tbox[("e", fact[1])] = fact[-1]


def rules_of(prog: Program) -> _Rules:
    found = _INDEXES.get(id(prog))
    if found is None or found[0] is not prog:
        if len(_INDEXES) > 16:
            _INDEXES.clear()
        found = (prog, _Rules(prog))
        _INDEXES[id(prog)] = found
    return found[1]


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


def _mentions(inputs: Mapping[Atom, Fact]) -> dict[object, list[Fact]]:
    """The input facts by each name in their atom (an element, a class, a
    property): an element's mentions were a scan of every input, for every
    element a proof reached."""
    out: dict[object, list[Fact]] = {}
    for a, f in inputs.items():
        for n in dict.fromkeys(a[1:]):
            out.setdefault(n, []).append(f)
    return out


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
        self.mentions: dict[object, list[Fact]] = (
            parent.mentions if parent is not None else _mentions(inputs)
        )
        self.witness_of = {y: key for key, y in m.witness.items()}
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
        elif tag != "oneof":
            raise NoProof(f"cannot trace {tag}")

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
        """Rules that conclude ``a``: premises, axiom id, and whether the role
        hierarchy or a chain was used."""
        m, rules = self.m, self.rules
        if a[0] == "t":
            x, b = str(a[1]), str(a[2])
            if b in (THING, nominal(x)):
                yield [("e", x)], None, _NONE
            # Only a class x has can be a premise (what the model lacks has no
            # place in the journal); they are yielded in the rules' order.
            subs = rules.sub.get(b, ())
            ts = m.types.get(x, _NO_TYPES)
            if len(subs) <= len(ts):
                hits = [(c, tag) for c, tag in subs if c in ts]
            else:
                at = rules.sub_at[b]
                hits = [
                    (c, tag)
                    for _, c, tag in sorted((i, c, tag) for c in ts if c in at for i, tag in at[c])
                ]
            for c, tag in hits:
                yield [("t", x, c)], tag, _NONE
            for body, tag in rules.conj.get(b, ()):
                yield [("t", x, c) for c in body], tag, _NONE
            for n, r, tag in rules.all.get(b, ()):
                for z in sorted(m._stored((r[0], not r[1]), x)):
                    yield [("t", z, n), edge(r, z, x)], tag, _NONE
            for r, filler in rules.exists.get(b, ()):
                for y in sorted(m._stored(r, x)):
                    yield [edge(r, x, y), ("t", y, filler)], None, _NONE
            for d, v in rules.data.get(b, ()):
                yield [("d", x, d, v)], None, _NONE
            if x in self.witness_of:
                z, r, w = self.witness_of[x]
                if w == b:
                    for n, tag in rules.some.get((r, w), ()):
                        yield [("t", z, n)], tag, _NONE
            if b == NOTHING:
                return
        elif a[0] == "r":
            p, s, o = str(a[1]), str(a[2]), str(a[3])
            for n, tag in rules.value.get((p, o, False), ()):
                yield [("t", s, n)], tag, _NONE
            for n, tag in rules.value.get((p, s, True), ()):
                yield [("t", o, n)], tag, _NONE
            for q, inv in rules.up.get(p, ()):
                yield [("r", q, o, s) if inv else ("r", q, s, o)], None, rules.hierarchy
            for r1, r2, inv in rules.chain.get(p, ()):
                used = rules.chains.get((r1, r2, (p, inv)), frozenset(m.prog.structural))
                start, end = (o, s) if inv else (s, o)
                for z in sorted(m._stored(r1, start)):
                    if end in m._stored(r2, z):
                        yield [edge(r1, start, z), edge(r2, z, end)], None, used
            for y, key in ((o, s), (s, o)):
                found = self.witness_of.get(y)
                if found is not None and found[0] == key and edge(found[1], key, y) == a:
                    for n, tag in rules.some.get((found[1], found[2]), ()):
                        yield [("t", key, n)], tag, _NONE
        else:
            x, d, v = str(a[1]), str(a[2]), bool(a[3])
            for n, tag in rules.dhead.get((d, v), ()):
                yield [("t", x, n)], tag, _NONE
