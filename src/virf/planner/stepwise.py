"""Plan lines offered one at a time: each one the simulator can run next.

A grammar of a whole reply (:mod:`virf.planner.constraint`) says which lines
exist, not which can follow which: a 135M model writes ``pick Potato_1``
before it has gone to the potato, ``put Pot_1`` while holding the pot, and
opens the kettle twice.  Every such line is a plan the tutor has to send
back for a reason that is not safety, and the model's repair is to delete
lines until nothing is left to fail.

:class:`Stepper` runs the plan as it is written, in the sandbox the tutor
uses (the same :class:`virf.world.simulator.Simulator`), and offers as the
next line only those of the constraint that would run in the state reached
and change something there.  A line that cannot run (an empty hand, a closed
fridge, an object not yet found) is never offered; nor is one that would
leave the world exactly as it is (a second ``find`` of the object just
found), which is how a greedy small model loops.

A line that would bring the world back to what the plan has already made
of it is not offered either: the plan would only have gone round a loop
(``pick``, ``put``, ``pick``, ``put`` ...).  One exception: a line may undo
the line just before it, once (``open`` the fridge, then ``close`` it), as
a hazard the plan's end would show is often settled that way.  The world
includes where the robot stands (``Robot_1 isNear Pot_1``), but not the
record of which objects it has found so far.

When the loop has a tutor, the sandbox carries its judgement of a plan's
lines so far (:attr:`Sandbox.judge`): the line the model writes is checked
as it is written, and one that makes something unsafe at that step is
turned away and the model asked for that line again without it
(:meth:`Stepper.accepts`).  A hazard only the end of a plan can show (an
oven left on) is not a reason to turn a line away: later lines may still
settle it.

This narrows what the model may write, never what the tutor checks: the
whole plan is verified as any other.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Set
from dataclasses import dataclass

from virf.errors import InputError
from virf.ontology.tbox import Vocabulary
from virf.planner.constraint import PlanConstraint
from virf.schema import Fact
from virf.world.language import LIQUIDS
from virf.world.plan import PlanStep, parse_line
from virf.world.scene import Scene
from virf.world.simulator import PreconditionFailure, ResolvedStep, Simulator, WorldState
from virf.world.state import changed


@dataclass(frozen=True, eq=False)
class Sandbox:
    """The scene a constrained plan is written for, to run its lines in as
    they come (a constraint carries it: :attr:`PlanConstraint.sandbox`)."""

    scene: Scene
    vocab: Vocabulary
    # Whether a plan's lines so far leave its last line harmless: False when
    # that line makes something unsafe at its step.  None: no tutor to ask.
    judge: Callable[[tuple[str, ...]], bool] | None = None


class Stepper:
    """One reply being written: the state its lines have reached so far."""

    def __init__(self, constraint: PlanConstraint, sandbox: Sandbox) -> None:
        self._constraint = constraint
        self._sim = Simulator(sandbox.vocab)
        self._state = self._sim.initial(sandbox.scene)
        self._judge = sandbox.judge
        self._previous: PlanStep | None = None
        # Each candidate line's state is told apart from where the plan has
        # been by a hash of its world, updated by the facts the line changes
        # (a pass over every fact per candidate made a line cost the square
        # of a big scene); equal hashes are confirmed on the facts.
        world = (f for f in self._state.facts if f.predicate != "isLocated")
        self._place = _Place(_fold(world), self._state)
        self._been = [self._place]
        # Where the plan was before its last line, which the next line may go
        # back to (undoing the last line) unless the last line was such an undo.
        self._back: _Place | None = None
        self.lines: list[str] = []

    def next_lines(self, refused: Set[str] = frozenset()) -> PlanConstraint:
        """The constraint's lines that run from here, change the world and
        do not bring it back to where the plan has been; none of
        ``refused``."""
        # A refused fill refuses the vessel whatever the liquid: the grammar
        # offers an object's liquids together.
        heads = {" ".join(line.split()[:2]) for line in refused}
        takes: list[tuple[str, tuple[str, ...]]] = []
        for verb, names in self._constraint.takes:
            kept = tuple(
                n
                for n in names
                if f"{verb} {n}" not in heads and self._run(_line(verb, n)) is not None
            )
            if kept:
                takes.append((verb, kept))
        return PlanConstraint(tuple(takes))

    def take(self, line: str) -> None:
        """Run the line the model wrote (one :meth:`next_lines` offered)."""
        # Whether it goes where the plan has been is not asked again: the
        # grammar offers a vessel's fills together, decided by the first
        # liquid, so 'fillLiquid Mug_1 coffee' may repeat a fill of coffee.
        ran = self._run(line, places=False)
        if ran is None:
            # The grammar offered only lines that run: a line that does not is
            # a fault of this module, not of the model.
            raise RuntimeError(f"the plan line {line!r} was offered but does not run")
        place, self._previous = ran
        undo = self._back is not None and place.same(self._back)
        self._back = None if undo else self._place
        self._state, self._place = place.state, place
        self._been.append(place)
        self.lines.append(line)

    def accepts(self, line: str) -> bool:
        """Whether the tutor lets ``line`` follow the lines so far (always,
        without a tutor)."""
        return self._judge is None or self._judge((*self.lines, line))

    def _run(self, line: str, places: bool = True) -> tuple[_Place, PlanStep] | None:
        n = len(self.lines) + 1
        try:
            step = parse_line(line, n, n, self._previous)
        except InputError:
            return None
        resolved = self._sim.resolve(self._state, step)
        if not isinstance(resolved, ResolvedStep):
            return None
        after = self._sim.apply(self._state, resolved)
        if isinstance(after, PreconditionFailure):
            return None
        now = self._place
        delta = [f for f in changed(self._state, after) if f.predicate != "isLocated"]
        place = _Place(now.world ^ _fold(delta), after)
        if not places:
            return place, step
        if not delta:
            return None  # nothing changed
        if self._back is not None and place.same(self._back):
            return place, step  # undoing the last line, once
        if any(place.same(been) for been in self._been):
            return None  # back where the plan has been
        return place, step


@dataclass(frozen=True)
class _Place:
    """Where a plan is: its world (the facts but for which objects the robot
    has found, a record of where it has been) as a hash, with the state to
    confirm it.  Where the robot stands is a fact of the world (``isNear``)."""

    world: int
    state: WorldState

    def same(self, other: _Place) -> bool:
        return self.world == other.world and (
            self.state is other.state or _world(self.state) == _world(other.state)
        )


def _world(state: WorldState) -> frozenset[Fact]:
    return frozenset(f for f in state.facts if f.predicate != "isLocated")


def _fold(facts: Iterable[Fact]) -> int:
    """A hash of a set of facts that a change updates: the XOR of theirs."""
    out = 0
    for f in facts:
        out ^= hash(f)
    return out


def _line(verb: str, name: str) -> str:
    # A fill runs or not whatever the liquid (the grammar then offers each).
    return f"{verb} {name} {LIQUIDS[0]}" if verb == "fillLiquid" else f"{verb} {name}"
