"""What every derivation of a finding needs, read off one least model: the
input facts and axioms without which the finding is no longer entailed.

An explanation's deletion search asks, for each fact or axiom of a proof,
whether the finding survives without it.  Nearly always it does not, and
each such answer cost a model without that item.  Here the answers "it does
not" come from the model the proof was read from.

**Atoms.**  Every atom of the least model has its derivations: the rules that
conclude it from atoms of the model (:func:`virf.reasoning.derive.derivations`),
and its being an input fact or a fact of the TBox.  What an atom *needs* is
the greatest solution of

    need(a) = ⋂ over derivations d of a: own(d) ∪ ⋃ over premises p of d: need(p)

(own: the input fact, or the axiom whose rule d applies).  That is exactly
the set of items without which the least model lacks ``a``: an atom derived
without item x is derived from atoms derived without x, so by induction x is
in no such solution's need of it; and the items every derivation needs are a
solution.  The greatest solution is found by iterating down from "every
item".  An atom left at "every item" has no derivation grounded in the
inputs: the enumeration missed a rule, and nothing is claimed at all.

**The query.**  Entailment is decided by the engine's own reading of the
query (negation by refutation, closures for ``only``).  A claim is made only
for the query's positive skeleton, where each negation, universal, number
restriction, lazy role or sink is replaced by Thing: the skeleton is implied
by the query, and it is false in the least model without x whenever x is in
its need.  With no axioms left to check (:func:`~virf.reasoning.evaluate.checks`),
that least model is a model of the knowledge base (it is consistent: the one
with x is).  So the query is false in a model of what is left, hence not
entailed: the deletion search's answer, found without the model.

Under-claiming is always safe (the search then asks the reasoner as
before), so whatever this reading cannot vouch for counts as needing
nothing: an element's existence, the role hierarchy and role chains (they
are compiled into the program, see :attr:`Program.structural`).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping
from contextlib import suppress

from virf.ontology.fragment import Expr, Fragment, Role
from virf.ontology.iri import NOTHING, THING
from virf.reasoning.chase import ChaseLimit, Model
from virf.reasoning.derive import Atom, derivations, edge, rules_of
from virf.schema import Fact

# The need of an atom not yet bounded: every item (an infinite bit set).
_TOP = -1
# One derivation: its own item's bit, and its premises.
_Option = tuple[int, tuple[Atom, ...]]
_Memo = dict[tuple[Expr, str], int | None]


def needed(
    m: Model,
    frag: Fragment,
    defs: Mapping[str, Expr],
    inputs: Mapping[Atom, Fact],
    rank: Mapping[object, int],
    concept: str,
    x: str,
    wanted: int = _TOP,
) -> int:
    """The ranks (as bits) of the ranked items without which ``concept(x)``
    is not entailed, given that it is entailed by the facts and rules of
    ``m`` (its least model, grown).  The search for them stops once those
    of ``wanted`` (a proof's) are all found."""
    if m.prog.checks or m.clash is not None:
        return 0
    needs = _Needs(m, frag, defs, inputs, rank)
    found = needs.query(concept, x)
    for part in _conjuncts(("C", concept), defs):
        if not wanted & ~found:
            break
        with suppress(ChaseLimit):  # too many witnesses: claim nothing more
            found |= needs.refuted(part, x)
    return found


def _conjuncts(e: Expr, defs: Mapping[str, Expr]) -> list[Expr]:
    """The conjuncts of ``e``, through the definitions of named queries."""
    if e[0] == "C" and e[1] in defs:
        return _conjuncts(defs[e[1]], defs)
    if e[0] == "and":
        return [c for part in e[1] for c in _conjuncts(part, defs)]
    return [e]


def _other_clash(m: Model) -> bool:
    """A clash the rules do not mark with owl:Nothing, or a closure the
    model breaks (a model grown past its first clash is checked whole)."""
    for (x, p), bound in m.closures.items():
        if m.rsucc((p, False), x) - bound:
            return True
    functional = m.prog.functional_data
    return any(len(table.get(d, ())) > 1 for table in m.data.values() for d in functional)


class _Needs:
    """The needs of the atoms of one state of a model (see the module's docstring)."""

    def __init__(
        self,
        m: Model,
        frag: Fragment,
        defs: Mapping[str, Expr],
        inputs: Mapping[Atom, Fact],
        rank: Mapping[object, int],
        free: frozenset[Atom] = frozenset(),
    ) -> None:
        self.m, self.frag, self.defs = m, frag, defs
        self.inputs, self.rank, self.free = inputs, rank, free
        self.rules = rules_of(m.prog)
        self.structural = m.prog.structural
        self.witness_of = {y: key for key, y in m.witness.items()}
        self.options: dict[Atom, list[_Option]] = {}
        self.users: dict[Atom, list[Atom]] = {}
        self.need: dict[Atom, int] = {}
        self.pending: list[Atom] = []  # premises of paths, still to explore
        self._paths_from: dict[tuple[str, bool, str], dict[str, Atom]] = {}

    def _bit(self, item: object) -> int:
        r = self.rank.get(item)
        return 0 if r is None else 1 << r

    def _own(self, tag: str | None) -> int:
        return 0 if tag is None or tag in self.structural else self._bit(tag)

    def query(self, concept: str, x: str) -> int:
        """The need of the query's positive skeleton at ``x``."""
        roots: list[Atom] = []
        e: Expr = ("C", concept)

        def collect(a: Atom) -> int:
            roots.append(a)
            return 0

        if self._expr(e, x, collect, {}) is None:
            return 0  # the skeleton is false: the caller's premise does not hold
        if not self._settle(roots):
            return 0
        found = self._expr(e, x, self.need.__getitem__, {})
        return 0 if found is None or found < 0 else found

    def _settle(self, roots: list[Atom]) -> bool:
        self._explore(roots + self.pending)
        self.pending = []
        return self._solve()

    # ------------------------------------------------------------------ negation
    def refuted(self, part: Expr, x: str) -> int:
        """What a negation in the conjunct ``part`` of the query at ``x``
        needs: ``not N``, or ``r some (... and not N)``.

        A class that falsifies ``not N`` (N, or one of its disjuncts) is
        asserted where the conjunct would otherwise hold (at ``x``, or at
        each r-successor where the rest of the filler holds), and the model
        grown past its first clash.  An item every clash needs is one
        without which the assertions are consistent: the least model of the
        rest with them is a model where the conjunct, hence the query, is
        false (when no new successor satisfies the rest of the filler there)."""
        defs = self.defs
        role: Role | None = None
        filler: Expr | None = None
        if part[0] == "not":
            negated, targets = [part[1]], [x]
        elif part[0] == "some" or (part[0] == "min" and part[1] == 1):
            role, filler = (part[1], part[2]) if part[0] == "some" else (part[2], part[3])
            negated = [c[1] for c in _conjuncts(filler, defs) if c[0] == "not"]
            targets = [z for z in sorted(self._ends(role, x)) if self._holds(filler, z)]
            if not targets or any(z in self.witness_of for z in targets):
                return 0
        else:
            return 0
        found = 0
        for e in negated:
            for name in self._falsifiers(e):
                found |= self._trial(name, targets, role, filler, x)
        return found

    def _falsifiers(self, e: Expr) -> list[str]:
        """Named classes whose assertion at an element makes ``e`` true there."""
        if e[0] == "C":
            if e[1] in self.defs:
                return self._falsifiers(self.defs[e[1]])
            return [] if e[1] == THING or e[1] in self.frag.sinks else [e[1]]
        if e[0] == "or":
            return [n for c in e[1] for n in self._falsifiers(c)]
        return []

    def _trial(
        self, name: str, targets: list[str], role: Role | None, filler: Expr | None, x: str
    ) -> int:
        """What every clash needs once ``name`` is asserted at the targets
        (see :meth:`refuted`)."""
        m = self.m
        assert m.journal is not None
        token = m.begin()
        try:
            start = len(m.journal)
            for z in targets:
                m.cls(z, name)
            asserted = frozenset(a for a in m.journal[start:] if a[0] in ("t", "r", "d"))
            m.run(through=True)
            clashes = sorted(m.members.get(NOTHING, ()))
            if not clashes or _other_clash(m):
                return 0
            grown = _Needs(m, self.frag, self.defs, self.inputs, self.rank, asserted)
            if role is not None and filler is not None:
                ends = grown._ends(role, x)
                if any(z not in targets and grown._holds(filler, z) for z in ends):
                    return 0  # a successor the assertions made
            roots: list[Atom] = [("t", w, NOTHING) for w in clashes]
            if not grown._settle(roots):
                return 0
            found = _TOP
            for a in roots:
                found &= grown.need[a]
            return max(found, 0)
        finally:
            m.rollback(token)

    def _holds(self, e: Expr, y: str) -> bool:
        """Is the positive skeleton of ``e`` true at ``y``?"""
        return self._expr(e, y, lambda a: 0, {}) is not None

    # ------------------------------------------------------------------ the skeleton
    def _expr(self, e: Expr, y: str, atom: Callable[[Atom], int], memo: _Memo) -> int | None:
        """The need of the positive skeleton of ``e`` at ``y`` (None: false
        in the model).  ``atom`` gives an atom's need."""
        key = (e, y)
        if key in memo:
            return memo[key]
        memo[key] = None  # a definition cannot reach itself; guard anyway
        m, tag = self.m, e[0]
        found: int | None = 0
        if tag == "C":
            name = e[1]
            if name in self.defs:
                inner = self._expr(self.defs[name], y, atom, memo)
                found = None if inner is None else inner | self._definition(name)
            elif name == THING or name in self.frag.sinks:
                found = 0
            else:
                found = atom(("t", y, name)) if name in m.types.get(y, ()) else None
        elif tag == "and":
            for c in e[1]:
                part = self._expr(c, y, atom, memo)
                if part is None:
                    found = None
                    break
                assert found is not None
                found |= part
        elif tag == "or":
            found = None
            for c in e[1]:
                part = self._expr(c, y, atom, memo)
                if part is not None:
                    found = part if found is None else found & part
        elif tag == "some" or (tag == "min" and e[1] == 1):
            role, filler = (e[1], e[2]) if tag == "some" else (e[2], e[3])
            ends = self._ends(role, y)
            found = None
            for z in sorted(ends):
                part = self._expr(filler, z, atom, memo)
                if part is not None:
                    both = part | atom(ends[z])
                    found = both if found is None else found & both
        elif tag == "value":
            ends = self._ends(e[1], y)
            found = atom(ends[e[2]]) if e[2] in ends else None
        elif tag == "dvalue":
            present = e[2] in m.data.get(y, {}).get(e[1], ())
            found = atom(("d", y, e[1], e[2])) if present else None
        elif tag == "oneof":
            found = 0 if y in e[1] else None
        # not, all, max, min > 1: Thing in the skeleton
        memo[key] = found
        return found

    def _definition(self, name: str) -> int:
        """The query class's own definition: without it the class is empty."""
        return self._own(self.frag.query_axiom[name].id)

    def _ends(self, role: Role, y: str) -> dict[str, Atom]:
        """The r-successors of ``y``, each with the atom of the edge to it
        (a lazy role's: of the paths to it)."""
        if role[0] in self.m.lazy:
            return self._paths(role[0], y, role[1])
        return {z: edge(role, y, z) for z in self.m.rsucc(role, y)}

    def _paths(self, p: str, start: str, backward: bool) -> dict[str, Atom]:
        """The ends of the paths of the lazy role ``p`` from ``start``, each
        with an atom whose derivations are the last steps of those paths
        (the search :meth:`Model.reach_any` makes, every step kept)."""
        key = (p, backward, start)
        found = self._paths_from.get(key)
        if found is not None:
            return found
        m, options, users = self.m, self.options, self.users
        spec = m.lazy[p]
        base = (m.pred if backward else m.succ).get(p, {})
        before = spec.right if backward else spec.left
        after = spec.left if backward else spec.right

        def node(n: str, state: int) -> Atom:
            return ("p", p, backward, start, n, state)

        def steps(roles: tuple[Role, ...], n: str) -> list[tuple[str, Atom]]:
            out = []
            for s in roles:
                r = (s[0], s[1] != backward)
                out += [(z, edge(r, n, z)) for z in sorted(m._stored(r, n))]
            return out

        options.setdefault(node(start, 0), []).append((0, ()))
        seen = {(start, 0)}
        todo = [(start, 0)]
        while todo:
            n, state = todo.pop()
            here = node(n, state)
            moves: list[tuple[str, int, Atom]] = []
            if state == 0 or spec.transitive:
                moves += [(z, 1, edge((p, backward), n, z)) for z in sorted(base.get(n, ()))]
                moves += [(z, 0, a) for z, a in steps(before, n)]
            if state == 1:
                moves += [(z, 1, a) for z, a in steps(after, n)]
            for z, nxt, a in moves:
                there = node(z, nxt)
                options.setdefault(there, []).append((0, (here, a)))
                users.setdefault(here, []).append(there)
                users.setdefault(a, []).append(there)
                self.pending.append(a)
                if (z, nxt) not in seen:
                    seen.add((z, nxt))
                    todo.append((z, nxt))
        found = {n: node(n, 1) for n, state in sorted(seen) if state == 1}
        self._paths_from[key] = found
        return found

    # ------------------------------------------------------------------ atoms
    def _present(self, a: Atom) -> bool:
        m, kind = self.m, a[0]
        if kind == "t":
            return str(a[2]) in m.types.get(str(a[1]), ())
        if kind == "r":
            return str(a[3]) in m._stored((str(a[1]), False), str(a[2]))
        if kind == "d":
            return bool(a[3]) in m.data.get(str(a[1]), {}).get(str(a[2]), ())
        return str(a[1]) in m.types

    def _explore(self, roots: list[Atom]) -> None:
        """The derivations of the roots, and of their premises, down to the inputs."""
        options, users, rules = self.options, self.users, self.rules
        disabled = self.m.disabled
        todo = list(roots)
        while todo:
            a = todo.pop()
            if a in options:
                continue
            found: list[_Option] = []
            options[a] = found
            if a[0] == "e":
                continue  # an element's existence: claimed to need nothing
            if a in self.free:
                found.append((0, ()))
                continue
            fact = self.inputs.get(a)
            if fact is not None:
                found.append((self._bit(fact), ()))
            if a in rules.tbox:
                found.append((self._own(rules.tbox[a]), ()))
            for premises, tag, _ in derivations(self.m, rules, self.witness_of, a):
                if tag in disabled or not all(self._present(p) for p in premises):
                    continue
                found.append((self._own(tag), tuple(premises)))
                for p in premises:
                    users.setdefault(p, []).append(a)
                    if p not in options:
                        todo.append(p)

    def _solve(self) -> bool:
        """The greatest solution of the needs (see the module's docstring);
        False when an atom has no grounded derivation."""
        need, options, users = self.need, self.options, self.users
        for a in options:
            need[a] = 0 if a[0] == "e" else _TOP
        # Premises were found after the atoms they derive: the reverse
        # order meets most of them first.
        order = [a for a in reversed(options) if a[0] != "e"]
        queued = set(order)
        work = deque(order)
        while work:
            a = work.popleft()
            queued.discard(a)
            value = _TOP
            for own, premises in options[a]:
                part = own
                for p in premises:
                    part |= need[p]
                value &= part
                if not value:
                    break
            if value != need[a]:
                need[a] = value
                for u in users.get(a, ()):
                    if u not in queued:
                        queued.add(u)
                        work.append(u)
        return all(v != _TOP for v in need.values())
