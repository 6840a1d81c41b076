"""The model a sharing block grows, kept between blocks.

Verifying a plan grows one model with what no step of it changes (see
:meth:`FastEngine.sharing`).  Verifying another plan in the same scene (the
planner's next attempt, a checked correction, a benchmark's next run) shares
almost all of those facts, and building their model again cost about half of
a verification in a scene of a thousand objects.  So the model keeps three
levels, each rolled back to the one below it:

* the TBox's own facts;
* the *base*: facts an earlier block shared, kept after that block ended;
* the block's own growth, rolled back when the block ends.

A block whose facts include the base, and of which the base is at least half,
only grows it with the rest.  Otherwise the base becomes what the two have in common, when that is most of the new
facts (the same scene, a plan that moves other objects), or the new facts
(another scene).  The rules are monotone and a rollback restores a state
exactly, so the grown model is the least model of the block's facts either
way; the answers do not depend on what was kept.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any, NamedTuple

from virf.reasoning.chase import Model, Token
from virf.reasoning.program import Program
from virf.schema import Fact, FactKind

# Journal entries a model may be rolled back by; past this, building the
# TBox's model again (about a millisecond) is cheaper than undoing each one.
ROLLBACK_AT_MOST = 4000

Loader = Callable[[Model, list[Fact]], None]


class Core(NamedTuple):
    """The model a sharing block grew: its facts, and the individuals they
    name.  ``state`` tells two blocks' cores apart: the kept base's token
    and the journal of the growth on it.  Two cores with equal states are
    the same model, atom for atom and name for name (None: not compared)."""

    model: Model
    facts: frozenset[Fact]
    individuals: frozenset[str]
    state: tuple[Any, ...] | None = None


def individuals(facts: Iterable[Fact]) -> frozenset[str]:
    """The ABox individuals the facts name (a classification's candidates)."""
    out: set[str] = set()
    for f in facts:
        out.add(f.subject)
        if f.kind is FactKind.OBJECT:
            out.add(f.object)
    return frozenset(out)


class Kept:
    """One journaled model of the TBox's facts, a base kept on it between
    blocks, and the growth of the block that holds it (one at a time)."""

    def __init__(self) -> None:
        self.model: Model | None = None
        self._tbox: Token | None = None  # the TBox's facts alone
        self.base: frozenset[Fact] = frozenset()
        self._base: Token | None = None  # the base loaded
        self._base_names: frozenset[str] = frozenset()
        self.held = False

    def grow(self, prog: Program, shared: frozenset[Fact], load: Loader) -> Model:
        """The model of the TBox's facts and ``shared``, for the block that
        holds it until :meth:`release`.  ``load`` may raise (the model is
        then rolled back to a level it can keep); a clash is the caller's."""
        self.held = True
        m = self.model
        if m is None or m.prog is not prog:
            m = self.model = prog.model(journal=True)
            self._tbox = self._base = m.begin()
            self.base, self._base_names = frozenset(), frozenset()
        if 2 * len(self.base) < len(shared) or not self.base <= shared:
            common = self.base & shared
            self._rebase(m, common if 2 * len(common) >= len(shared) else shared, load)
        m = self.model
        assert m is not None and self._base is not None
        rest = shared - self.base if self.base else shared
        load(m, Fact.sorted(rest))
        return m

    def core(self, m: Model, shared: frozenset[Fact]) -> Core:
        """The block's core, its individuals named from what the base already knows."""
        rest = shared - self.base if self.base else shared
        base = self._base
        assert base is not None and m.journal is not None
        # A rebase makes a new token: the base is the same state while its token is.
        state = (base, tuple(m.journal[base[0] :]))
        return Core(m, shared, self._base_names | individuals(rest), state)

    def _rebase(self, m: Model, base: frozenset[Fact], load: Loader) -> None:
        assert self._tbox is not None and m.journal is not None
        if len(m.journal) - self._tbox[0] > ROLLBACK_AT_MOST:
            m = self.model = m.prog.model(journal=True)
            self._tbox = m.begin()
        else:
            m.rollback(self._tbox)
            self._tbox = m.begin()
        self.base, self._base_names, self._base = frozenset(), frozenset(), self._tbox
        if not base:
            return
        try:
            load(m, Fact.sorted(base))
        except BaseException:
            m.rollback(self._tbox)
            self._tbox = self._base = m.begin()
            raise
        if m.clash is not None:
            # Every set of facts that includes it clashes too: keep none.
            m.rollback(self._tbox)
            self._tbox = self._base = m.begin()
            return
        self.base, self._base_names, self._base = base, individuals(base), m.begin()

    def release(self) -> None:
        """End the block: roll its growth back to the base."""
        m, token = self.model, self._base
        self.held = False
        if m is None or token is None:
            return
        # Undoing the growth costs what the block added, never more than
        # building the base again.
        m.rollback(token)
