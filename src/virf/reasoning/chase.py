"""The model the compiled rules build: a finite interpretation grown by
forward chaining (a restricted chase: every ``A ⊑ ∃r.M`` gives each A its
own witness), with a journal that rolls it back.

What the rules derive, including a clash, is entailed (see
:mod:`virf.reasoning.program`), so the model is a lower bound.  Changes can
be recorded and undone: a question grows the model, is answered, and rolls
it back, which costs what the question added.

A transitive role that no rule reads (VIRF's ``encloses``: transitive, and
extended by ``encloses o supports``, but asked about only by the queries) is
not materialised: its closure over a chain of n objects has n²/2 edges, and
deriving them one rule firing at a time costs n³.  The model keeps the edges
the other rules give it and answers a question about the role with a search
over them (:meth:`Model.reach`), which is the same relation.
"""

from __future__ import annotations

import time
from collections import defaultdict, deque
from collections.abc import Iterable
from itertools import count
from typing import TYPE_CHECKING, Any

from virf.ontology.fragment import Role
from virf.ontology.iri import NOTHING, THING
from virf.reasoning import DeadlineExceeded, current_deadline

if TYPE_CHECKING:
    # Only for annotations: the program builds its models from this module.
    from virf.reasoning.program import Program


def nominal(individual: str) -> str:
    """The class {individual}; the braces keep it apart from every OWL name."""
    return "{" + individual + "}"


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
        # A class has an entry only while it has members (rollback deletes
        # the emptied ones): the classes with a member are the keys.
        self.members: dict[str, set[str]] = {}
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
        xs = self.members.get(a)
        if xs is None:
            self.members[a] = {x}
        else:
            xs.add(x)
        self.version = next(_STATES)
        entry = ("t", x, a)  # one tuple for the journal and the queue
        if self.journal is not None:
            self.journal.append(entry)
        self.queue.append(entry)

    def role(self, r: Role, x: str, y: str) -> None:
        p, inv = r
        if inv:
            x, y = y, x
        # Most calls re-derive an edge already held (both ends are elements
        # then): answered first, by one lookup.
        inner = self.succ[p]
        ys = inner.get(x)
        if ys is not None and y in ys:
            return
        if x not in self.types:
            self.element(x)
        if y not in self.types:
            self.element(y)
        if ys is None:
            ys = inner[x]
        ys.add(y)
        self.pred[p][y].add(x)
        self.version = next(_STATES)
        entry = ("r", p, x, y)  # one tuple for the journal and the queue
        if self.journal is not None:
            self.journal.append(entry)
        self.queue.append(entry)

    def datum(self, x: str, d: str, v: bool) -> None:
        if x not in self.types:
            self.element(x)
        vs = self.data[x][d]
        if v in vs:
            return
        vs.add(v)
        self.version = next(_STATES)
        entry = ("d", x, d, v)  # one tuple for the journal and the queue
        if self.journal is not None:
            self.journal.append(entry)
        self.queue.append(entry)

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

    def run(self, *, through: bool = False) -> None:
        """Apply the rules to everything queued, until nothing new follows
        (or a clash: ``through`` goes on past it, so the model holds every
        way the rules reach a clash, see :mod:`virf.reasoning.necessity`).

        Raises :class:`DeadlineExceeded` when the deadline of the engine call
        passes; the model is then unfinished and must be dropped (or rolled
        back)."""
        ctrig = self.prog.ctrig
        rtrig = self.prog.rtrig
        off = self.disabled
        q = self.queue
        types = self.types
        succ, pred = self.succ, self.pred
        stored = self._stored
        deadline = current_deadline()
        while q:
            if deadline is not None and time.monotonic() > deadline:
                raise DeadlineExceeded(
                    "the deadline passed while the fast engine applied its rules"
                )
            for _ in range(min(len(q), _BATCH)):
                if self.clash is not None and not through:
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
                        if head not in ts and tag not in off and ts.issuperset(body):
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
                        # Half the super-role edges are held already (both
                        # directions of a symmetric role): skip the call.
                        held = succ.get(s[0])
                        if held is not None:
                            ys = held.get(y if s[1] else x)
                            if ys is not None and (x if s[1] else y) in ys:
                                continue
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
                        # The stored edges read and the edges derived are
                        # looked up here, not through _stored and role: the
                        # chains (isInside o isNear) re-derive most edges.
                        for r2, r3 in chain1:
                            inner = (pred if r2[1] else succ).get(r2[0])
                            ends = inner.get(b) if inner is not None else None
                            if ends:
                                held = succ.get(r3[0])
                                for c in list(ends):
                                    if held is not None:
                                        hs = held.get(c if r3[1] else a)
                                        if hs is not None and (a if r3[1] else c) in hs:
                                            continue
                                    self.role(r3, a, c)
                        for r1, r3 in chain2:
                            inner = (succ if r1[1] else pred).get(r1[0])
                            starts = inner.get(a) if inner is not None else None
                            if starts:
                                held = succ.get(r3[0])
                                for w in list(starts):
                                    if held is not None:
                                        hs = held.get(b if r3[1] else w)
                                        if hs is not None and (w if r3[1] else b) in hs:
                                            continue
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
        # and roll back does not keep every name it has seen.  The two
        # commonest entries are undone inline: an explanation rolls back
        # hundreds of thousands of them.
        journal, types, members, succ, pred = (
            self.journal,
            self.types,
            self.members,
            self.succ,
            self.pred,
        )
        undone = journal[mark:]
        del journal[mark:]
        for entry in reversed(undone):
            tag = entry[0]
            if tag == "r":
                _, p, x, y = entry
                ys = succ[p].get(x)
                if ys is not None:
                    ys.discard(y)
                    if not ys:
                        del succ[p][x]
                xs = pred[p].get(y)
                if xs is not None:
                    xs.discard(x)
                    if not xs:
                        del pred[p][y]
            elif tag == "t":
                _, x, a = entry
                types[x].discard(a)
                xs = members.get(a)
                if xs is not None:
                    xs.discard(x)
                    if not xs:
                        del members[a]
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
        """The first closure, in order, with a successor outside it (sorted
        only when there is one: every step's model is checked)."""
        found: tuple[tuple[str, str], set[str]] | None = None
        for key, bound in self.closures.items():
            extra = self.rsucc((key[1], False), key[0]) - bound
            if extra and (found is None or key < found[0]):
                found = (key, extra)
        if found is None:
            return None
        (x, p), extra = found
        return f"{x} {p} {min(extra)} is outside its closure"


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
