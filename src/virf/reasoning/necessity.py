"""What a finding needs, and what it can do without, read off one least
model: the answers to an explanation's deletion search, found from the
derivations instead of a model per question.

The search asks, for facts and axioms left out, whether the finding is still
entailed.  Here the model a proof was read from answers most of those
questions (:class:`Oracle`); the rest go to the engine as before.

**Atoms.**  Every atom of the least model has its derivations: the rules that
conclude it from atoms of the model (:func:`virf.reasoning.derive.derivations`),
and its being an input fact or a fact of the TBox.  The query is read into
the same graph: a node per sub-expression and individual where it holds,
with one derivation per way it holds (a disjunct, a successor).

**Needed.**  What an atom *needs* is the greatest solution of

    need(a) = ⋂ over derivations d of a: own(d) ∪ ⋃ over premises p of d: need(p)

(own: the input fact, or the axiom whose rule d applies).  That is exactly
the set of items without which the least model lacks ``a``: an atom derived
without item x is derived from atoms derived without x, so by induction x is
in no such solution's need of it; and the items every derivation needs are a
solution.  It is found by iterating down from "every item".  An atom left
at "every item" has no derivation grounded in the inputs: the enumeration
missed a rule, and nothing is claimed at all.

The query is read through its positive skeleton: each negation, universal,
number restriction or sink counts as Thing.  The skeleton is implied by the
query, and with no axioms left to check (:func:`~virf.reasoning.evaluate.checks`)
the least model without x is a model of the knowledge base (consistent: the
one with x is).  So an x in the skeleton's need is one without which the
finding is false in a model, hence not entailed.  A negation ``not N`` (at
the individual, or in ``r some (... and not N)``) is also read from a second
model: N, or one of its disjuncts, asserted where the conjunct would hold,
grown past the first clash (``Model.run(through=True)``).  An item every
clash needs is one without which the assertions are consistent: the least
model of the rest with them is a model where the conjunct, hence the
query, fails.

**Still entailed.**  Over the same graph, a set of items left out leaves the
finding entailed when the query's node is still derived: each derivation is
a rule application of the model, and the engine's certain reading (a
negation holds where asserting it derives a clash) is sound.  For this every
derivation carries every item it rests on (the role hierarchy, chains, the
TBox's facts), and an element exists through the facts that name it.  A
negation ``not N`` the query reads at an element is derived there by the
clashes that N (each of its disjuncts) asserted at that element alone
derives, each clash with its own derivations (:meth:`_Needs.negations`).

**No longer entailed.**  The needs answer for one item at a time; the
deletion search leaves out several (those it dropped already, and the one it
tries).  The same argument answers those: every atom of the least model of
what is left has a derivation in the graph that rests on nothing left out
(the rules are monotone), and that model is a model of the knowledge base.
So when the query's positive skeleton is not derived without the items left
out, with every negation, universal and number restriction counting as
Thing, the finding is false in that model, hence not entailed
(:meth:`Oracle.decide`).  Where the skeleton is derived but the query is
not, a negation decides, and the question goes to the engine.

Under-claiming is always safe: a question the graph cannot answer goes to
the engine.  So whatever this reading cannot vouch for counts as needing
nothing, and as not derived: an element's existence (for the needs), the
role hierarchy and chains (for the needs), a universal or number
restriction, a negation at a witness or of a class whose assertion the
reading cannot enumerate (for what remains entailed).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Collection, Mapping, Sequence
from contextlib import suppress

from virf.ontology.fragment import Expr, Fragment, Role
from virf.ontology.iri import NOTHING, THING
from virf.reasoning import Proof
from virf.reasoning.chase import ChaseLimit, Model
from virf.reasoning.derive import Atom, derivations, edge, naming, rules_of
from virf.reasoning.oracle import Oracle
from virf.schema import Fact

# The need of an atom not yet bounded: every item (an infinite bit set).
_TOP = -1
# One derivation: the item it needs of its own (an axiom the search can
# leave out, or an input fact), every item it rests on, and its premises.
_Option = tuple[int, int, tuple[Atom, ...]]
# Query nodes that count as Thing for the needs.
_WEAK = ("not", "all", "max", "min", "sink")


def needed(
    m: Model,
    frag: Fragment,
    defs: Mapping[str, Expr],
    inputs: Mapping[Atom, Fact],
    rank: Mapping[object, int],
    concept: str,
    x: str,
    without: frozenset[str] = frozenset(),
    wanted: int = _TOP,
) -> tuple[int, Oracle | None]:
    """The ranks (as bits) of the ranked items without which ``concept(x)``
    is not entailed, given that it is entailed by the facts and rules of
    ``m`` (its least model, grown, with the axioms ``without`` left out),
    and an oracle for the questions about what is left out.  Refutations
    are tried for claims only while some of ``wanted`` (a proof's items)
    are not found, and for the oracle where they derive a negation."""
    if m.prog.checks or m.clash is not None:
        return 0, None
    needs = _Needs(m, frag, defs, inputs, rank)
    needs._add(("e", x), 0, 0, ())  # the engine adds the individual asked about
    root = needs.node(("C", concept), x)
    if root is None or not needs.settle([root]):
        return 0, None
    found = max(needs.need[root], 0)
    for part in _conjuncts(("C", concept), defs):
        with suppress(ChaseLimit):  # too many witnesses: claim nothing more
            found |= needs.refuted(part, x, bool(wanted & ~found))
    with suppress(ChaseLimit):
        needs.negations(x)
    weak = [a for a in needs.options if a[0] == "q" and _weak(a)]
    every = {**needs.options, **needs.extra}
    return found, Oracle(every, root, rank, found, without, weak)


def _weak(a: Atom) -> bool:
    """Is the query node ``a`` Thing in the positive skeleton?"""
    e = a[1]
    return isinstance(e, tuple) and e[0] in _WEAK and e[:2] != ("min", 1)


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
    """The derivations of one state of a model, and their needs (see the
    module's docstring)."""

    def __init__(
        self,
        m: Model,
        frag: Fragment,
        defs: Mapping[str, Expr],
        inputs: Mapping[Atom, Fact],
        rank: Mapping[object, int],
        free: frozenset[Atom] = frozenset(),
        elements: dict[str, list[Fact]] | None = None,
    ) -> None:
        self.m, self.frag, self.defs = m, frag, defs
        self.inputs, self.rank, self.free = inputs, rank, free
        self.elements = naming(inputs) if elements is None else elements
        self.rules = rules_of(m.prog)
        self.structural = m.prog.structural
        self.witness_of = {y: key for key, y in m.witness.items()}
        self.options: dict[Atom, list[_Option]] = {}
        # Derivations of other models' atoms (refutations), for the oracle only.
        self.extra: dict[Atom, list[_Option]] = {}
        self.users: dict[Atom, list[Atom]] = {}
        self.need: dict[Atom, int] = {}
        self.pending: list[Atom] = []  # premises still to explore
        self._nodes: dict[tuple[Expr, str], Atom | None] = {}
        self._paths_from: dict[tuple[str, bool, str], dict[str, Atom]] = {}

    def _bit(self, item: object) -> int:
        r = self.rank.get(item)
        return 0 if r is None else 1 << r

    def _own(self, tag: str | None) -> int:
        return 0 if tag is None or tag in self.structural else self._bit(tag)

    def _bits(self, tags: Collection[str]) -> int:
        out = 0
        for tag in tags:
            out |= self._bit(tag)
        return out

    def _add(self, a: Atom, own: int, rests: int, premises: tuple[Atom, ...]) -> None:
        self.options.setdefault(a, []).append((own, rests, premises))
        for p in premises:
            self.users.setdefault(p, []).append(a)
            if p not in self.options:
                self.pending.append(p)

    def settle(self, roots: list[Atom]) -> bool:
        self._explore(roots + self.pending)
        self.pending = []
        return self._solve()

    # ------------------------------------------------------------------ the query
    def node(self, e: Expr, y: str) -> Atom | None:
        """The atom or query node of ``e`` at ``y`` (None: its positive
        skeleton is false in the model), with its derivations."""
        key = (e, y)
        if key in self._nodes:
            return self._nodes[key]
        self._nodes[key] = None  # a definition cannot reach itself; guard anyway
        m, tag = self.m, e[0]
        here: Atom = ("q", e, y)
        found: Atom | None = here
        if tag == "C":
            name = e[1]
            if name in self.defs:
                inner = self.node(self.defs[name], y)
                found = None if inner is None else here
                if inner is not None:
                    own = self._own(self.frag.query_axiom[name].id)
                    self._add(here, own, own, (inner,))
            elif name in self.frag.sinks:
                found = ("q", ("sink", name), y)
                self.options.setdefault(found, [])
            else:
                found = ("t", y, name) if name in m.types.get(y, ()) else None
        elif tag == "and":
            parts = [self.node(c, y) for c in e[1]]
            if any(p is None for p in parts):
                found = None
            else:
                self._add(here, 0, 0, tuple(p for p in parts if p is not None))
        elif tag == "or":
            held = [p for p in (self.node(c, y) for c in e[1]) if p is not None]
            found = here if held else None
            for p in held:
                self._add(here, 0, 0, (p,))
        elif tag == "some" or (tag == "min" and e[1] == 1):
            role, filler = (e[1], e[2]) if tag == "some" else (e[2], e[3])
            ends = self._ends(role, y)
            found = None
            for z in sorted(ends):
                part = self.node(filler, z)
                if part is not None:
                    found = here
                    self._add(here, 0, 0, (ends[z], part))
        elif tag == "value":
            found = self._ends(e[1], y).get(e[2])
        elif tag == "dvalue":
            present = e[2] in m.data.get(y, {}).get(e[1], ())
            found = ("d", y, e[1], e[2]) if present else None
        elif tag == "oneof":
            found = here if y in e[1] else None
            if found is not None:
                self._add(here, 0, 0, ())
        else:  # not, all, max, min > 1: Thing in the skeleton
            self.options.setdefault(here, [])
        self._nodes[key] = found
        return found

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
        m = self.m
        spec = m.lazy[p]
        base = (m.pred if backward else m.succ).get(p, {})
        before = spec.right if backward else spec.left
        after = spec.left if backward else spec.right
        rests = self._bits(self.rules.lazy.get(p, m.prog.structural))

        def node(n: str, state: int) -> Atom:
            return ("p", p, backward, start, n, state)

        def steps(roles: tuple[Role, ...], n: str) -> list[tuple[str, Atom]]:
            out = []
            for s in roles:
                r = (s[0], s[1] != backward)
                out += [(z, edge(r, n, z)) for z in sorted(m._stored(r, n))]
            return out

        self._add(node(start, 0), 0, 0, ())
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
                self._add(node(z, nxt), 0, rests, (here, a))
                if (z, nxt) not in seen:
                    seen.add((z, nxt))
                    todo.append((z, nxt))
        found = {n: node(n, 1) for n, state in sorted(seen) if state == 1}
        self._paths_from[key] = found
        return found

    # ------------------------------------------------------------------ negation
    def refuted(self, part: Expr, x: str, claims: bool) -> int:
        """What a negation in the conjunct ``part`` of the query at ``x``
        needs (``not N``, or ``r some (... and not N)``; only when
        ``claims``), and its refutation as derivations for the oracle.

        A class that falsifies ``not N`` (N, or one of its disjuncts) is
        asserted where the conjunct would otherwise hold (at ``x``, or at
        each r-successor where the rest of the filler holds), and the model
        grown past its first clash.  An item every clash needs is one
        without which the assertions are consistent: the least model of the
        rest with them is a model where the conjunct, hence the query, is
        false (when no new successor satisfies the rest of the filler
        there).  At a single target, the clashes also derive the negation."""
        role: Role | None = None
        filler: Expr | None = None
        if part[0] == "not":
            negated, targets = [part[1]], [x]
        elif part[0] == "some" or (part[0] == "min" and part[1] == 1):
            role, filler = (part[1], part[2]) if part[0] == "some" else (part[2], part[3])
            negated = [c[1] for c in _conjuncts(filler, self.defs) if c[0] == "not"]
            targets = [z for z in sorted(self._ends(role, x)) if self._holds(filler, z)]
            if not targets or any(z in self.witness_of for z in targets):
                return 0
        else:
            return 0
        found = 0
        for e in negated:
            names, complete, rests = self._falsifiers(e)
            derives = (
                complete and len(targets) == 1 and ("q", ("not", e), targets[0]) in self.options
            )
            if not (claims or derives):
                continue
            clashes: list[Atom] = []
            for name in names:
                kill, clash = self._trial(name, targets, role, filler, x)
                found |= kill
                if clash is not None:
                    clashes.append(clash)
            if derives and len(clashes) == len(names):
                self._add(("q", ("not", e), targets[0]), 0, rests, tuple(clashes))
        return found

    def negations(self, x: str) -> None:
        """Derivations, for the oracle, of the negations ``not N`` the query
        reads at one element each and no refutation derived (inside a
        filler, or a class it names): N, or each of its disjuncts, asserted
        at that element alone derives a clash.  Without them the oracle
        could not tell whether the finding holds once a fact the graph's
        first derivation used is left out (an appliance enclosing two
        non-food objects), and the engine was asked, one model a fact."""
        open_: list[tuple[Atom, Expr, str]] = []
        for a, options in self.options.items():
            e = a[1]
            if a[0] == "q" and isinstance(e, tuple) and e[0] == "not" and not options:
                open_.append((a, e[1], str(a[2])))
        for a, e, z in open_:
            if z in self.witness_of:
                continue  # as in refuted: a witness is no target
            names, complete, rests = self._falsifiers(e)
            if not complete or not names:
                continue
            clashes: list[Atom] = []
            for name in names:
                clash = self._trial(name, [z], None, None, x)[1]
                if clash is None:
                    break
                clashes.append(clash)
            else:
                self._add(a, 0, rests, tuple(clashes))

    def _holds(self, e: Expr, y: str) -> bool:
        """Is the positive skeleton of ``e`` true at ``y``?"""
        return self.node(e, y) is not None

    def _falsifiers(self, e: Expr) -> tuple[list[str], bool, int]:
        """Named classes whose assertion at an element makes ``e`` true
        there, whether ``not e`` holds exactly where each of them clashes
        (the engine's certain reading), and the definitions that reading
        rests on (as bits)."""
        if e[0] == "C":
            if e[1] in self.defs:
                names, complete, rests = self._falsifiers(self.defs[e[1]])
                ident = self.frag.query_axiom[e[1]].id
                return names, complete, rests | self._bits(() if ident is None else (ident,))
            if e[1] in (THING, NOTHING) or e[1] in self.frag.sinks:
                return [], False, 0
            return [e[1]], True, 0
        if e[0] == "or":
            names = []
            complete, rests = True, 0
            for c in e[1]:
                more, whole, bits = self._falsifiers(c)
                names += more
                complete, rests = complete and whole, rests | bits
            return names, complete, rests
        return [], False, 0

    def _trial(
        self, name: str, targets: list[str], role: Role | None, filler: Expr | None, x: str
    ) -> tuple[int, Atom | None]:
        """What every clash needs once ``name`` is asserted at the targets
        (see :meth:`refuted`), and a node any of the clashes derives."""
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
                return 0, None
            grown = _Needs(m, self.frag, self.defs, self.inputs, self.rank, asserted, self.elements)
            roots: list[Atom] = [("t", w, NOTHING) for w in clashes]
            if not grown.settle(roots):
                return 0, None
            # The trial's atoms, kept apart from this model's.
            space = ("E", name, tuple(targets))
            for a, options in grown.options.items():
                self.extra[(*space, a)] = [
                    (own, rests, tuple((*space, p) for p in premises))
                    for own, rests, premises in options
                ]
            clash: Atom = ("X", name, tuple(targets))
            self.extra[clash] = [(0, 0, ((*space, a),)) for a in roots]
            if role is not None and filler is not None:
                ends = grown._ends(role, x)
                if any(z not in targets and grown._holds(filler, z) for z in ends):
                    return 0, clash  # a successor the assertions made: no claim
            found = _TOP
            for a in roots:
                found &= grown.need[a]
            return max(found, 0), clash
        finally:
            m.rollback(token)

    # ------------------------------------------------------------------ atoms
    def _explore(self, roots: list[Atom]) -> None:
        """The derivations of the roots, and of their premises, down to the inputs."""
        options, rules = self.options, self.rules
        disabled = self.m.disabled
        todo = list(roots)
        while todo:
            a = todo.pop()
            if a in options:
                continue
            options[a] = []
            if a in self.free:
                self._add(a, 0, 0, ())
                continue
            if a[0] == "e":
                self._element(a)
                continue
            fact = self.inputs.get(a)
            if fact is not None:
                bit = self._bit(fact)
                self._add(a, bit, bit, ())
            if a in rules.tbox:
                tag = rules.tbox[a]
                self._add(a, self._own(tag), self._bits(() if tag is None else (tag,)), ())
            for premises, tag, structure in derivations(self.m, rules, self.witness_of, a):
                if tag in disabled:
                    continue
                rests = self._bits(structure) | (0 if tag is None else self._bit(tag))
                self._add(a, self._own(tag), rests, tuple(premises))
            todo += self.pending
            self.pending = []

    def _element(self, a: Atom) -> None:
        """How an element comes to be: a fact that names it, the TBox, or
        the rule that made it a witness (its needs count as none)."""
        x = str(a[1])
        for f in self.elements.get(x, ()):
            self._add(a, 0, self._bit(f), ())
        if a in self.rules.tbox:
            tag = self.rules.tbox[a]
            self._add(a, 0, self._bits(() if tag is None else (tag,)), ())
        if x in self.witness_of:
            z, r, _ = self.witness_of[x]
            self._add(a, 0, 0, (edge(r, z, x),))

    def _solve(self) -> bool:
        """The greatest solution of the needs (see the module's docstring);
        False when an atom has no grounded derivation."""
        need, options, users = self.need, self.options, self.users
        fixed = {a for a in options if a[0] == "e" or (a[0] == "q" and _weak(a))}
        for a in options:
            need[a] = 0 if a in fixed else _TOP
        # Premises were found after the atoms they derive: the reverse
        # order meets most of them first.
        order = [a for a in reversed(options) if a not in fixed]
        queued = set(order)
        work = deque(order)
        while work:
            a = work.popleft()
            queued.discard(a)
            value = _TOP
            for own, _, premises in options[a]:
                part = own
                for p in premises:
                    part |= need[p]
                value &= part
                if not value:
                    break
            if value != need[a]:
                need[a] = value
                for u in users.get(a, ()):
                    if u not in queued and u not in fixed:
                        queued.add(u)
                        work.append(u)
        return all(v != _TOP for v in need.values())


def _items(order: Sequence[object], bits: int) -> list[object]:
    """The items of ``order`` whose ranks are the bits set, in order (one
    step per bit set: the ranks run through every background axiom)."""
    out = []
    while bits:
        low = bits & -bits
        out.append(order[low.bit_length() - 1])
        bits ^= low
    return out


def proof_bits(found: Proof, rank: Mapping[object, int]) -> int:
    """The ranks (as bits) of a proof's items: :func:`needed` tries
    refutations for claims only while some of them are not claimed."""
    used = {r for i in (*found.facts, *found.axioms) if (r := rank.get(i)) is not None}
    return sum(1 << r for r in used)


def with_needs(
    found: Proof | None, known: tuple[int, Oracle | None], order: Sequence[object]
) -> Proof | None:
    """``found`` (a proof read off a model by the backward search,
    :class:`virf.reasoning.proof.Prover`) with what :func:`needed` gave for
    that model (``known``: the items every derivation needs, as ranks in
    ``order``, and the oracle).  Without ``found``, the proof is the first
    derivation the graph finds, when it derives the finding (None
    otherwise): the deletion search asks the oracle first, so the backward
    search for the derivation it would rather keep can be spared."""
    bits, oracle = known
    if found is None:
        support = None if oracle is None else oracle.support()
        if support is None:
            return None
        items = _items(order, support)
        found = Proof(
            frozenset(f for f in items if isinstance(f, Fact)),
            frozenset(a for a in items if isinstance(a, str)),
        )
    claimed = _items(order, bits)
    return Proof(
        found.facts,
        found.axioms,
        frozenset(f for f in claimed if isinstance(f, Fact)),
        frozenset(a for a in claimed if isinstance(a, str)),
        oracle,
    )
