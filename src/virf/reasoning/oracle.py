"""Questions an explanation's deletion search asks, answered over the
derivation graph of one proof's model (see :mod:`virf.reasoning.necessity`):
is the finding still entailed once some facts and axioms are left out?
"""

from __future__ import annotations

import time
from collections.abc import Collection, Mapping

from virf.deadlines import DeadlineExceeded, current_deadline
from virf.reasoning.derive import Atom
from virf.schema import Fact


class Oracle:
    """Answers the deletion search's questions about the facts and axioms
    of one proof's model, each with some left out: True (still entailed:
    the query's node is still derived), False (a needed item is out), None
    (ask the engine)."""

    def __init__(
        self,
        every: Mapping[Atom, list[tuple[int, int, tuple[Atom, ...]]]],
        root: Atom,
        rank: Mapping[object, int],
        needed: int,
        without: frozenset[str],
        weak: Collection[Atom],
    ) -> None:
        """``every`` atom's derivations (own item, items it rests on,
        premises), the query's node, the items' ranks (their bits), those
        needed, the axioms the proof's model left out, and the query's
        nodes its positive skeleton reads as Thing (see
        :mod:`virf.reasoning.necessity`)."""
        self.rank = rank
        self.needed = needed
        self.without = without
        # The graph as arrays: a derivation's head, the items it rests on,
        # its premises by number; the derivations each atom is a premise of.
        number = {a: i for i, a in enumerate(every)}
        self.root = number[root]
        heads: list[int] = []
        self.heads = heads
        self.rests: list[int] = []
        self.counts: list[int] = []
        uses: list[list[int]] = [[] for _ in every]
        self.uses = uses
        self.starts: list[int] = []
        self.premises: list[set[int]] = []
        for a, options in every.items():
            h = number[a]
            for _, rests, premises in options:
                k = len(heads)
                heads.append(h)
                self.rests.append(rests)
                if not premises:
                    self.premises.append(set())
                    self.counts.append(0)
                    self.starts.append(k)
                    continue
                # (Sets built directly: this loop runs for every derivation
                # of every explanation.)  A premise outside the graph leaves
                # the derivation unusable (-1).
                try:
                    known = {number[p] for p in premises}
                    count = len(known)
                except KeyError:
                    known = {number[p] for p in premises if p in number}
                    count = -1
                self.premises.append(known)
                self.counts.append(count)
                for p in known:
                    uses[p].append(k)
        self.size = len(every)
        # Items no derivation rests on change nothing: answers are kept by
        # the removed items that matter.
        self.relevant = 0
        for rests in self.rests:
            self.relevant |= rests
        self._memo: dict[int, bool | None] = {}
        self.weak = [number[a] for a in weak if a in number]
        # The engine call's deadline holds for the questions it answers later.
        self.deadline = current_deadline()

    def mask(self, facts: Collection[Fact], axioms: Collection[str]) -> int | None:
        """The items as bits (None: one the graph cannot leave out)."""
        removed = 0
        for item in (*facts, *axioms):
            if item in self.without:
                continue  # out already
            r = self.rank.get(item)
            if r is None:
                return None
            removed |= 1 << r
        return removed

    def decide(self, removed: int) -> bool | None:
        """Is the finding entailed by the proof's facts and axioms without
        the ``removed`` ones (a :meth:`mask`)?"""
        if self.deadline is not None and time.monotonic() > self.deadline:
            raise DeadlineExceeded("the deadline passed while an explanation was read off a proof")
        if removed & self.needed:
            return False
        key = removed & self.relevant
        if key in self._memo:
            return self._memo[key]
        answer: bool | None = True
        if not self._derived(key):
            # Not even the positive skeleton is derived: the least model of
            # what is left (a model of the knowledge base, the proof's model
            # having no clash and no axiom left to check) lacks it, so the
            # finding is not entailed.  Otherwise a negation or a universal
            # decides, which the graph does not: ask the engine.
            answer = False if not self._derived(key, self.weak) else None
        self._memo[key] = answer
        return answer

    def support(self) -> int | None:
        """The items (as bits) of one derivation of the root, its premises'
        derivations included: items that suffice for the finding (None:
        the graph does not derive the root)."""
        via = self._derive(0)
        if via is None:
            return None
        bits, seen, walk = 0, {self.root}, [self.root]
        while walk:
            k = via[walk.pop()]
            if k >= 0:
                bits |= self.rests[k]
                for p in self.premises[k]:
                    if p not in seen:
                        seen.add(p)
                        walk.append(p)
        return bits

    def _derived(self, removed: int, free: Collection[int] = ()) -> bool:
        """Is the root derived by derivations resting on no removed item
        (the atoms ``free`` given)?"""
        return self._derive(removed, free) is not None

    def _derive(self, removed: int, free: Collection[int] = ()) -> dict[int, int] | None:
        """The derivation that first derived each atom on the way to the
        root, resting on no removed item (-1: an atom ``free``), or None
        when the root is not derived."""
        counts = list(self.counts)
        rests, heads, uses = self.rests, self.heads, self.uses
        via: dict[int, int] = {}
        todo = [k for k in self.starts if not rests[k] & removed]
        for h in free:
            via[h] = -1
            for k in uses[h]:
                counts[k] -= 1
                if counts[k] == 0 and not rests[k] & removed:
                    todo.append(k)
        if self.root in via:
            return via
        while todo:
            k = todo.pop()
            h = heads[k]
            if h in via:
                continue
            via[h] = k
            if h == self.root:
                return via
            for k in uses[h]:
                counts[k] -= 1
                if counts[k] == 0 and not rests[k] & removed:
                    todo.append(k)
        return None
