"""A checkable case: a plan, the scene it runs in and the requirements it
must meet, named.  Every benchmark verifies cases: the SafeAgentBench tasks'
(:meth:`virf.bench.safeagentbench.Task.to_case`) and the latency bench's
synthetic ones."""

from __future__ import annotations

from dataclasses import dataclass

from virf.schema import Report
from virf.verify.requirements import Requirement, Unreadable
from virf.verify.verifier import Verifier
from virf.world.plan import PlanStep
from virf.world.scene import Scene


@dataclass(frozen=True)
class Case:
    name: str
    scene: Scene
    plan: tuple[PlanStep, ...]
    requirements: tuple[Requirement | Unreadable, ...] = ()

    def verify(self, verifier: Verifier) -> Report:
        return verifier.verify(self.scene, self.plan, self.requirements)
