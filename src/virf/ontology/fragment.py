"""The TBox as Python data, split into what the fast engine can reason with.

At load time every logical axiom is converted from OWLAPI into hashable
Python terms.  A construct the fast engine has no semantics for (a data range,
a key, a functional object property, ...) is recorded as a *problem*; with
any problem present the fast engine answers nothing itself and hands every
question to the reference reasoner.  That is the load-time refusal: nothing
depends on whether a later input happens to touch the construct.

The accepted axioms are then sorted into three groups:

* **query classes**: a class ``Q`` defined by exactly one ``Q EquivalentTo E``
  and used nowhere else except inside other query definitions and as the
  subclass of sink classes.  Such a definition is a conservative extension, so
  ``Q(x)`` is entailed exactly when ``E(x)`` is, and ``E`` can be evaluated as
  a query instead of being reasoned with.  All Unsafe State Concepts are of
  this kind, which is why their negations, ``only`` and ``max 0`` never enter
  the knowledge base proper.
* **sink classes**: classes that only ever appear as superclasses of query or
  sink classes (``UnsafeStateConcept``, ``Danger``).  Interpreting them as
  everything satisfies their axioms, so they constrain nothing.
* **knowledge-base axioms**: everything else.  Their Horn parts compile to
  forward-chaining rules (a sound lower bound); an axiom that does not compile
  completely is kept for checking candidate models.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from virf.ontology.iri import NOTHING, THING, iri_short

Role = tuple[str, bool]  # (object property, inverted)
# Class expressions are nested tuples:
#   ("C", name) | ("and", (e, ...)) | ("or", (e, ...)) | ("not", e)
#   ("some", role, e) | ("all", role, e) | ("value", role, individual)
#   ("min", n, role, e) | ("max", n, role, e) | ("oneof", (individual, ...))
#   ("dvalue", data property, bool)
Expr = tuple[Any, ...]


class Unsupported(Exception):
    """An OWL construct outside the fast engine's fragment."""


@dataclass(frozen=True)
class Axiom:
    kind: str
    args: tuple[Any, ...]
    id: str | None
    text: str


def _role(pe: Any) -> Role:
    pe = pe.getSimplified()
    if pe.isAnonymous():
        return (iri_short(pe.getInverse().asOWLObjectProperty().getIRI()), True)
    return (iri_short(pe.asOWLObjectProperty().getIRI()), False)


def _bool_literal(lit: Any) -> bool:
    datatype = str(lit.getDatatype().getIRI().toString())
    if not datatype.endswith("#boolean"):
        raise Unsupported(f"data value of type {datatype}")
    value = str(lit.getLiteral()).strip()
    if value not in ("true", "false", "1", "0"):
        raise Unsupported(f"boolean literal '{value}'")
    return value in ("true", "1")


def expr(ce: Any) -> Expr:
    """OWLAPI class expression -> Python term."""
    kind = str(ce.getClassExpressionType().toString())
    if kind == "Class":
        return ("C", iri_short(ce.asOWLClass().getIRI()))
    if kind == "ObjectIntersectionOf":
        return ("and", tuple(sorted(expr(c) for c in ce.getOperandsAsList())))
    if kind == "ObjectUnionOf":
        return ("or", tuple(sorted(expr(c) for c in ce.getOperandsAsList())))
    if kind == "ObjectComplementOf":
        return ("not", expr(ce.getOperand()))
    if kind == "ObjectSomeValuesFrom":
        return ("some", _role(ce.getProperty()), expr(ce.getFiller()))
    if kind == "ObjectAllValuesFrom":
        return ("all", _role(ce.getProperty()), expr(ce.getFiller()))
    if kind == "ObjectHasValue":
        ind = ce.getFiller()
        if ind.isAnonymous():
            raise Unsupported("anonymous individual")
        return ("value", _role(ce.getProperty()), iri_short(ind.asOWLNamedIndividual().getIRI()))
    if kind in ("ObjectMinCardinality", "ObjectMaxCardinality", "ObjectExactCardinality"):
        n = int(ce.getCardinality())
        role = _role(ce.getProperty())
        filler = expr(ce.getFiller())
        if kind == "ObjectMinCardinality":
            return ("min", n, role, filler)
        if kind == "ObjectMaxCardinality":
            return ("max", n, role, filler)
        return ("and", tuple(sorted((("min", n, role, filler), ("max", n, role, filler)))))
    if kind == "ObjectOneOf":
        inds = []
        for i in ce.getIndividualsAsList():
            if i.isAnonymous():
                raise Unsupported("anonymous individual")
            inds.append(iri_short(i.asOWLNamedIndividual().getIRI()))
        return ("oneof", tuple(sorted(inds)))
    if kind == "DataHasValue":
        prop = iri_short(ce.getProperty().asOWLDataProperty().getIRI())
        return ("dvalue", prop, _bool_literal(ce.getFiller()))
    raise Unsupported(f"class expression {kind}")


def _named_ind(i: Any) -> str:
    if i.isAnonymous():
        raise Unsupported("anonymous individual")
    return iri_short(i.asOWLNamedIndividual().getIRI())


def convert(ax: Any, ident: str | None, text: str) -> Axiom:
    """OWLAPI logical axiom -> :class:`Axiom` (raises :class:`Unsupported`)."""
    kind = str(ax.getAxiomType().toString())

    def make(k: str, *args: Any) -> Axiom:
        return Axiom(k, tuple(args), ident, text)

    if kind == "SubClassOf":
        return make("sub", expr(ax.getSubClass()), expr(ax.getSuperClass()))
    if kind == "EquivalentClasses":
        return make("eq", tuple(expr(c) for c in ax.getClassExpressionsAsList()))
    if kind == "DisjointClasses":
        return make("disj", tuple(expr(c) for c in ax.getClassExpressionsAsList()))
    if kind == "ClassAssertion":
        return make("cassert", expr(ax.getClassExpression()), _named_ind(ax.getIndividual()))
    if kind == "ObjectPropertyAssertion":
        return make(
            "passert",
            _role(ax.getProperty()),
            _named_ind(ax.getSubject()),
            _named_ind(ax.getObject()),
        )
    if kind == "DataPropertyAssertion":
        prop = iri_short(ax.getProperty().asOWLDataProperty().getIRI())
        return make("dassert", prop, _named_ind(ax.getSubject()), _bool_literal(ax.getObject()))
    if kind == "SubObjectPropertyOf":
        return make("subprop", _role(ax.getSubProperty()), _role(ax.getSuperProperty()))
    if kind == "SubPropertyChainOf":
        chain = tuple(_role(p) for p in ax.getPropertyChain())
        if len(chain) != 2:
            raise Unsupported("property chain of length other than 2")
        return make("chain", chain, _role(ax.getSuperProperty()))
    if kind == "InverseObjectProperties":
        return make("inverse", _role(ax.getFirstProperty()), _role(ax.getSecondProperty()))
    if kind == "EquivalentObjectProperties":
        return make("eqprop", tuple(_role(p) for p in ax.getOperandsAsList()))
    if kind == "TransitiveObjectProperty":
        return make("trans", _role(ax.getProperty()))
    if kind == "SymmetricObjectProperty":
        return make("sym", _role(ax.getProperty()))
    if kind == "ObjectPropertyDomain":
        return make("domain", _role(ax.getProperty()), expr(ax.getDomain()))
    if kind == "ObjectPropertyRange":
        return make("range", _role(ax.getProperty()), expr(ax.getRange()))
    if kind == "FunctionalDataProperty":
        return make("dfunc", iri_short(ax.getProperty().asOWLDataProperty().getIRI()))
    if kind == "DataPropertyRange":
        rng = ax.getRange()
        if not rng.isOWLDatatype() or not str(rng.asOWLDatatype().getIRI().toString()).endswith(
            "#boolean"
        ):
            raise Unsupported("data property range other than xsd:boolean")
        return make("drange", iri_short(ax.getProperty().asOWLDataProperty().getIRI()))
    if kind == "DataPropertyDomain":
        return make(
            "ddomain",
            iri_short(ax.getProperty().asOWLDataProperty().getIRI()),
            expr(ax.getDomain()),
        )
    if kind == "DifferentIndividuals":
        # Candidate models interpret distinct names as distinct elements, so
        # these always hold there; the lower bound may ignore them.
        return make("different", tuple(_named_ind(i) for i in ax.getIndividualsAsList()))
    raise Unsupported(f"axiom type {kind}")


def classes_in(e: Expr) -> Iterable[str]:
    tag = e[0]
    if tag == "C":
        yield e[1]
    elif tag in ("and", "or"):
        for c in e[1]:
            yield from classes_in(c)
    elif tag == "not":
        yield from classes_in(e[1])
    elif tag in ("some", "all"):
        yield from classes_in(e[2])
    elif tag in ("min", "max"):
        yield from classes_in(e[3])


_TAGS = {"C", "and", "or", "not", "some", "all", "value", "min", "max", "oneof", "dvalue"}


def _axiom_classes(ax: Axiom) -> set[str]:
    out: set[str] = set()
    for a in ax.args:
        if isinstance(a, tuple) and a and isinstance(a[0], str) and a[0] in _TAGS:
            out.update(classes_in(a))
        elif isinstance(a, tuple):
            for b in a:
                if isinstance(b, tuple) and b and isinstance(b[0], str) and b[0] in _TAGS:
                    out.update(classes_in(b))
    return out


@dataclass
class Fragment:
    """The converted TBox, partitioned (see the module docstring)."""

    axioms: list[Axiom]
    problems: list[str]
    query_defs: dict[str, Expr] = field(default_factory=dict)
    query_axiom: dict[str, Axiom] = field(default_factory=dict)
    sinks: frozenset[str] = frozenset()
    kb: list[Axiom] = field(default_factory=list)

    @property
    def exact(self) -> bool:
        return not self.problems


def load_fragment(owl_axioms: Iterable[Any], render: Any) -> Fragment:
    """OWLAPI logical axioms -> the partitioned fragment (Java side)."""
    from virf.ontology.owlapi import annotations_of

    axioms: list[Axiom] = []
    problems: list[str] = []
    for ax in owl_axioms:
        ident = annotations_of(ax).get("id")
        text = render(ax)
        try:
            axioms.append(convert(ax, ident, text))
        except Unsupported as exc:
            problems.append(f"{exc} in '{text}'")
    return fragment_from(axioms, problems)


def fragment_from(axioms: list[Axiom], problems: list[str]) -> Fragment:
    """The partitioned fragment of converted axioms (also what the compiled
    knowledge artifact is read back into)."""
    frag = Fragment(sorted(axioms, key=lambda a: (a.kind, repr(a.args))), sorted(set(problems)))
    _partition(frag)
    return frag


def _partition(frag: Fragment) -> None:
    defs: dict[str, list[tuple[Axiom, Expr]]] = defaultdict(list)
    for ax in frag.axioms:
        if ax.kind == "eq" and len(ax.args[0]) == 2:
            a, b = ax.args[0]
            for named, other in ((a, b), (b, a)):
                if named[0] == "C" and other[0] != "C":
                    defs[named[1]].append((ax, other))
    every_class: set[str] = set()
    for ax in frag.axioms:
        every_class |= _axiom_classes(ax)
    # The built-in classes mean something on their own (Nothing in particular
    # makes axioms inconsistent), so they are never queries or sinks.
    builtin = {THING, NOTHING}
    queries = {q for q, ds in defs.items() if len(ds) == 1} - builtin
    sinks = set(every_class) - set(defs) - builtin
    while True:
        before = (len(queries), len(sinks))
        for ax in frag.axioms:
            if ax.kind == "eq" and len(ax.args[0]) == 2:
                named = [e[1] for e in ax.args[0] if e[0] == "C"]
                q = next((n for n in named if n in queries and defs[n][0][0] is ax), None)
                if q is not None:
                    body = defs[q][0][1]
                    sinks -= set(classes_in(body))
                    continue
            # With sinks read as owl:Thing, "anything SubClassOf sink" holds
            # trivially and constrains nothing.
            if ax.kind == "sub" and ax.args[1][0] == "C" and ax.args[1][1] in sinks:
                continue
            if ax.kind == "eq" and all(e[0] == "C" and e[1] in sinks for e in ax.args[0]):
                continue
            used = _axiom_classes(ax)
            queries -= used
            sinks -= used
        # A cyclic definition cannot be evaluated by unfolding.
        for q in sorted(queries):
            if _reaches(q, q, queries, defs, set()):
                queries.discard(q)
        if (len(queries), len(sinks)) == before:
            break
    frag.sinks = frozenset(sinks)
    frag.query_defs = {q: defs[q][0][1] for q in sorted(queries)}
    frag.query_axiom = {q: defs[q][0][0] for q in sorted(queries)}
    special = set(frag.query_axiom.values())
    for ax in frag.axioms:
        if ax in special:
            continue
        if ax.kind == "sub" and ax.args[1][0] == "C" and ax.args[1][1] in sinks:
            continue
        if ax.kind == "eq" and all(e[0] == "C" and e[1] in sinks for e in ax.args[0]):
            continue
        frag.kb.append(ax)


def _reaches(
    start: str,
    goal: str,
    queries: set[str],
    defs: dict[str, list[tuple[Axiom, Expr]]],
    seen: set[str],
) -> bool:
    for c in classes_in(defs[start][0][1]):
        if c == goal:
            return True
        if c in queries and c not in seen:
            seen.add(c)
            if _reaches(c, goal, queries, defs, seen):
                return True
    return False
