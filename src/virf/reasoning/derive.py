"""The rules of a compiled program read backwards: which rules conclude an
atom of a finished model, and from which atoms of it.

Shared by the proofs (:mod:`virf.reasoning.proof`: one derivation) and the
needs (:mod:`virf.reasoning.necessity`: every derivation).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterator, Mapping

from virf.ontology.fragment import Role
from virf.ontology.iri import NOTHING, THING
from virf.reasoning.chase import Model, nominal
from virf.reasoning.program import Program
from virf.schema import Fact, FactKind

# ("t", x, class) | ("r", property, subject, object) | ("d", x, property, value)
# | ("e", x): x is an element
Atom = tuple[object, ...]
# A rule's premises, its axiom id, and the role-hierarchy and chain axioms
# (structural: see Program.structural) the step uses.
Derivation = tuple[list[Atom], str | None, frozenset[str]]
_NONE: frozenset[str] = frozenset()
_NO_TYPES: frozenset[str] = frozenset()
_INDEXES: dict[int, tuple[Program, Rules]] = {}


def atom_of(f: Fact) -> Atom:
    """The model atom an input fact adds; a closure, which adds none, is
    ("c", x, property, members)."""
    if f.kind is FactKind.TYPE:
        return ("t", f.subject, f.object)
    if f.kind is FactKind.OBJECT:
        return ("r", f.predicate, f.subject, f.object)
    if f.kind is FactKind.DATA:
        return ("d", f.subject, f.predicate, f.object == "true")
    return ("c", f.subject, f.predicate, f.members)


def naming(inputs: Mapping[Atom, Fact]) -> dict[str, list[Fact]]:
    """The input facts that make each element (a class is not one): an
    element's were a scan of every input, for every element a proof reached."""
    out: dict[str, list[Fact]] = {}
    for f in inputs.values():
        if f.kind is FactKind.OBJECT:
            names: tuple[str, ...] = (f.subject, f.object)
        elif f.kind is FactKind.CLOSURE:
            names = (f.subject, *f.members)
        else:
            names = (f.subject,)
        for n in dict.fromkeys(names):
            out.setdefault(n, []).append(f)
    return out


def edge(r: Role, a: str, b: str) -> Atom:
    """The stored atom of ``r(a, b)`` (an inverse role is stored the other way)."""
    return ("r", r[0], b, a) if r[1] else ("r", r[0], a, b)


class Rules:
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
        # The same, by the first class of the body: owl:Nothing is the head
        # of a rule for every pair of disjoint classes, of which an element
        # has a few.
        self.conj_at: dict[str, dict[str, list[tuple[int, tuple[str, ...], str | None]]]] = {}
        for b, conjs in self.conj.items():
            by_first: dict[str, list[tuple[int, tuple[str, ...], str | None]]] = {}
            for k, (body, tag) in enumerate(conjs):
                by_first.setdefault(body[0], []).append((k, body, tag))
            self.conj_at[b] = by_first
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


def rules_of(prog: Program) -> Rules:
    found = _INDEXES.get(id(prog))
    if found is None or found[0] is not prog:
        if len(_INDEXES) > 16:
            _INDEXES.clear()
        found = (prog, Rules(prog))
        _INDEXES[id(prog)] = found
    return found[1]


def derivations(
    m: Model, rules: Rules, witness_of: Mapping[str, tuple[str, Role, str]], a: Atom
) -> Iterator[Derivation]:
    """Rules that conclude ``a`` from premises the model holds: premises,
    axiom id, and whether the role hierarchy or a chain was used.  (A
    premise is tested here, where the rule says which can be missing: a
    test of each premise after cost a quarter of reading the needs.)"""
    types = m.types
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
        conjs: list[tuple[tuple[str, ...], str | None]] = rules.conj.get(b, [])
        if len(conjs) > len(ts):
            # Only a body x has can have its premises in the model.
            at_first = rules.conj_at[b]
            firsts = [(k, body, tag) for c in ts if c in at_first for k, body, tag in at_first[c]]
            conjs = [(body, tag) for _, body, tag in sorted(firsts) if ts.issuperset(body)]
        for body, tag in conjs:
            if ts.issuperset(body):
                yield [("t", x, c) for c in body], tag, _NONE
        for n, r, tag in rules.all.get(b, ()):
            for z in sorted(m._stored((r[0], not r[1]), x)):
                if n in types.get(z, _NO_TYPES):
                    yield [("t", z, n), edge(r, z, x)], tag, _NONE
        for r, filler in rules.exists.get(b, ()):
            for y in sorted(m._stored(r, x)):
                if filler in types.get(y, _NO_TYPES):
                    yield [edge(r, x, y), ("t", y, filler)], None, _NONE
        for d, v in rules.data.get(b, ()):
            if v in m.data.get(x, {}).get(d, ()):
                yield [("d", x, d, v)], None, _NONE
        if x in witness_of:
            z, r, w = witness_of[x]
            if w == b:
                for n, tag in rules.some.get((r, w), ()):
                    if n in types.get(z, _NO_TYPES):
                        yield [("t", z, n)], tag, _NONE
        if b == NOTHING:
            return
    elif a[0] == "r":
        p, s, o = str(a[1]), str(a[2]), str(a[3])
        for n, tag in rules.value.get((p, o, False), ()):
            if n in types.get(s, _NO_TYPES):
                yield [("t", s, n)], tag, _NONE
        for n, tag in rules.value.get((p, s, True), ()):
            if n in types.get(o, _NO_TYPES):
                yield [("t", o, n)], tag, _NONE
        for q, inv in rules.up.get(p, ()):
            if (s if inv else o) in m._stored((q, False), o if inv else s):
                yield [("r", q, o, s) if inv else ("r", q, s, o)], None, rules.hierarchy
        for r1, r2, inv in rules.chain.get(p, ()):
            used = rules.chains.get((r1, r2, (p, inv)), frozenset(m.prog.structural))
            start, end = (o, s) if inv else (s, o)
            for z in sorted(m._stored(r1, start)):
                if end in m._stored(r2, z):
                    yield [edge(r1, start, z), edge(r2, z, end)], None, used
        for y, key in ((o, s), (s, o)):
            found = witness_of.get(y)
            if found is not None and found[0] == key and edge(found[1], key, y) == a:
                for n, tag in rules.some.get((found[1], found[2]), ()):
                    if n in types.get(key, _NO_TYPES):
                        yield [("t", key, n)], tag, _NONE
    else:
        x, d, v = str(a[1]), str(a[2]), bool(a[3])
        for n, tag in rules.dhead.get((d, v), ()):
            if n in types.get(x, _NO_TYPES):
                yield [("t", x, n)], tag, _NONE
