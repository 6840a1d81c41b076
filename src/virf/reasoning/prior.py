"""What the previous step's model said, and where this step's can differ.

The steps of a plan are classified on one shared model, each grown by what
that step adds and rolled back after (:meth:`FastEngine.classify_shared`).
Two steps' models differ in the atoms one step's growth holds and the
other's does not, and a step moves a few objects of a thousand.  The
classical truth of a query at an individual reads only the types, data and
role edges of the individuals its roles lead to, so where none of those
changed, the previous step's answer is this step's: the query is decided
again only within reach of the change.

For a query ``e``, :meth:`Prior.affected` is the set of individuals where
``e`` may read something that changed (None: anywhere, for a query over a
role that is searched rather than stored):

* a class: the individuals whose types changed;
* ``r some F``, ``r only F``, cardinalities: the individuals with a changed
  ``r`` edge, and the ``r``-predecessors (in this model) of those where
  ``F`` may differ.  A predecessor that only the other model had is linked
  by a changed edge, so it is in the first set already;
* ``r value i``: the individuals with a changed ``r`` edge;
* a data value: the individuals whose data changed.

A query class's candidates (:meth:`Evaluator.candidates`) are read from
whole tables of the model: the members of a class, the edges of a role, the
values of a data property.  Where no atom of those tables changed, the
previous step's candidates are this step's (:attr:`Prior.tables` and
:meth:`Prior.edge_tables` list the tables that changed).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from collections.abc import Set as AbstractSet
from typing import TYPE_CHECKING, Any

from virf.ontology.fragment import Expr
from virf.ontology.iri import THING
from virf.reasoning.chase import Model

if TYPE_CHECKING:
    from virf.reasoning.program import LazyRole

# Journal entries that are atoms of the model: an element, a type, an edge, a datum.
_ATOMS = frozenset({"e", "t", "r", "d"})

Atoms = frozenset[tuple[Any, ...]]
Values = dict[tuple[Expr, str], bool]
# Each concept's candidates in a step's model (None: possibly any individual).
Wheres = dict[str, frozenset[str] | None]
# The candidates of the definitions a step's model read (None: possibly any).
Reads = dict[str, frozenset[str] | None]
Table = tuple[Any, ...]  # see tables()
Tables = frozenset[Table]


def atoms(m: Model, since: int) -> Atoms:
    """The atoms the model's journal recorded from position ``since`` on."""
    assert m.journal is not None
    return frozenset(e for e in m.journal[since:] if e[0] in _ATOMS)


def tables(
    e: Expr, defs: dict[str, Expr], sinks: AbstractSet[str], lazy: Mapping[str, LazyRole]
) -> Tables:
    """The model's tables :meth:`Evaluator.candidates` reads for ``e``:

    * ``("t", class)``: the class's members;
    * ``("r", property)``: every edge of the property;
    * ``("r>", property, i)`` / ``("r<", property, i)``: its edges into
      ``i`` / out of ``i``;
    * ``("r>M", property, mark)`` / ``("r<M", property, mark)``: its edges
      into / out of individuals that bear the mark (:func:`bounding_marks`);
    * ``("d", data property)``: its values.

    Where no atom of them changed between two models, ``e``'s candidates
    are the same in both."""
    tag = e[0]
    if tag == "C":
        if e[1] in defs:
            return tables(defs[e[1]], defs, sinks, lazy)
        return frozenset() if e[1] == THING or e[1] in sinks else frozenset({("t", e[1])})
    if tag in ("and", "or"):
        return frozenset().union(*(tables(c, defs, sinks, lazy) for c in e[1]))
    if tag == "some" or (tag == "min" and int(e[1]) >= 1):
        role, filler = (e[1], e[2]) if tag == "some" else (e[2], e[3])
        spec = lazy.get(role[0])
        if spec is not None:
            # The search from the filler's candidates reads the role's stored
            # edges and those of its left and right roles (Model.reach_any).
            walked = {("r", s[0]) for s in (*spec.left, *spec.right)}
            return tables(filler, defs, sinks, lazy) | {("r", role[0]), *walked}
        # The edges read are those from (or to) the filler's candidates, all
        # of which bear one of the marks that bound them (a class, or an edge
        # to a value; the filler's own tables include theirs): a robot
        # moving beside a loaf changes no edge to an ignition source.
        bound = bounding_marks(filler, defs, sinks)
        edges: Tables = (
            frozenset({("r", role[0])})
            if bound is None
            else frozenset(("r<M" if role[1] else "r>M", role[0], mark) for mark in bound)
        )
        return tables(filler, defs, sinks, lazy) | edges
    if tag == "value":
        # Only the edges that end at the value: a step that switches a
        # device on changes no edge into any other state.
        role = e[1]
        if role[0] in lazy:
            return frozenset()
        return frozenset({("r<" if role[1] else "r>", role[0], e[2])})
    if tag == "dvalue":
        return frozenset({("d", e[1])})
    return frozenset()  # the candidates are None or fixed by the expression


# What an individual bears: ("C", class) a class; ("V", property, inverse,
# i) an edge of the property to i (from i, when inverse).
Mark = tuple[str, ...]


def bounding_marks(
    e: Expr, defs: dict[str, Expr], sinks: AbstractSet[str]
) -> frozenset[Mark] | None:
    """Marks one of which every candidate of ``e`` bears (None: none found
    that do).  Of a conjunction's parts, a value bounds more closely than a
    class (PhysicalObject bounds little)."""
    tag = e[0]
    if tag == "C":
        if e[1] in defs:
            return bounding_marks(defs[e[1]], defs, sinks)
        return None if e[1] == THING or e[1] in sinks else frozenset({("C", e[1])})
    if tag == "value":
        return frozenset({("V", e[1][0], "<" if e[1][1] else ">", e[2])})
    if tag == "and":
        found = [b for c in e[1] if (b := bounding_marks(c, defs, sinks)) is not None]
        if not found:
            return None
        return next((b for b in found if all(m[0] == "V" for m in b)), found[0])
    if tag == "or":
        parts = [bounding_marks(c, defs, sinks) for c in e[1]]
        return None if any(p is None for p in parts) else frozenset().union(*parts)  # type: ignore[arg-type]
    return None


def holders(m: Model, mark: Mark) -> AbstractSet[str]:
    """The individuals that bear ``mark`` in ``m`` (a live table: do not
    modify it)."""
    if mark[0] == "C":
        return m.members.get(mark[1], _NO_ONE)
    _, q, way, i = mark
    # Those with an edge x q i (way ">"), or i q x (way "<").
    return (m.pred if way == ">" else m.succ).get(q, {}).get(i, _NO_ONE)


_NO_ONE: frozenset[str] = frozenset()


class Prior:
    """The classical answers a step's model gave, and the atoms that differ
    between that model and the one now asked about."""

    def __init__(
        self, values: Values, defs: dict[str, Expr], sinks: frozenset[str], diff: Iterable[Any]
    ) -> None:
        self.values = values
        self.defs = defs
        self.sinks = sinks
        # (Comprehensions by kind of atom: a loop over every atom with a
        # branch per kind cost a tenth of a step.)
        atoms = diff if isinstance(diff, AbstractSet) else frozenset(diff)
        types = [e for e in atoms if e[0] == "t"]
        data = [e for e in atoms if e[0] == "d"]
        edges = [e for e in atoms if e[0] == "r"]
        self.types: set[str] = {e[1] for e in atoms if e[0] in ("e", "t")}
        self.data: set[str] = {e[1] for e in data}
        # The tables the atoms are in.
        self.tables: set[Table] = {("t", e[2]) for e in types}
        self.tables.update(("d", e[2]) for e in data)
        self.tables.update(("r", e[1]) for e in edges)
        self.edges: dict[str, set[str]] = {}
        # The ends of the changed edges, by direction and property.
        self.ends: dict[tuple[str, str], set[str]] = {}
        for _, p, x, y in edges:
            self.edges.setdefault(p, set()).update((x, y))
            self.ends.setdefault((">", p), set()).add(y)
            self.ends.setdefault(("<", p), set()).add(x)
        self._affected: dict[Expr, set[str] | None] = {}

    def edge_tables(
        self,
        m: Model,
        values: Mapping[tuple[str, str], frozenset[str]],
        marks: Mapping[tuple[str, str], tuple[Mark, ...]],
    ) -> Iterator[Table]:
        """The tables (see :func:`tables`) of the changed edges that end at
        one of the individuals ``values``, ``("r>", p, i)`` and ``("r<", p,
        i)``, or at what bears one of the ``marks``, ``("r>M", p, mark)``
        and ``("r<M", p, mark)`` (both by direction and property).  An end's
        marks are read in ``m``: an end whose marks differ between the
        models has that change among the atoms, in the mark's own table."""
        # By property, with set operations: a box moved with a thousand in
        # it changes thousands of edges, and a check per edge cost more than
        # the candidates it kept.
        for (way, p), ends in self.ends.items():
            for i in values.get((way, p), ()):
                if i in ends:
                    yield ("r" + way, p, i)
            for mark in marks.get((way, p), ()):
                if not ends.isdisjoint(holders(m, mark)):
                    yield ("r" + way + "M", p, mark)

    def affected(self, m: Model, e: Expr) -> set[str] | None:
        """Where ``e``'s classical truth may differ from the previous model's
        (``m`` is this step's model, as grown)."""
        if e in self._affected:
            return self._affected[e]
        found = self._find(m, e)
        self._affected[e] = found
        return found

    def _find(self, m: Model, e: Expr) -> set[str] | None:
        tag = e[0]
        if tag == "C":
            name = e[1]
            if name in self.defs:
                return self.affected(m, self.defs[name])
            return set() if name in self.sinks else self.types
        if tag in ("and", "or"):
            out: set[str] = set()
            for c in e[1]:
                part = self.affected(m, c)
                if part is None:
                    return None
                out |= part
            return out
        if tag == "not":
            return self.affected(m, e[1])
        if tag in ("some", "all", "min", "max"):
            role, filler = (e[1], e[2]) if tag in ("some", "all") else (e[2], e[3])
            if role[0] in m.lazy:
                return None
            inner = self.affected(m, filler)
            if inner is None:
                return None
            out = set(self.edges.get(role[0], ()))
            back = (role[0], not role[1])
            for z in inner:
                if z in m.types:
                    out |= m.rsucc(back, z)
            return out
        if tag == "value":
            return None if e[1][0] in m.lazy else self.edges.get(e[1][0], set())
        if tag == "oneof":
            return set()
        if tag == "dvalue":
            return self.data
        return None

    def holds(self, m: Model, e: Expr, x: str) -> bool | None:
        """The previous model's answer to ``e(x)`` when it is this one's too;
        None when it must be read again."""
        known = self.values.get((e, x))
        if known is None:
            return None
        where = self.affected(m, e)
        if where is None or x in where:
            return None
        return known


class Readers:
    """The query classes by the tables their candidates read (see
    :func:`tables`), to find those a step's change touches from the tables
    it changed, not concept by concept: a step changes a few tables, and a
    knowledge base has hundreds of concepts."""

    def __init__(
        self, defs: dict[str, Expr], sinks: AbstractSet[str], lazy: Mapping[str, LazyRole]
    ) -> None:
        readers: dict[Table, set[str]] = {}
        for name in defs:
            for table in tables(("C", name), defs, sinks, lazy):
                readers.setdefault(table, set()).add(name)
        self.readers = {t: frozenset(names) for t, names in readers.items()}
        # The individuals and marks asked of a changed edge's end, by
        # direction and property.
        values: dict[tuple[str, str], set[str]] = {}
        marks: dict[tuple[str, str], list[Mark]] = {}
        for table in sorted(readers):
            if table[0] in ("r>", "r<"):
                values.setdefault((table[0][1], table[1]), set()).add(table[2])
            elif table[0] in ("r>M", "r<M"):
                marks.setdefault((table[0][1], table[1]), []).append(table[2])
        self.values = {k: frozenset(v) for k, v in values.items()}
        self.marks = {k: tuple(v) for k, v in marks.items()}

    def touched(self, prior: Prior, m: Model) -> set[str]:
        """The classes whose candidates may differ between ``prior``'s model
        and ``m``; any other keeps the previous step's."""
        found: set[str] = set()
        for table in (*prior.tables, *prior.edge_tables(m, self.values, self.marks)):
            found.update(self.readers.get(table, ()))
            # A class outside the query definitions reads its own members.
            if table[0] == "t":
                found.add(table[1])
        return found
