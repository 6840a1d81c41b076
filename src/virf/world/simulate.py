"""The one simulation loop: a plan run step by step in the sandbox.

The verifier, the benchmark runner, the agent harness and the tests all run
plans through :func:`simulate`, so they agree on where a plan stops and why.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from virf.world.plan import PlanStep
from virf.world.simulator import (
    MissingObject,
    PreconditionFailure,
    ResolvedStep,
    Simulator,
    WorldState,
)

Stop = MissingObject | PreconditionFailure


@dataclass(frozen=True)
class Trace:
    """States S0..Sn of a run, the n steps that produced them, and why the run
    stopped early (``None`` when every step ran)."""

    states: tuple[WorldState, ...]
    resolved: tuple[ResolvedStep, ...]
    stop: Stop | None = None

    @property
    def complete(self) -> bool:
        return self.stop is None

    @property
    def final(self) -> WorldState:
        return self.states[-1]

    @property
    def executed(self) -> int:
        """How many steps ran (the state after the last of them is :attr:`final`)."""
        return len(self.states) - 1

    def stop_reason(self) -> str | None:
        """One line naming the step that could not run, or ``None``."""
        stop = self.stop
        if stop is None:
            return None
        why = f"no '{stop.term}'" if isinstance(stop, MissingObject) else stop.message
        return f"step {stop.step.index} ({stop.step.text}): {why}"


def simulate(sim: Simulator, start: WorldState, plan: Sequence[PlanStep]) -> Trace:
    """Run ``plan`` from ``start`` until a step names nothing the simulator can
    act on or fails a precondition; what ran before the stop stays done."""
    states = [start]
    resolved: list[ResolvedStep] = []
    for step in plan:
        r = sim.resolve(states[-1], step)
        if isinstance(r, MissingObject):
            return Trace(tuple(states), tuple(resolved), r)
        nxt = sim.apply(states[-1], r)
        if isinstance(nxt, PreconditionFailure):
            # The step was resolved: its action facts are part of the lookahead.
            return Trace(tuple(states), (*resolved, r), nxt)
        resolved.append(r)
        states.append(nxt)
    return Trace(tuple(states), tuple(resolved), None)
