"""The instances of the concepts asked, read off one grown model of the fast
engine (:mod:`virf.reasoning.fast`): which individuals a concept can hold at
(its candidates, :meth:`Evaluator.candidates`), and at those, whether it is
entailed (:meth:`Evaluator.decide`).  A step of a plan keeps the previous
step's candidates of every concept its change did not touch
(:mod:`virf.reasoning.prior`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from collections.abc import Set as AbstractSet

from virf.deadlines import check_deadline
from virf.ontology.fragment import Expr, Fragment
from virf.ontology.iri import THING
from virf.reasoning import Classification
from virf.reasoning.chase import Model
from virf.reasoning.evaluate import Evaluator, Fallback, checks
from virf.reasoning.prior import Prior, Readers, Wheres
from virf.reasoning.program import LazyRole

_NONE: frozenset[str] = frozenset()


class Instances:
    """Reads the instances of concepts off a model, for one fragment."""

    def __init__(self, fragment: Fragment, lazy: Mapping[str, LazyRole]) -> None:
        self.fragment = fragment
        self._required: dict[str, list[frozenset[str]]] = {}  # see needs
        self._readers = Readers(fragment.query_defs, fragment.sinks, lazy)

    def __call__(
        self,
        m: Model,
        ev: Evaluator,
        abox: frozenset[str],
        concepts: Sequence[str],
        before: tuple[Wheres, AbstractSet[str]] | None = None,
        wheres: Wheres | None = None,
    ) -> Classification:
        """The instances among ``abox`` of each concept, in the grown model.

        ``before`` is the previous step's candidates of each concept and
        the concepts the change touched: a concept none of whose tables changed keeps
        its candidates (a step moves one or two objects; reading every
        concept's candidates again was half of a step's classification).
        This step's candidates go into ``wheres``, for the next."""
        if m.clash is not None:
            return Classification(False, {})
        bad = ev.violations(checks(m))
        if bad is not None:
            raise Fallback(f"candidate model violates: {bad}")
        found: dict[str, tuple[str, ...]] = {}
        # The classes with a member: the model deletes a class's entry with
        # its last member, and adds one only with a member.
        inhabited = m.members.keys()
        kept: Wheres = {}
        touched: AbstractSet[str] = frozenset()
        if before is not None:
            kept, touched = before
        required = self._required if ev.defs is self.fragment.query_defs else {}
        for concept in concepts:
            where: frozenset[str] | None
            if concept in kept and concept not in touched:
                where = kept[concept]
            else:
                # Every set of classes the concept needs lacks a member: it has
                # no candidate (most concepts, in most steps, are settled here).
                # (A loop and a set comparison: generators here cost a tenth
                # of a step.)
                for alt in required.get(concept) or self.needs(concept, ev.defs):
                    if inhabited >= alt:
                        break
                else:
                    if wheres is not None:
                        wheres[concept] = _NONE
                    continue
                # (Checked only here: a concept settled above costs a microsecond.)
                check_deadline("while the fast engine classified the facts")
                # Only where the concept holds in the model can it be entailed.
                read = ev.candidates(("C", concept))
                # Frozen: a class's members are a live table of the model.
                where = None if read is None else frozenset(read) if read else _NONE
            if wheres is not None:
                wheres[concept] = where
            if where is not None and not where:
                continue
            check_deadline("while the fast engine classified the facts")
            pool = abox if where is None else abox & where
            names = tuple(x for x in sorted(pool) if ev.decide(concept, x))
            if names:
                found[concept] = names
        return Classification(True, found)

    def touched(self, prior: Prior, m: Model) -> AbstractSet[str]:
        """The concepts and classes whose candidates the change since
        ``prior`` may touch (see :class:`virf.reasoning.prior.Readers`)."""
        return self._readers.touched(prior, m)

    def needs(self, concept: str, defs: dict[str, Expr]) -> list[frozenset[str]]:
        """The knowledge-base classes the concept's candidates require."""
        if defs is not self.fragment.query_defs:
            return [frozenset()]
        needs = self._required.get(concept)
        if needs is None:
            needs = required(("C", concept), defs, self.fragment.sinks)
            self._required[concept] = needs
        return needs


def required(e: Expr, defs: dict[str, Expr], sinks: AbstractSet[str]) -> list[frozenset[str]]:
    """What :meth:`Evaluator.candidates` needs to find any candidate for
    ``e``, read from the definitions alone: sets of knowledge-base classes,
    one of which must have a member each (a disjunction's, one set per
    disjunct).  Where none has, ``e`` has no candidate.  A set ``{}`` asks
    nothing; a requirement left out only makes the test weaker."""
    tag = e[0]
    if tag == "C":
        if e[1] in defs:
            return required(defs[e[1]], defs, sinks)
        return [frozenset()] if e[1] == THING or e[1] in sinks else [frozenset({e[1]})]
    if tag == "and":
        # One set of each conjunct's, in every combination (within a bound).
        out: list[frozenset[str]] = [frozenset()]
        for c in e[1]:
            part = required(c, defs, sinks)
            if len(out) * len(part) <= _REQUIRED_AT_MOST:
                out = [a | b for a in out for b in part]
        return out
    if tag == "or":
        return [x for c in e[1] for x in required(c, defs, sinks)]
    if tag == "some" or (tag == "min" and int(e[1]) >= 1):
        # Over any role, a searched one too: no candidate of the filler, none here.
        return required(e[2] if tag == "some" else e[3], defs, sinks)
    return [frozenset()]


# Alternatives a requirement may list before a conjunct's are left out.
_REQUIRED_AT_MOST = 16
