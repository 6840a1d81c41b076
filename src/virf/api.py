"""Public API: load the knowledge base once, verify scene + plan pairs.

>>> tutor = LogicTutor()                      # kitchen scenario, fast engine
>>> report = tutor.verify_files("examples/walkthrough/scene.json",
...                             "examples/walkthrough/plan.txt")
>>> report.status, report.dangerous_step
('UNSAFE', 7)
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from virf.errors import InputError
from virf.kb.scene import Scene, build_scene, load_scene_file
from virf.kb.tbox import DEFAULT_SCENARIO, TBox, load_tbox
from virf.reasoning import Engine, make_engine
from virf.schema import Report
from virf.sim.plan import PlanStep, load_plan_file, parse_plan
from virf.verify.verifier import Verifier

DEFAULT_ENGINE = "fast"


class LogicTutor:
    """The verifier with its knowledge base and engine loaded."""

    def __init__(
        self,
        scenario: str = DEFAULT_SCENARIO,
        engine: str = DEFAULT_ENGINE,
        timeout_s: float = 120.0,
        workers: int = 1,
    ) -> None:
        self.tbox: TBox = load_tbox(scenario)
        self.engine: Engine = make_engine(engine, self.tbox, timeout_s=timeout_s)
        self.verifier = Verifier(self.tbox, self.engine, timeout_s=timeout_s, workers=workers)

    def scene(self, data: dict[str, Any] | str | Path) -> Scene:
        if isinstance(data, dict):
            return build_scene(data, self.tbox.vocabulary)
        return load_scene_file(data, self.tbox.vocabulary)

    def verify(
        self, scene: Scene | dict[str, Any], plan: Sequence[str] | Sequence[PlanStep]
    ) -> Report:
        sc = scene if isinstance(scene, Scene) else self.scene(scene)
        if isinstance(plan, str):  # a str is a Sequence[str] of characters
            raise InputError("plan must be a list of action lines, not one string")
        steps = (
            tuple(plan)
            if all(isinstance(p, PlanStep) for p in plan)
            else parse_plan([str(p) for p in plan])
        )
        if not steps:
            # Nothing to verify is not a safe plan: the CLI refuses it too.
            raise InputError("plan has no actions (only blank lines or comments)")
        return self.verifier.verify(sc, steps)  # type: ignore[arg-type]

    def verify_files(self, scene_path: str | Path, plan_path: str | Path) -> Report:
        return self.verifier.verify(self.scene(scene_path), load_plan_file(plan_path))
