"""Knowledge-base axioms compiled to forward-chaining rules, and the model they build.

Every rule is a sound consequence of one axiom, so whatever the rules derive
(including a clash) is entailed: the materialised model is a *lower bound*.
An axiom whose meaning the rules capture completely is marked *compiled*;
the least model of the rules satisfies it by construction.  The others
(existential or disjunctive right-hand sides, negation on the left) are
evaluated on the finished model by :func:`Model.violations`; when none is
violated the model is a genuine model of the knowledge base, which makes it a
countermodel for everything false in it.

A transitive role that no rule reads (VIRF's ``encloses``: transitive, and
extended by ``encloses o supports``, but asked about only by the queries) is
not materialised: its closure over a chain of n objects has n²/2 edges, and
deriving them one rule firing at a time costs n³.  The model keeps the edges
the other rules give it and answers a question about the role with a search
over them (:class:`LazyRole`), which is the same relation.
"""

from __future__ import annotations

import time
from collections import defaultdict, deque
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from itertools import count
from typing import Any

from virf.ontology.fragment import Axiom, Expr, Fragment, Role
from virf.ontology.iri import NOTHING, THING
from virf.reasoning import DeadlineExceeded, current_deadline


def nominal(individual: str) -> str:
    """The class {individual}; the braces keep it apart from every OWL name."""
    return "{" + individual + "}"


@dataclass(frozen=True)
class LazyRole:
    """A role p whose extension is the least relation that contains its base
    edges (asserted, or derived by rules other than the ones below) and is
    closed under ``p o p ⊑ p`` (when ``transitive``), ``p o s ⊑ p`` for each
    s in ``right`` and ``s o p ⊑ p`` for each s in ``left``.

    A p-path is then a word of (left* base right*), once, or repeated when p
    is transitive; :meth:`Model.reach` follows such words over the graph."""

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
        self._spare: Model | None = None

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

    def spare(self) -> Model:
        """A second model of the TBox's own facts, built once, for a caller
        that grows it for a while and rolls it back (see
        :meth:`virf.reasoning.fast.FastEngine.sharing`)."""
        if self._spare is None:
            self._spare = self.model(journal=True)
        return self._spare

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
WITNESS_LIMIT = 5000
# Queue items the rules process between two looks at the clock: small enough
# that a deadline is noticed within milliseconds, large enough that the look
# costs nothing measurable.
_BATCH = 256


class ChaseLimit(Exception):
    """Existential axioms keep creating witnesses: the fast engine gives up."""


class Model:
    """A finite interpretation grown by the rules.  Changes can be recorded in
    a journal and rolled back (used to try an assertion and undo it)."""

    def __init__(self, prog: Program, disabled: frozenset[str] = frozenset()) -> None:
        self.prog = prog
        self.disabled = disabled
        self.types: dict[str, set[str]] = {}
        self.members: dict[str, set[str]] = defaultdict(set)
        self.succ: dict[str, dict[str, set[str]]] = defaultdict(lambda: defaultdict(set))
        self.pred: dict[str, dict[str, set[str]]] = defaultdict(lambda: defaultdict(set))
        self.data: dict[str, dict[str, set[bool]]] = defaultdict(lambda: defaultdict(set))
        self.closures: dict[tuple[str, str], frozenset[str]] = {}
        self.clash: str | None = None
        self.journal: list[tuple[Any, ...]] | None = None
        self.queue: deque[tuple[Any, ...]] = deque()
        self.fresh = 0
        self.witness: dict[tuple[str, Role, str], str] = {}
        self.version = next(_STATES)
        self.lazy = prog.lazy
        # (role, backward, start) -> (model version, individuals reached)
        self._reached: dict[tuple[str, bool, str], tuple[int, set[str]]] = {}
        # Closures "x p nothing" on a lazy role.  run() checks p's base edges
        # against a closure as they arrive, but no rule sees p's derived
        # edges, so it also searches for one at its end.
        self._empty_lazy: list[tuple[str, str]] = []
        self.base_mark = 0  # journal entries of the TBox's own facts (see Program.model)

    def close(self, x: str, p: str, members: frozenset[str]) -> None:
        """``x p only {members}`` (nothing when empty); two closures on the
        same pair intersect.  Before the next :meth:`run`: it checks the
        edges that arrive against the closure."""
        key = (x, p)
        old = self.closures.get(key)
        self.closures[key] = members if old is None else old & members
        if self.journal is not None:
            self.journal.append(("c", key, old))
        if not self.closures[key]:
            # Edges the rules saw before this closure (a model grown in
            # stages) are not seen again: check them here.
            there = self._stored((p, False), x)
            if there and self.clash is None:
                self.clash = f"{x} {p} {min(there)} contradicts '{x} {p} nothing'"
            if p in self.lazy and key not in self._empty_lazy:
                self._empty_lazy.append(key)
                if self.journal is not None:
                    self.journal.append(("z",))
        self.element(x)
        for member in members:
            self.element(member)

    # ------------------------------------------------------------------ growth
    def element(self, x: str) -> None:
        if x in self.types:
            return
        self.types[x] = set()
        if self.journal is not None:
            self.journal.append(("e", x))
        self.cls(x, THING)
        self.cls(x, nominal(x))

    def new_element(self) -> str:
        self.fresh += 1
        name = f"_:fresh{self.fresh}"
        self.element(name)
        return name

    def cls(self, x: str, a: str) -> None:
        ts = self.types.get(x)
        if ts is None:
            self.element(x)
            ts = self.types[x]
        if a in ts:
            return
        ts.add(a)
        self.members[a].add(x)
        self.version = next(_STATES)
        if self.journal is not None:
            self.journal.append(("t", x, a))
        self.queue.append(("t", x, a))

    def role(self, r: Role, x: str, y: str) -> None:
        p, inv = r
        if inv:
            x, y = y, x
        if x not in self.types:
            self.element(x)
        if y not in self.types:
            self.element(y)
        ys = self.succ[p][x]
        if y in ys:
            return
        ys.add(y)
        self.pred[p][y].add(x)
        self.version = next(_STATES)
        if self.journal is not None:
            self.journal.append(("r", p, x, y))
        self.queue.append(("r", p, x, y))

    def datum(self, x: str, d: str, v: bool) -> None:
        if x not in self.types:
            self.element(x)
        vs = self.data[x][d]
        if v in vs:
            return
        vs.add(v)
        self.version = next(_STATES)
        if self.journal is not None:
            self.journal.append(("d", x, d, v))
        self.queue.append(("d", x, d, v))

    def rsucc(self, r: Role, x: str) -> set[str]:
        """The r-successors of x (do not modify the set)."""
        p, inv = r
        if p in self.lazy:
            return self.reach(p, x, inv)
        inner = (self.pred if inv else self.succ).get(p)
        if inner is None:
            return _EMPTY
        return inner.get(x, _EMPTY)

    def rpred(self, r: Role, x: str) -> set[str]:
        return self.rsucc((r[0], not r[1]), x)

    def _stored(self, r: Role, x: str) -> set[str]:
        """The r-edges from x held in the tables: for a lazy role only its base
        edges.  The rules use this; they never read a lazy role."""
        p, inv = r
        table = self.pred if inv else self.succ
        inner = table.get(p)
        if inner is None:
            return _EMPTY
        return inner.get(x, _EMPTY)

    def reach(
        self, p: str, x: str, backward: bool, via: dict[tuple[str, int], Hop] | None = None
    ) -> set[str]:
        """The p-successors (``backward``: p-predecessors) of x for a lazy role
        p: a search over base, left and right edges, remembered until the
        model changes.  ``via`` (a fresh search) receives, for each node and
        state reached, the node, state and stored role it was reached from."""
        key = (p, backward, x)
        hit = self._reached.get(key)
        if hit is not None and hit[0] == self.version and via is None:
            return hit[1]
        found = self.reach_any(p, (x,), backward, via)
        self._reached[key] = (self.version, found)
        return found

    def reach_any(
        self,
        p: str,
        starts: Iterable[str],
        backward: bool,
        via: dict[tuple[str, int], Hop] | None = None,
    ) -> set[str]:
        """What :meth:`reach` gives for any of ``starts``, in one search (the
        union, found in the time of one)."""
        spec = self.lazy[p]
        base = (self.pred if backward else self.succ).get(p, {})
        # A p-path is (left* base right*), repeated when p is transitive.
        # State 1 means a whole block has been crossed (the node is an
        # answer), state 0 that the current block still needs its base edge.
        # Read backward, the blocks are (right* base left*), so the roles
        # taken before the base edge swap with those taken after it.
        before = spec.right if backward else spec.left
        after = spec.left if backward else spec.right
        firsts = set(starts)
        seen: tuple[set[str], set[str]] = (set(firsts), set())
        todo: list[tuple[str, int]] = [(x, 0) for x in sorted(firsts)]

        def edges(roles: tuple[Role, ...], node: str) -> Iterable[tuple[str, Role]]:
            for s in roles:
                r = (s[0], s[1] != backward)
                for y in self._stored(r, node):
                    yield y, r

        mine = (p, backward)
        while todo:
            node, state = todo.pop()
            moves: list[tuple[Iterable[tuple[str, Role]], int]] = []
            if state == 0 or spec.transitive:  # start a block, or the next one
                moves += [(((y, mine) for y in base.get(node, _EMPTY)), 1)]
                moves += [(edges(before, node), 0)]
            if state == 1:
                moves.append((edges(after, node), 1))
            for targets, nxt in moves:
                for y, r in targets:
                    if y not in seen[nxt]:
                        seen[nxt].add(y)
                        todo.append((y, nxt))
                        if via is not None:
                            via[(y, nxt)] = (node, state, r)
        return seen[1]

    def run(self) -> None:
        """Apply the rules to everything queued, until nothing new follows.

        Raises :class:`DeadlineExceeded` when the deadline of the engine call
        passes; the model is then unfinished and must be dropped (or rolled
        back)."""
        ctrig = self.prog.ctrig
        rtrig = self.prog.rtrig
        off = self.disabled
        q = self.queue
        types = self.types
        stored = self._stored
        deadline = current_deadline()
        while q:
            if deadline is not None and time.monotonic() > deadline:
                raise DeadlineExceeded(
                    "the deadline passed while the fast engine applied its rules"
                )
            for _ in range(min(len(q), _BATCH)):
                if self.clash is not None:
                    q.clear()
                    return
                item = q.popleft()
                if item[0] == "t":
                    _, x, a = item
                    if a == NOTHING:
                        self.clash = f"{x} is an instance of owl:Nothing"
                        continue
                    trig = ctrig.get(a)
                    if trig is None:
                        continue
                    subs, conj, value_head, all_by_class, exists_by_filler, some_head, data_head = (
                        trig
                    )
                    ts = types[x]
                    for b, tag in subs:
                        if b not in ts and tag not in off:
                            self.cls(x, b)
                    for body, head, tag in conj:
                        if head not in ts and tag not in off and all(c in ts for c in body):
                            self.cls(x, head)
                    for r, i, tag in value_head:
                        if tag not in off:
                            self.role(r, x, i)
                    for r, b, tag in all_by_class:
                        if tag not in off:
                            for y in list(stored(r, x)):
                                self.cls(y, b)
                    for r, b in exists_by_filler:
                        for z in list(stored((r[0], not r[1]), x)):
                            self.cls(z, b)
                    for r, w, tag in some_head:
                        key = (x, r, w)
                        if key not in self.witness and tag not in off:
                            if self.fresh > WITNESS_LIMIT:
                                raise ChaseLimit(f"more than {WITNESS_LIMIT} anonymous witnesses")
                            y = self.new_element()
                            self.witness[key] = y
                            if self.journal is not None:
                                self.journal.append(("w", key))
                            self.role(r, x, y)
                            self.cls(y, w)
                    for d, v, tag in data_head:
                        if tag not in off:
                            self.datum(x, d, v)
                elif item[0] == "r":
                    _, p, x, y = item
                    if self.closures:
                        bound = self.closures.get((x, p))
                        if bound is not None and not bound:
                            self.clash = f"{x} {p} {y} contradicts '{x} {p} nothing'"
                            continue
                    rt = rtrig.get(p)
                    if rt is None:
                        continue
                    up, forward, backward = rt
                    for s in up:
                        self.role(s, x, y)
                    for (exists_r, all_r, chain1, chain2), a, b in (
                        (forward, x, y),
                        (backward, y, x),
                    ):
                        if exists_r:
                            tb = types[b]
                            for filler, head in exists_r:
                                if filler in tb:
                                    self.cls(a, head)
                        if all_r:
                            ta = types[a]
                            for cls_, head, tag in all_r:
                                if cls_ in ta and tag not in off:
                                    self.cls(b, head)
                        for r2, r3 in chain1:
                            for c in list(stored(r2, b)):
                                self.role(r3, a, c)
                        for r1, r3 in chain2:
                            for w in list(stored((r1[0], not r1[1]), a)):
                                self.role(r3, w, b)
                else:
                    _, x, d, v = item
                    for head in self.prog.data_rule.get((d, v), ()):
                        self.cls(x, head)
                    if d in self.prog.functional_data and len(self.data[x][d]) > 1:
                        self.clash = f"{x} has two values for the functional property {d}"
        if self._empty_lazy and self.clash is None:
            for x, p in self._empty_lazy:
                found = self.reach(p, x, False)
                if found:
                    self.clash = f"{x} {p} {min(found)} contradicts '{x} {p} nothing'"
                    break

    def enable(self, tags: frozenset[str]) -> None:
        """Switch the rules of the axioms ``tags`` back on, and queue what the
        model holds that triggers them; the next :meth:`run` grows the model
        to the least model with them (rules only add, so growing the smaller
        model gives it).  The caller restores :attr:`disabled` when it rolls
        back."""
        self.disabled = self.disabled - tags
        classes = {c for t in tags for c in self.prog.tag_classes.get(t, ())}
        for a in sorted(classes):
            for x in sorted(self.members.get(a, ())):
                self.queue.append(("t", x, a))

    def applicable(self) -> frozenset[str]:
        """Ids of the axioms with a rule whose body some element satisfies
        here (a rule with a class body counts when the class has a member).

        Over a least model, this is every axiom a derivation of anything in
        it can use: the least model of a subset of the facts, or of the rules,
        is contained in this one, so a rule that applies nowhere here applies
        nowhere there.  Leaving such axioms out changes no such model."""
        prog, members = self.prog, self.members
        used: set[str] = set()
        tables: tuple[dict[str, Any], ...] = (
            prog.sub,
            prog.value_head,
            prog.all_by_class,
            prog.some_head,
            prog.data_head,
        )
        for table in tables:
            for a, rules in table.items():
                if members.get(a):
                    used.update(r[-1] for r in rules if r[-1] is not None)
        for conj in prog.conj.values():
            for body, _, tag in conj:
                if tag is None or tag in used:
                    continue
                pool = members.get(body[0])
                if pool and any(all(c in self.types[x] for c in body[1:]) for x in pool):
                    used.add(tag)
        # An axiom on roles applies where one of its roles has an edge (a
        # lazy role's derived edges all start from its stored ones).
        for ax in prog.shaping:
            assert ax.id is not None
            if (
                ax.kind in ("passert", "dassert")
                or any(self.succ.get(p) for p in _role_names(ax.args))
                or (ax.kind == "dfunc" and any(ax.args[0] in t for t in self.data.values()))
            ):
                used.add(ax.id)
        return frozenset(used)

    # ------------------------------------------------------------------ journal
    def begin(self) -> Token:
        """Start recording; :meth:`rollback` with the token restores this exact
        state (including its version, so caches stay valid, and its count of
        fresh names, so witnesses are named alike every time).  Calls nest:
        only the outermost rollback stops the recording."""
        created = self.journal is None
        if self.journal is None:
            self.journal = []
        return (len(self.journal), self.version, self.clash, self.fresh, created)

    def rollback(self, token: Token) -> None:
        mark, version, clash, fresh, created = token
        assert self.journal is not None
        self.queue.clear()
        # Emptied entries are removed, so a model that many questions grow
        # and roll back does not keep every name it has seen.
        while len(self.journal) > mark:
            entry = self.journal.pop()
            tag = entry[0]
            if tag == "t":
                _, x, a = entry
                self.types[x].discard(a)
                _discard(self.members, a, x)
            elif tag == "r":
                _, p, x, y = entry
                _discard(self.succ[p], x, y)
                _discard(self.pred[p], y, x)
            elif tag == "d":
                _, x, d, v = entry
                _discard(self.data[x], d, v)
                if not self.data[x]:
                    del self.data[x]
            elif tag == "w":
                del self.witness[entry[1]]
            elif tag == "c":
                _, key, old = entry
                if old is None:
                    del self.closures[key]
                else:
                    self.closures[key] = old
            elif tag == "z":
                self._empty_lazy.pop()
            else:
                del self.types[entry[1]]
        self.clash = clash
        self.version = version
        self.fresh = fresh
        if created:
            self.journal = None
        if created or len(self._reached) > 4096:
            # Entries of the states rolled back cannot be hit again.
            self._reached.clear()

    # ------------------------------------------------------------------ checks
    def closure_violation(self) -> str | None:
        for (x, p), bound in sorted(self.closures.items()):
            extra = self.rsucc((p, False), x) - bound
            if extra:
                return f"{x} {p} {sorted(extra)[0]} is outside its closure"
        return None


_EMPTY: set[str] = set()
# A journal position, the version, clash and fresh-name count it restores, and
# whether the journal started with it.
Token = tuple[int, int, str | None, int, bool]
# How a lazy role's search reached a node: the node and state it came from,
# and the stored role of the edge it took.
Hop = tuple[str, int, Role]


def _role_names(args: Any) -> set[str]:
    """The role names in an axiom's arguments (roles are (name, inverse) pairs)."""
    is_role = isinstance(args, tuple) and len(args) == 2 and isinstance(args[1], bool)
    if is_role and isinstance(args[0], str):
        return {args[0]}
    out: set[str] = set()
    if isinstance(args, tuple | list):
        for a in args:
            out |= _role_names(a)
    return out


def _discard(table: dict[Any, set[Any]], key: Any, item: Any) -> None:
    found = table.get(key)
    if found is not None:
        found.discard(item)
        if not found:
            del table[key]


# Every model state gets a number never used before, so a cache keyed by it
# cannot confuse two states.
_STATES = count()
