"""A query read over one model of the fast engine: classical truth (the
upper bound, once the model is checked), certain truth (the lower bound),
and the search for assertions that would make a query false.

Certain truth is sound: negation holds only where adding the negated fact
derives a clash, ``only`` and ``max 0`` only through closure facts.  A query
whose reading the bounds cannot settle raises :class:`Fallback`, and the
engine asks the reference reasoner (see :mod:`virf.reasoning.fast`).
"""

from __future__ import annotations

from collections.abc import Callable
from collections.abc import Set as AbstractSet
from typing import Any

from virf.ontology.fragment import Axiom, Expr, Role
from virf.ontology.iri import NOTHING, THING
from virf.reasoning.chase import Model
from virf.reasoning.prior import Prior, Reads, Values

_NONE: frozenset[str] = frozenset()
_UNREAD = object()


class Fallback(Exception):
    """The bounds did not meet: ask the reference engine."""


def checks(m: Model) -> list[Axiom]:
    """The axioms the rules do not capture, to check a candidate model
    against (those switched off in ``m`` left out)."""
    return [a for a in m.prog.checks if a.id is None or a.id not in m.disabled]


class Evaluator:
    """Query evaluation over one model: classical truth, certain truth, and
    the search for a falsifying extension."""

    def __init__(
        self,
        model: Model,
        defs: dict[str, Expr],
        sinks: frozenset[str],
        prior: Prior | None = None,
        reads: tuple[Reads, AbstractSet[str]] | None = None,
    ) -> None:
        """With ``prior`` (the previous step's answers), the classical truth
        at an individual the change cannot reach is taken from it; either
        way, the answers read while the model is as given are kept in
        :attr:`values`, for the next step.  Likewise ``reads``: the previous
        step's candidates of the definitions, and the definitions whose
        candidates the change may touch (see :meth:`reads`)."""
        self.m = model
        self.defs = defs
        self.sinks = sinks
        self.prior = prior
        self._reads = reads
        self._at = model.version
        self.values: Values = {}
        self._version = model.version
        self._classical: dict[tuple[Expr, str], bool] = {}
        self._cert: dict[tuple[Expr, str], bool] = {}
        self._cert_not: dict[tuple[Expr, str], bool] = {}
        self._candidates: dict[str, AbstractSet[str] | None] = {}
        self._lazy: dict[tuple[Role, Expr, str], set[str]] = {}
        self._kept: tuple[Any, ...] | None = None  # the caches of the model as given

    def _fresh(self) -> None:
        """Caches hold for one state of the model.  Those of the model as
        given are put aside while a question grows it (a negation or a
        refutation asserts something, and rolls it back): every concept read
        them again after each, and the candidates of a step cost more than
        the rest of its classification."""
        version = self.m.version
        if self._version == version:
            return
        if self._version == self._at:
            self._kept = (
                self._classical,
                self._cert,
                self._cert_not,
                self._candidates,
                self._lazy,
            )
        if version == self._at and self._kept is not None:
            (self._classical, self._cert, self._cert_not, self._candidates, self._lazy) = self._kept
            self._kept = None
        else:
            self._classical, self._cert, self._cert_not = {}, {}, {}
            self._candidates, self._lazy = {}, {}
        self._version = version

    # ------------------------------------------------------------------ classical
    def holds(self, e: Expr, x: str) -> bool:
        """Truth of ``e`` at ``x`` in the model, read as a finite interpretation."""
        self._fresh()
        key = (e, x)
        hit = self._classical.get(key)
        if hit is None:
            # Only the model as given is the one the prior's change is from
            # (a refutation grows it, and rolls back after).
            as_given = self.m.version == self._at
            if as_given and self.prior is not None:
                hit = self.prior.holds(self.m, e, x)
            if hit is None:
                hit = self._holds(e, x)
            self._classical[key] = hit
            if as_given:
                self.values[key] = hit
        return hit

    def _holds(self, e: Expr, x: str) -> bool:
        m, tag = self.m, e[0]
        if tag == "C":
            name = e[1]
            if name in self.defs:
                return self.holds(self.defs[name], x)
            if name in self.sinks:
                return True
            return name in m.types[x]
        if tag == "and":
            return all(self.holds(c, x) for c in e[1])
        if tag == "or":
            return any(self.holds(c, x) for c in e[1])
        if tag == "not":
            return not self.holds(e[1], x)
        if tag == "some":
            if e[1][0] in m.lazy:
                return x in self._lazy_some(e[1], e[2], self.holds)
            return any(self.holds(e[2], y) for y in m.rsucc(e[1], x))
        if tag == "all":
            return all(self.holds(e[2], y) for y in m.rsucc(e[1], x))
        if tag == "value":
            return e[2] in m.rsucc(e[1], x)
        if tag == "min":
            return sum(1 for y in m.rsucc(e[2], x) if self.holds(e[3], y)) >= int(e[1])
        if tag == "max":
            return sum(1 for y in m.rsucc(e[2], x) if self.holds(e[3], y)) <= int(e[1])
        if tag == "oneof":
            return x in e[1]
        if tag == "dvalue":
            # .get: a read must not add entries the journal does not know of.
            return e[2] in m.data.get(x, {}).get(e[1], _NONE)
        raise Fallback(f"cannot evaluate {tag}")

    # ------------------------------------------------------------------ certain
    def certain(self, e: Expr, x: str) -> bool:
        """Sound: True only if ``e(x)`` is entailed (the model is the lower bound)."""
        self._fresh()
        key = (e, x)
        hit = self._cert.get(key)
        if hit is None:
            hit = self._certain(e, x)
            self._cert[key] = hit
        return hit

    def _certain(self, e: Expr, x: str) -> bool:
        m, tag = self.m, e[0]
        if tag == "C":
            name = e[1]
            if name in self.defs:
                return self.certain(self.defs[name], x)
            if name in self.sinks:
                return False
            return name in m.types[x]
        if tag == "and":
            return all(self.certain(c, x) for c in e[1])
        if tag == "or":
            return any(self.certain(c, x) for c in e[1])
        if tag == "not":
            return self.certain_not(e[1], x)
        if tag == "some" or (tag == "min" and e[1] == 1):
            role, filler = (e[1], e[2]) if tag == "some" else (e[2], e[3])
            if role[0] in m.lazy:
                return x in self._lazy_some(role, filler, self.certain)
            return any(self.certain(filler, y) for y in m.rsucc(role, x))
        if tag == "value":
            return e[2] in m.rsucc(e[1], x)
        if tag == "all":
            bound = self.bound(e[1], x)
            return bound is not None and all(self.certain(e[2], s) for s in bound)
        if tag == "max" and e[1] == 0:
            bound = self.bound(e[2], x)
            return bound is not None and all(self.certain_not(e[3], s) for s in bound)
        if tag == "oneof":
            return x in e[1]
        if tag == "dvalue":
            return e[2] in m.data.get(x, {}).get(e[1], _NONE)
        return False

    def _lazy_some(self, role: Role, filler: Expr, test: Callable[[Expr, str], bool]) -> set[str]:
        """Where ``role some filler`` holds (by ``test``) for a lazy role: one
        search back from where the filler holds, not one search forward
        from each individual (a chain of n boxes cost n² steps)."""
        key = (role, filler, test.__name__)
        hit = self._lazy.get(key)
        if hit is None:
            found = self.where(filler) if test == self.holds else None
            if found is None:
                pool = self.candidates(filler)
                where = self.m.types.keys() if pool is None else pool
                found = {y for y in where if y in self.m.types and test(filler, y)}
            hit = self.m.reach_any(role[0], found, not role[1])
            self._lazy[key] = hit
        return hit

    def where(self, e: Expr) -> set[str] | None:
        """Every individual of the model at which ``e`` holds classically,
        read with set operations over the class and role tables (None when
        ``e`` needs counting or a search over a role no table holds).  A
        filler asked about every object of a thousand (what may a running
        heater enclose?) cost one evaluation per object."""
        m, tag = self.m, e[0]
        if tag == "C":
            name = e[1]
            if name in self.defs:
                return self.where(self.defs[name])
            if name in self.sinks:
                return set(m.types)
            return set(m.members.get(name, _NONE))
        if tag in ("and", "or"):
            parts: list[set[str]] = []
            for c in e[1]:
                part = self.where(c)
                if part is None:
                    return None
                parts.append(part)
            if tag == "or":
                return set().union(*parts)
            return parts[0].intersection(*parts[1:]) if parts else set(m.types)
        if tag == "not":
            inner = self.where(e[1])
            return None if inner is None else m.types.keys() - inner
        if tag in ("some", "all", "value"):
            role = e[1]
            back = (role[0], not role[1])
            if role[0] in m.lazy:
                if tag != "some":
                    return None
                return set(self._lazy_some(role, e[2], self.holds))
            if tag == "value":
                return set(m.rsucc(back, e[2])) if e[2] in m.types else set()
            inner = self.where(e[2])
            if inner is None:
                return None
            if tag == "all":  # no successor outside the filler
                inner = m.types.keys() - inner
            found: set[str] = set()
            for y in inner:
                found |= m.rsucc(back, y)
            return found if tag == "some" else m.types.keys() - found
        if tag == "oneof":
            return {x for x in e[1] if x in m.types}
        if tag == "dvalue":
            return {x for x, table in m.data.items() if e[2] in table.get(e[1], _NONE)}
        return None

    def bound(self, r: Role, x: str) -> frozenset[str] | None:
        """Individuals that every r-successor of x must be, from closure facts
        on r or on a super-property of r (None when nothing bounds them)."""
        if r[1]:
            return None
        out: frozenset[str] | None = None
        for q in [(r[0], False), *self.m.prog.supers(r[0])]:
            if q[1]:
                continue
            members = self.m.closures.get((x, q[0]))
            if members is not None:
                out = members if out is None else out & members
        return out

    def candidates(self, e: Expr) -> AbstractSet[str] | None:
        """A superset of the individuals at which ``e`` holds in the model
        (None: possibly any).  Read from the class and role tables, so a
        query is evaluated only where it can hold: checking every query at
        every individual cost more than the rest of a verification."""
        m, tag = self.m, e[0]
        if tag == "C":
            name = e[1]
            if name in self.defs:
                # Definitions share defined classes: each is read once per
                # model, and kept from the previous step where the change
                # touched none of the tables it reads.
                self._fresh()
                hit = self._candidates.get(name, _UNREAD)
                if hit is _UNREAD:
                    reads = self._reads
                    if (
                        reads is not None
                        and name in reads[0]
                        and name not in reads[1]
                        and m.version == self._at
                    ):
                        hit = reads[0][name]
                    else:
                        hit = self.candidates(self.defs[name])
                    self._candidates[name] = hit
                return hit  # type: ignore[return-value]
            if name in self.sinks or name == THING:
                return None
            return m.members.get(name, _NONE)
        if tag == "and":
            # Named conjuncts first, then a role's value, then the rest: an
            # action class absent from the state, or a property no object
            # has, settles the question before a filler is read.
            both: set[str] | None = None
            order = _by_cost(e)
            for c in order:
                part = self.candidates(c)
                if part is None:
                    continue
                both = set(part) if both is None else both & part
                if not both:
                    if not part and c is not order[0]:
                        _read_first(e, c)
                    return both
            return both
        if tag == "or":
            parts = [self.candidates(c) for c in e[1]]
            if any(p is None for p in parts):
                return None
            return set().union(*parts)  # type: ignore[arg-type]
        if tag == "some" or (tag == "min" and int(e[1]) >= 1):
            role, filler = (e[1], e[2]) if tag == "some" else (e[2], e[3])
            ends = self.candidates(filler)
            if role[0] in m.lazy:
                # Where a search back along the role's paths from the filler's
                # candidates leads (without it, every heater was decided).
                return None if ends is None else m.reach_any(role[0], ends, not role[1])
            back = (m.succ if role[1] else m.pred).get(role[0], {})
            if ends is None:
                forth = (m.pred if role[1] else m.succ).get(role[0], {})
                return {x for x, ys in forth.items() if ys}
            out: set[str] = set()
            for y in ends:
                out |= back.get(y, _NONE)
            return out
        if tag == "value":
            role = e[1]
            if role[0] in m.lazy:
                return None
            return set((m.succ if role[1] else m.pred).get(role[0], {}).get(e[2], _NONE))
        if tag == "oneof":
            return set(e[1])
        if tag == "dvalue":
            return {x for x, table in m.data.items() if e[2] in table.get(e[1], _NONE)}
        return None

    def reads(self) -> Reads:
        """The candidates of the definitions read in the model as given,
        frozen (a class's members are a live table of the model)."""
        m = self.m
        if m.version != self._at:
            return {}
        self._fresh()
        return {
            name: read if read is None or isinstance(read, frozenset) else frozenset(read)
            for name, read in self._candidates.items()
        }

    # ------------------------------------------------------------------ decision
    def decide(self, concept: str, x: str) -> bool:
        """Is ``concept(x)`` entailed?  The model must already be verified
        (:func:`checks`): the bounds meet, or :class:`Fallback`."""
        if concept in self.sinks:
            raise Fallback(f"{concept} is a sink class")
        e = self.defs.get(concept)
        if e is None:  # a knowledge-base class: the verified least model decides
            return concept in self.m.types[x]
        if not self.holds(e, x):
            return False
        if self.certain(e, x):
            return True
        if self._refuted(e, x):
            return False
        raise Fallback(f"{concept}({x}) is neither proved nor refuted")

    def _refuted(self, e: Expr, x: str) -> bool:
        """A model of the axioms where ``e(x)`` is false, grown from this one
        by a few falsifying assertions (rolled back after)."""
        m = self.m
        token = m.begin()
        try:
            for _ in range(4):
                ops = self.falsifiers(e, x)
                if not ops:
                    return False
                self.apply(ops)
                if m.clash is not None:
                    return False
                if not self.holds(e, x):
                    return self.violations(checks(m)) is None
            return False
        finally:
            m.rollback(token)

    def certain_not(self, e: Expr, x: str) -> bool:
        """Sound: True only if ``not e(x)`` is entailed, i.e. asserting ``e(x)``
        makes the rules derive a clash."""
        self._fresh()
        key = (e, x)
        hit = self._cert_not.get(key)
        if hit is not None:
            return hit
        if e[0] == "or":
            hit = all(self.certain_not(c, x) for c in e[1])
        elif e[0] == "C" and e[1] in self.defs:
            hit = self.certain_not(self.defs[e[1]], x)
        elif not _assertable(e, self.defs):
            hit = False
        else:
            m = self.m
            token = m.begin()
            try:
                self.impose(e, x)
                m.run()
                hit = m.clash is not None
            finally:
                m.rollback(token)
        self._fresh()
        self._cert_not[key] = hit
        return hit

    def impose(self, e: Expr, x: str) -> None:
        m, tag = self.m, e[0]
        if tag == "C":
            if e[1] != THING:
                m.cls(x, e[1])
        elif tag == "and":
            for c in e[1]:
                self.impose(c, x)
        elif tag == "some" or (tag == "min" and e[1] == 1):
            role, filler = (e[1], e[2]) if tag == "some" else (e[2], e[3])
            n = m.new_element()
            m.role(role, x, n)
            self.impose(filler, n)
        elif tag == "value":
            m.role(e[1], x, e[2])
        elif tag == "dvalue":
            m.datum(x, e[1], e[2])
        else:
            raise Fallback(f"cannot assert {tag}")

    # ------------------------------------------------------------------ refutation
    def falsifiers(self, e: Expr, x: str) -> list[tuple[Any, ...]] | None:
        """Assertions that may make ``e(x)`` false (``e`` holds now), or None."""
        m, tag = self.m, e[0]
        if not self.holds(e, x):
            return []
        if tag == "C":
            if e[1] in self.defs:
                return self.falsifiers(self.defs[e[1]], x)
            return None
        if tag == "and":
            for c in e[1]:
                if not self.certain(c, x):
                    f = self.falsifiers(c, x)
                    if f is not None:
                        return f
            return None
        if tag == "or":
            out: list[tuple[Any, ...]] = []
            for c in e[1]:
                f = self.falsifiers(c, x)
                if f is None:
                    return None
                out += f
            return out
        if tag == "not":
            inner = e[1]
            if inner[0] == "C" and inner[1] in self.defs:
                inner = self.defs[inner[1]]
            # To falsify "not (A or B)" it is enough to make one disjunct true.
            options = inner[1] if inner[0] == "or" else (inner,)
            for option in options:
                if _assertable(option, self.defs) and not self.certain_not(option, x):
                    return [("assert", option, x)]
            return None
        if tag == "some":
            out = []
            for y in sorted(m.rsucc(e[1], x)):
                f = self.falsifiers(e[2], y)
                if f is None:
                    return None
                out += f
            return out
        if tag == "all":  # needs one successor outside the filler
            role, filler = e[1], e[2]
            bound = self.bound(role, x)
            if bound is None:
                return [("fresh", role, x)]
            for s in sorted(bound):
                if self.certain(filler, s):
                    continue
                linked = s in m.rsucc(role, x)
                f = self.falsifiers(filler, s)
                if f is not None:
                    return ([] if linked else [("link", role, x, s)]) + f
            return None
        if tag == "max" and e[1] == 0:  # needs one successor inside the filler
            role, filler = e[2], e[3]
            if not _assertable(filler, self.defs):
                return None
            bound = self.bound(role, x)
            if bound is None:
                return [("fresh-assert", role, x, filler)]
            for s in sorted(bound):
                if self.certain_not(filler, s):
                    continue
                linked = s in m.rsucc(role, x)
                return ([] if linked else [("link", role, x, s)]) + [("assert", filler, s)]
            return None
        return None

    def apply(self, ops: list[tuple[Any, ...]]) -> None:
        m = self.m
        for op in ops:
            if op[0] == "assert":
                self.impose(op[1], op[2])
            elif op[0] == "link":
                m.role(op[1], op[2], op[3])
            elif op[0] == "fresh":
                m.role(op[1], op[2], m.new_element())
            elif op[0] == "fresh-assert":
                n = m.new_element()
                m.role(op[1], op[2], n)
                self.impose(op[3], n)
        m.run()

    def violations(self, checks: list[Axiom]) -> str | None:
        """The first knowledge-base axiom the model does not satisfy."""
        closure = self.m.closure_violation()
        if closure:
            return closure
        for ax in checks:
            if not self._satisfied(ax):
                return ax.text
        return None

    def _satisfied(self, ax: Axiom) -> bool:
        m, k, a = self.m, ax.kind, ax.args

        def sub(left: Expr, right: Expr) -> bool:
            pool = m.members.get(left[1], set()) if left[0] == "C" else m.types.keys()
            return all(self.holds(right, x) for x in list(pool) if self.holds(left, x))

        if k == "sub":
            return sub(a[0], a[1])
        if k == "eq":
            return all(sub(x, y) for x in a[0] for y in a[0] if x is not y)
        if k == "disj":
            return all(sub(x, ("not", y)) for i, x in enumerate(a[0]) for y in a[0][i + 1 :])
        if k == "cassert":
            return a[1] in m.types and self.holds(a[0], a[1])
        if k == "domain":
            return sub(("some", a[0], ("C", THING)), a[1])
        if k == "range":
            return sub(("C", THING), ("all", a[0], a[1]))
        if k == "ddomain":
            return sub(("or", (("dvalue", a[0], True), ("dvalue", a[0], False))), a[1])
        raise Fallback(f"no model check for {k}")


# Conjunctions' parts in the order candidates() reads them, by the
# conjunction's id (the conjunction is kept beside it, so the id stays its own).
_ORDERED: dict[int, tuple[Expr, tuple[Expr, ...]]] = {}
_COST = {"C": 0, "value": 1, "dvalue": 1, "oneof": 1}


def _read_first(e: Expr, part: Expr) -> None:
    """Read ``part`` first next time: it had no candidate, and a step
    changes little, so it likely has none again (the order changes what is
    read, never what is found)."""
    parts = _by_cost(e)
    _ORDERED[id(e)] = (e, (part, *(c for c in parts if c is not part)))


def _by_cost(e: Expr) -> tuple[Expr, ...]:
    hit = _ORDERED.get(id(e))
    if hit is not None and hit[0] is e:
        return hit[1]
    parts = tuple(sorted(e[1], key=lambda c: _COST.get(c[0], 2)))  # stable: ties keep order
    if len(_ORDERED) > 100_000:  # definitions rebuilt without axioms, again and again
        _ORDERED.clear()
    _ORDERED[id(e)] = (e, parts)
    return parts


def _assertable(e: Expr, defs: dict[str, Expr]) -> bool:
    tag = e[0]
    if tag == "C":
        return e[1] not in defs and e[1] != NOTHING
    if tag == "and":
        return all(_assertable(c, defs) for c in e[1])
    if tag in ("some",):
        return _assertable(e[2], defs)
    if tag == "min":
        return e[1] == 1 and _assertable(e[3], defs)
    return tag in ("value", "dvalue")
