"""Public API: load the knowledge base once, verify scene + plan pairs.

>>> tutor = LogicTutor()                      # kitchen scenario, fast engine
>>> report = tutor.verify_files("examples/walkthrough/scene.json",
...                             "examples/walkthrough/plan.txt")
>>> report.status, report.dangerous_step
('UNSAFE', 7)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from virf.errors import InputError
from virf.ontology.tbox import DEFAULT_SCENARIO, TBox, load_tbox
from virf.reasoning import Engine, make_engine
from virf.schema import Report
from virf.verify.verifier import Verifier
from virf.world.plan import MAX_PLAN_STEPS, PlanStep, load_plan_file, parse_plan
from virf.world.scene import Scene, build_scene, load_scene_file

DEFAULT_ENGINE = "fast"
# A day: any longer deadline is no deadline, and the reasoners' own timers
# (milliseconds in a Java long, threading.Timer) must be able to hold it.
MAX_TIMEOUT_S = 86_400.0
# Each worker is a reasoner of its own; more than this only costs memory.
MAX_WORKERS = 64


def check_timeout(seconds: object, option: str = "timeout") -> float:
    """``seconds`` as a verification deadline, or an input error.

    NaN would never expire (every comparison with it is false), infinity is no
    deadline, and zero or a negative number would fail every plan."""
    if isinstance(seconds, bool) or not isinstance(seconds, int | float):
        raise InputError(f"{option} must be a number of seconds, not {type(seconds).__name__}")
    value = float(seconds)
    if not math.isfinite(value) or not 0 < value <= MAX_TIMEOUT_S:
        raise InputError(
            f"{option} {value:g}: give a number of seconds above 0 and at most {MAX_TIMEOUT_S:g}"
        )
    return value


def check_workers(workers: object) -> int:
    if isinstance(workers, bool) or not isinstance(workers, int):
        raise InputError(f"workers must be a whole number, not {type(workers).__name__}")
    if not 1 <= workers <= MAX_WORKERS:
        raise InputError(f"workers {workers}: give a number from 1 to {MAX_WORKERS}")
    return workers


class LogicTutor:
    """The verifier with its knowledge base and engine loaded."""

    def __init__(
        self,
        scenario: str = DEFAULT_SCENARIO,
        engine: str = DEFAULT_ENGINE,
        timeout_s: float = 120.0,
        workers: int = 1,
    ) -> None:
        # Checked before the knowledge base loads: a bad option fails in milliseconds.
        timeout_s = check_timeout(timeout_s)
        workers = check_workers(workers)
        self.tbox: TBox = load_tbox(scenario)
        self.engine: Engine = make_engine(engine, self.tbox, timeout_s=timeout_s)
        self.verifier = Verifier(self.tbox, self.engine, timeout_s=timeout_s, workers=workers)

    def scene(self, data: dict[str, Any] | str | Path) -> Scene:
        if isinstance(data, dict):
            return build_scene(data, self.tbox.vocabulary)
        if isinstance(data, str | Path):
            return load_scene_file(data, self.tbox.vocabulary)
        raise InputError(f"scene must be a dict or a file path, not {type(data).__name__}")

    def verify(
        self, scene: Scene | dict[str, Any], plan: Sequence[str] | Sequence[PlanStep]
    ) -> Report:
        sc = scene if isinstance(scene, Scene) else self.scene(scene)
        if isinstance(plan, str | bytes) or not isinstance(plan, Sequence):
            # A str is a Sequence[str] of characters; a generator would be
            # consumed by the first look at it.
            what = "one string" if isinstance(plan, str | bytes) else type(plan).__name__
            raise InputError(f"plan must be a list of action lines, not {what}")
        items = list(plan)
        if all(isinstance(p, PlanStep) for p in items):
            steps = tuple(items)
            if len(steps) > MAX_PLAN_STEPS:
                raise InputError(f"plan has more than {MAX_PLAN_STEPS} actions (the limit)")
        else:
            steps = parse_plan(items)
        if not steps:
            # Nothing to verify is not a safe plan: the CLI refuses it too.
            raise InputError("plan has no actions (only blank lines or comments)")
        return self.verifier.verify(sc, steps)  # type: ignore[arg-type]

    def verify_files(self, scene_path: str | Path, plan_path: str | Path) -> Report:
        return self.verifier.verify(self.scene(scene_path), load_plan_file(plan_path))
