"""Knowledge-base axioms compiled to forward-chaining rules.

Every rule is a sound consequence of one axiom, so whatever the rules derive
(including a clash) is entailed: the model they build
(:mod:`virf.reasoning.chase`) is a *lower bound*.  An axiom whose meaning the
rules capture completely is marked *compiled*; the least model of the rules
satisfies it by construction.  The others (existential or disjunctive
right-hand sides, negation on the left) are evaluated on the finished model
by :meth:`virf.reasoning.evaluate.Evaluator.violations`; when none is
violated the model is a genuine model of the knowledge base, which makes it a
countermodel for everything false in it.

A transitive role that no rule reads is left unmaterialised
(:meth:`Program.find_lazy`): the model answers a question about it with a
search over the edges it holds (see :mod:`virf.reasoning.chase`).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from virf.ontology.fragment import Axiom, Expr, Fragment, Role
from virf.ontology.iri import NOTHING, THING
from virf.ontology.tbox import TBox
from virf.reasoning.chase import Model, nominal


@dataclass(frozen=True)
class LazyRole:
    """A role p whose extension is the least relation that contains its base
    edges (asserted, or derived by rules other than the ones below) and is
    closed under ``p o p ⊑ p`` (when ``transitive``), ``p o s ⊑ p`` for each
    s in ``right`` and ``s o p ⊑ p`` for each s in ``left``.

    A p-path is then a word of (left* base right*), once, or repeated when p
    is transitive; :meth:`virf.reasoning.chase.Model.reach` follows such words over the graph."""

    transitive: bool
    left: tuple[Role, ...]
    right: tuple[Role, ...]


@dataclass
class Program:
    """Rules of one knowledge base (a fragment minus some axioms)."""

    # Every rule entry ends with the id of the axiom it comes from (or None).
    sub: dict[str, list[tuple[str, str | None]]] = field(default_factory=lambda: defaultdict(list))
    conj: dict[str, list[tuple[tuple[str, ...], str, str | None]]] = field(
        default_factory=lambda: defaultdict(list)
    )
    # ∃r.A ⊑ B, indexed by role and by filler
    exists_by_role: dict[Role, list[tuple[str, str]]] = field(
        default_factory=lambda: defaultdict(list)
    )
    exists_by_filler: dict[str, list[tuple[Role, str]]] = field(
        default_factory=lambda: defaultdict(list)
    )
    # A ⊑ ∀r.B, indexed by role and by A
    all_by_role: dict[Role, list[tuple[str, str, str | None]]] = field(
        default_factory=lambda: defaultdict(list)
    )
    all_by_class: dict[str, list[tuple[Role, str, str | None]]] = field(
        default_factory=lambda: defaultdict(list)
    )
    value_head: dict[str, list[tuple[Role, str, str | None]]] = field(
        default_factory=lambda: defaultdict(list)
    )
    data_rule: dict[tuple[str, bool], list[str]] = field(default_factory=lambda: defaultdict(list))
    role_up: dict[str, list[Role]] = field(default_factory=dict)  # p -> super roles, not p itself
    chain_first: dict[Role, list[tuple[Role, Role]]] = field(
        default_factory=lambda: defaultdict(list)
    )
    chain_second: dict[Role, list[tuple[Role, Role]]] = field(
        default_factory=lambda: defaultdict(list)
    )
    functional_data: set[str] = field(default_factory=set)
    # A ⊑ ∃r.M: every A gets its own witness (a restricted chase)
    some_head: dict[str, list[tuple[Role, str, str | None]]] = field(
        default_factory=lambda: defaultdict(list)
    )
    data_head: dict[str, list[tuple[str, bool, str | None]]] = field(
        default_factory=lambda: defaultdict(list)
    )
    facts: list[tuple[Any, ...]] = field(default_factory=list)
    checks: list[Axiom] = field(default_factory=list)
    lazy: dict[str, LazyRole] = field(default_factory=dict)
    # ids of axioms compiled into facts or role tables: removing one of them
    # needs a fresh compile, not just disabled rules
    structural: set[str] = field(default_factory=set)
    shaping: list[Axiom] = field(default_factory=list)  # the structural axioms themselves
    _aux: dict[Expr, str] = field(default_factory=dict)
    # The axiom being compiled: rules from right-hand sides carry its id so
    # that a question "without" that axiom can switch them off.  Rules from
    # left-hand sides only define auxiliary names and carry no id.
    _tag: str | None = None

    # ------------------------------------------------------------------ compile
    def aux(self, e: Expr) -> str:
        name = self._aux.get(e)
        if name is None:
            name = f"aux:{len(self._aux)}"
            self._aux[e] = name
        return name

    def left(self, e: Expr) -> str | None:
        """A class name N with rules that make every instance of ``e`` an N
        in the least model, or None when ``e`` is not an EL concept."""
        tag = e[0]
        if tag == "C":
            return str(e[1])
        if e in self._aux:
            return self._aux[e]
        if tag == "and":
            parts = [self.left(c) for c in e[1]]
            if any(p is None for p in parts):
                return None
            n = self.aux(e)
            body = tuple(sorted(set(p for p in parts if p is not None)))
            for b in body:
                self.conj[b].append((body, n, None))
            return n
        if tag == "or":
            parts = [self.left(c) for c in e[1]]
            if any(p is None for p in parts):
                return None
            n = self.aux(e)
            for p in parts:
                assert p is not None
                self.sub[p].append((n, None))
            return n
        if tag == "some" or (tag == "min" and e[1] == 1):
            role, filler = (e[1], e[2]) if tag == "some" else (e[2], e[3])
            inner = self.left(filler)
            if inner is None:
                return None
            n = self.aux(e)
            self.exists_by_role[role].append((inner, n))
            self.exists_by_filler[inner].append((role, n))
            return n
        if tag == "value":
            n = self.aux(e)
            inner = nominal(e[2])
            self.exists_by_role[e[1]].append((inner, n))
            self.exists_by_filler[inner].append((e[1], n))
            return n
        if tag == "oneof":
            n = self.aux(e)
            for i in e[1]:
                self.sub[nominal(i)].append((n, None))
            return n
        if tag == "dvalue":
            n = self.aux(e)
            self.data_rule[(e[1], e[2])].append(n)
            return n
        return None

    def right(self, n: str, e: Expr) -> bool:
        """Rules for ``n ⊑ e``; True when they capture it completely."""
        tag = e[0]
        if tag == "C":
            if e[1] != THING:
                self.sub[n].append((e[1], self._tag))
            return True
        if tag == "and":
            done = [self.right(n, c) for c in e[1]]
            return all(done)
        if tag == "value":
            self.value_head[n].append((e[1], e[2], self._tag))
            return True
        if tag == "all":
            m = self.aux(("all-head", n, e))
            self.all_by_role[e[1]].append((n, m, self._tag))
            self.all_by_class[n].append((e[1], m, self._tag))
            return self.right(m, e[2])
        if tag == "max" and e[1] == 0:
            return self.right(n, ("all", e[2], ("not", e[3])))
        if tag == "some" or (tag == "min" and e[1] == 1):
            role, filler = (e[1], e[2]) if tag == "some" else (e[2], e[3])
            m = self.aux(("some-head", n, e))
            self.some_head[n].append((role, m, self._tag))
            return self.right(m, filler)
        if tag == "not":
            inner = self.left(e[1])
            if inner is None:
                return False
            body = tuple(sorted({n, inner}))
            for b in body:
                self.conj[b].append((body, NOTHING, self._tag))
            return True
        if tag == "dvalue":
            self.data_head[n].append((e[1], e[2], self._tag))
            return True
        return False  # or, min > 1, oneof on the right: left to the model check

    def add(self, ax: Axiom) -> None:
        k, a = ax.kind, ax.args
        self._tag = ax.id
        if ax.id is not None and k in _STRUCTURAL:
            self.structural.add(ax.id)
            self.shaping.append(ax)
        complete = True
        if k == "sub":
            n = self.left(a[0])
            complete = n is not None and self.right(n, a[1])
        elif k == "eq":
            for x in a[0]:
                for y in a[0]:
                    if x is not y:
                        n = self.left(x)
                        complete = (n is not None and self.right(n, y)) and complete
        elif k == "disj":
            for i, x in enumerate(a[0]):
                for y in a[0][i + 1 :]:
                    lx, ly = self.left(x), self.left(y)
                    if lx is None or ly is None:
                        complete = False
                        continue
                    body = tuple(sorted({lx, ly}))
                    for b in body:
                        self.conj[b].append((body, NOTHING, self._tag))
        elif k == "cassert":
            self.facts.append(("element", a[1], ax.id))
            complete = self.right(nominal(a[1]), a[0])
        elif k == "passert":
            self.facts.append(("role", a[0], a[1], a[2], ax.id))
        elif k == "dassert":
            self.facts.append(("data", a[1], a[0], a[2], ax.id))
        elif k == "domain":
            n = self.left(("some", a[0], ("C", THING)))
            assert n is not None
            complete = self.right(n, a[1])
        elif k == "range":
            complete = self.right(THING, ("all", a[0], a[1]))
        elif k == "ddomain":
            for v in (True, False):
                n = self.left(("dvalue", a[0], v))
                assert n is not None
                complete = self.right(n, a[1]) and complete
        elif k == "dfunc":
            self.functional_data.add(a[0])
        elif k in ("drange", "different"):
            pass  # hold in every candidate model (boolean values, distinct names)
        elif k in ("subprop", "inverse", "eqprop", "trans", "sym", "chain"):
            pass  # collected by roles()
        else:
            complete = False
        if not complete:
            self.checks.append(ax)
        self._tag = None

    def roles(self, axioms: Iterable[Axiom]) -> None:
        edges: dict[Role, set[Role]] = defaultdict(set)

        def sub(r: Role, s: Role) -> None:
            edges[r].add(s)
            edges[(r[0], not r[1])].add((s[0], not s[1]))

        for ax in axioms:
            k, a = ax.kind, ax.args
            if k == "subprop":
                sub(a[0], a[1])
            elif k == "inverse":
                sub(a[0], (a[1][0], not a[1][1]))
                sub(a[1], (a[0][0], not a[0][1]))
            elif k == "eqprop":
                for x in a[0]:
                    for y in a[0]:
                        if x != y:
                            sub(x, y)
            elif k == "sym":
                sub(a[0], (a[0][0], not a[0][1]))
            elif k == "trans":
                self._chain(a[0], a[0], a[0])
            elif k == "chain":
                self._chain(a[0][0], a[0][1], a[1])
        names = {r[0] for r in edges}
        for p in sorted(names):
            seen: set[Role] = set()
            todo = [(p, False)]
            while todo:
                r = todo.pop()
                for s in edges.get(r, ()):
                    if s not in seen:
                        seen.add(s)
                        todo.append(s)
            seen.discard((p, False))
            self.role_up[p] = sorted(seen)

    def _chain(self, r1: Role, r2: Role, r: Role) -> None:
        self.chain_first[r1].append((r2, r))
        self.chain_second[r2].append((r1, r))

    def supers(self, p: str) -> list[Role]:
        return self.role_up.get(p, [])

    def find_lazy(self) -> None:
        """Choose the roles left unmaterialised and drop the chain rules that
        would derive their closure edge by edge.

        A role p qualifies when no rule is triggered by a p-edge except the
        chains that define p itself: no super-role (a super-role, or an
        inverse, would have to see every derived edge), no ``some``/``only``
        rule on p, every chain that reads p derives p, and p appears in those
        chains only uninverted and as ``p o p``, ``p o s`` or ``s o p`` with s
        itself materialised.  Then whatever the least model contains outside
        p is the same with or without p's derived edges, and p's extension
        can be read off the base edges when a query asks for it."""
        chains = [(r1, r2, r) for r1, pairs in self.chain_first.items() for r2, r in pairs]
        lazy: dict[str, LazyRole] = {}
        for p in sorted({r[0] for r1, r2, r in chains if r[0] in (r1[0], r2[0])}):
            fwd, inv = (p, False), (p, True)
            if self.role_up.get(p) or any(
                self.exists_by_role.get(r) or self.all_by_role.get(r) for r in (fwd, inv)
            ):
                continue
            transitive, left, right, ok = False, [], [], True
            for r1, r2, r in chains:
                if p not in (r1[0], r2[0], r[0]):
                    continue
                if r1 == r2 == r == fwd:
                    transitive = True
                elif r == fwd and r1 == fwd and r2[0] != p:
                    right.append(r2)
                elif r == fwd and r2 == fwd and r1[0] != p:
                    left.append(r1)
                elif r == fwd and p not in (r1[0], r2[0]):
                    continue  # derives base edges of p from other roles: an ordinary rule
                else:
                    ok = False
            if ok:
                lazy[p] = LazyRole(transitive, tuple(sorted(set(left))), tuple(sorted(set(right))))
        # A lazy role's search walks the edges of its left and right roles as
        # they are stored, so those must be materialised.
        changed = True
        while changed:
            changed = False
            for p, spec in sorted(lazy.items()):
                if any(s[0] in lazy for s in spec.left + spec.right):
                    del lazy[p]
                    changed = True
        self.lazy = lazy
        for table in (self.chain_first, self.chain_second):
            for key in list(table):
                kept = [
                    (other, r)
                    for other, r in table[key]
                    if not (r[0] in lazy and r[0] in (key[0], other[0]))
                ]
                if kept:
                    table[key] = kept
                else:
                    del table[key]

    def finish(self) -> None:
        """Index the rules by trigger: one lookup per new class or role fact."""
        self.ctrig: dict[str, tuple[Any, ...]] = {}
        names = (
            set(self.sub)
            | set(self.conj)
            | set(self.value_head)
            | set(self.all_by_class)
            | set(self.exists_by_filler)
            | set(self.some_head)
            | set(self.data_head)
        )
        for a in names:
            entry = (
                tuple(self.sub.get(a, ())),
                tuple(self.conj.get(a, ())),
                tuple(self.value_head.get(a, ())),
                tuple(self.all_by_class.get(a, ())),
                tuple(self.exists_by_filler.get(a, ())),
                tuple(self.some_head.get(a, ())),
                tuple(self.data_head.get(a, ())),
            )
            if any(entry):
                self.ctrig[a] = entry
        # The classes whose members trigger each axiom's rules (see Model.enable).
        self.tag_classes: dict[str, set[str]] = defaultdict(set)
        for table in (self.sub, self.value_head, self.all_by_class, self.some_head, self.data_head):
            for a, rules in table.items():
                for rule in rules:
                    if rule[-1] is not None:
                        self.tag_classes[rule[-1]].add(a)
        for conj in self.conj.values():
            for body, _, tag in conj:
                if tag is not None:
                    self.tag_classes[tag].add(body[0])
        self.rtrig: dict[str, tuple[Any, ...]] = {}
        props = (
            set(self.role_up)
            | {r[0] for r in self.exists_by_role}
            | {r[0] for r in self.all_by_role}
        )
        props |= {r[0] for r in self.chain_first} | {r[0] for r in self.chain_second}
        for p in props:
            sides = []
            for r in ((p, False), (p, True)):
                sides.append(
                    (
                        tuple(self.exists_by_role.get(r, ())),
                        tuple(self.all_by_role.get(r, ())),
                        tuple(self.chain_first.get(r, ())),
                        tuple(self.chain_second.get(r, ())),
                    )
                )
            self.rtrig[p] = (tuple(self.role_up.get(p, ())), sides[0], sides[1])
        self._bases: dict[frozenset[str], Model] = {}
        self._base_used: frozenset[str] = frozenset()  # see scratch()

    def model(self, disabled: frozenset[str] = frozenset(), *, journal: bool = False) -> Model:
        """A new least model of the TBox's own facts, the caller's to grow.
        With ``journal``, what it derives is recorded from the start, so a
        proof can trace its atoms back to the TBox (see :mod:`.proof`)."""
        m = Model(self, disabled)
        if journal:
            m.begin()
        for fact in self.facts:
            if fact[0] == "element":
                m.element(fact[1])
            elif fact[0] == "role":
                m.role(fact[1], fact[2], fact[3])
            elif fact[0] == "data":
                m.datum(fact[1], fact[2], fact[3])
        m.run()
        m.base_mark = len(m.journal) if m.journal is not None else 0
        return m

    @contextmanager
    def scratch(self, disabled: frozenset[str] = frozenset()) -> Iterator[Model]:
        """The least model of the TBox's own facts (with the rules of the
        ``disabled`` axioms switched off), to grow for one question: built
        once, and rolled back to it when the block ends.  Rolling back costs
        what the question added; copying the TBox's model for every question
        cost more than answering most of them.

        Most axioms a question leaves out (an explanation asks without each
        candidate in turn) have no rule that applies to the TBox's own facts.
        Without them the TBox's model is the same, so a model is built only
        for each set of the others, and grown with all of them switched off."""
        full = self._bases.get(frozenset())
        if full is None:
            self._bases[frozenset()] = full = self.model(journal=True)
            self._base_used = full.applicable()
        shaping = disabled & self._base_used
        found = self._bases.get(shaping)
        if found is None:
            if len(self._bases) > 64:
                self._bases = {frozenset(): full}
            self._bases[shaping] = found = self.model(shaping, journal=True)
        token = found.begin()
        found.disabled = disabled
        try:
            yield found
        finally:
            found.disabled = shaping
            found.rollback(token)


def compile_program(frag: Fragment, without: frozenset[str]) -> Program:
    prog = Program()
    axioms = [a for a in frag.kb if a.id is None or a.id not in without]
    for ax in axioms:
        prog.add(ax)
    prog.roles(axioms)
    prog.find_lazy()
    prog.checks.sort(key=lambda a: a.text)
    prog.finish()
    return prog


_STRUCTURAL = {
    "passert",
    "dassert",
    "subprop",
    "inverse",
    "eqprop",
    "trans",
    "sym",
    "chain",
    "dfunc",
}


def fragment_summary(tbox: TBox) -> dict[str, Any]:
    """Whether the fast engine can answer for this TBox itself, and how."""
    frag = tbox.fragment
    prog = compile_program(frag, frozenset())
    return {
        "exact_fragment": frag.exact,
        "problems": frag.problems,
        "query_classes": len(frag.query_defs),
        "sink_classes": len(frag.sinks),
        "kb_axioms": len(frag.kb),
        "compiled_axioms": len(frag.kb) - len(prog.checks),
        "model_checked_axioms": len(prog.checks),
    }
