"""Public API: load the knowledge base once, verify scene + plan pairs.

>>> tutor = LogicTutor()                      # kitchen scenario, fast engine
>>> report = tutor.verify_files("examples/walkthrough/scene.json",
...                             "examples/walkthrough/plan.txt")
>>> report.status, report.dangerous_step
('UNSAFE', 7)
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import Any

from virf.errors import InputError
from virf.ontology.tbox import TBox, load_tbox
from virf.reasoning import Engine, make_engine
from virf.schema import Report
from virf.verify.verifier import Verifier
from virf.world.plan import PlanStep, check_plan_size, load_plan_file, parse_plan
from virf.world.scene import Scene, build_scene, load_scene_data, load_scene_file

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
    """The verifier with its knowledge base and engine loaded.

    ``explain=False`` leaves the minimal explanations out of the reports
    (batch runs that only need verdicts; the verdicts are the same)."""

    def __init__(
        self,
        scenario: str | None = None,
        engine: str = DEFAULT_ENGINE,
        timeout_s: float = 120.0,
        workers: int = 1,
        *,
        explain: bool = True,
        kb: str | Path | None = None,
    ) -> None:
        """``kb``: a knowledge workspace (``virf kb init``) whose accepted
        axioms are added to the built-in TBox.  ``scenario`` defaults to the
        workspace's with ``kb``, else to the kitchen."""
        # Checked before the knowledge base loads: a bad option fails in milliseconds.
        timeout_s = check_timeout(timeout_s)
        workers = check_workers(workers)
        tbox = load_tbox(scenario, kb=kb)
        self._attach(
            tbox, make_engine(engine, tbox, timeout_s=timeout_s), timeout_s, workers, explain
        )

    @classmethod
    def over(
        cls,
        tbox: TBox,
        engine: Engine | str = DEFAULT_ENGINE,
        *,
        timeout_s: float = 120.0,
        workers: int = 1,
        explain: bool = True,
    ) -> LogicTutor:
        """A tutor over a TBox already loaded (e.g. one with extra modules).

        Given an :class:`Engine` rather than a name, the tutor uses that very
        engine, so several tutors can share one (and its statistics)."""
        timeout_s = check_timeout(timeout_s)
        workers = check_workers(workers)
        if isinstance(engine, str):
            engine = make_engine(engine, tbox, timeout_s=timeout_s)
        tutor = cls.__new__(cls)
        tutor._attach(tbox, engine, timeout_s, workers, explain)
        return tutor

    def restricted(self, uscs: Collection[str]) -> LogicTutor:
        """This tutor checking only the Unsafe State Concepts ``uscs`` (by
        name): the knowledge-source ablations.  The knowledge base and the
        engine are shared, not loaded again."""
        unknown = sorted(set(uscs) - set(self.tbox.vocabulary.uscs))
        if unknown:
            raise InputError(f"not an Unsafe State Concept: {unknown[0]}")
        tutor = type(self).__new__(type(self))
        tutor._attach(
            self.tbox, self.engine, self.timeout_s, self.workers, self.explain, frozenset(uscs)
        )
        return tutor

    def _attach(
        self,
        tbox: TBox,
        engine: Engine,
        timeout_s: float,
        workers: int,
        explain: bool,
        uscs: frozenset[str] | None = None,
    ) -> None:
        self.tbox: TBox = tbox
        self.engine: Engine = engine
        self.timeout_s = timeout_s
        self.workers = workers
        self.explain = explain
        self.verifier = Verifier(
            tbox, engine, timeout_s=timeout_s, explain=explain, workers=workers, uscs=uscs
        )

    def scene(self, data: dict[str, Any] | str | Path, *, strict_vocabulary: bool = False) -> Scene:
        """The scene ``data`` (scene-file JSON, or a file's path) describes.
        A class the knowledge base lacks is an open-world object, unless
        ``strict_vocabulary``, which refuses it."""
        if isinstance(data, dict):
            return build_scene(data, self.tbox.vocabulary, strict_vocabulary=strict_vocabulary)
        if isinstance(data, str | Path):
            if not strict_vocabulary:
                return load_scene_file(data, self.tbox.vocabulary)
            p = Path(data)
            return build_scene(
                load_scene_data(p),
                self.tbox.vocabulary,
                name=p.stem if p.stem != "scene" else p.parent.name,
                strict_vocabulary=True,
            )
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
            check_plan_size(len(steps))
        else:
            steps = parse_plan(items)
        if not steps:
            # Nothing to verify is not a safe plan: the CLI refuses it too.
            raise InputError("plan has no actions (only blank lines or comments)")
        return self.verifier.verify(sc, steps)  # type: ignore[arg-type]

    def verify_files(self, scene_path: str | Path, plan_path: str | Path) -> Report:
        return self.verifier.verify(self.scene(scene_path), load_plan_file(plan_path))


def check_knowledge_base(
    scenario: str | None = None, kb: str | Path | None = None
) -> dict[str, Any]:
    """``virf kb check``: the reference reasoner's verdict on the TBox (starts
    the JVM) and what the fast engine makes of it."""
    from virf.ontology import check
    from virf.reasoning.program import fragment_summary

    result = check.check_tbox(scenario, kb)
    result["fast_engine"] = fragment_summary(load_tbox(scenario, kb=kb))
    return result
