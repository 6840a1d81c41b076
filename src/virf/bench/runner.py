"""Run the Logic Tutor over SafeAgentBench tasks: one :class:`TaskResult` per
task, with the documented label corrections and notes applied, and the plans
given for tasks that ship none.  The figures are :mod:`virf.bench.summary`'s.

A report says what kind of problem it found (:func:`virf.verify.findings.problem`):
a hazard, or a step the plan cannot run (a failed precondition, an object the
scene lacks, a plan-logic rule).  Both block the plan; a result keeps the two
apart (:attr:`TaskResult.hazard`, :attr:`TaskResult.not_executable`).
"""

from __future__ import annotations

import dataclasses
import time
from collections import defaultdict
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar

from pydantic import Field

from virf.bench.goals import check_goals
from virf.bench.metrics import detected, not_executable
from virf.bench.safeagentbench import Task, UnparsedPlan, load_task_files
from virf.errors import InputError, Record, Says, parse_json, read_input_file
from virf.ontology.tbox import Vocabulary
from virf.verify.requirements import Requirement
from virf.verify.verifier import Verifier
from virf.world.plan import PlanStep
from virf.world.simulate import simulate
from virf.world.simulator import Simulator, WorldState


@dataclass(frozen=True)
class TaskResult:
    file: str
    line: int
    source_index: int | None
    instruction: str
    label: str
    corrected_label: str  # safe | unsafe | exclude
    category: str | None
    status: str | None  # None: no plan to verify
    dangerous_step: int | None
    violated_concept: str | None
    concept_category: str | None
    goal_satisfied: bool | None
    reason: str
    time_ms: float
    requirement: str | None = None
    requirement_parsed: bool | None = None
    requirement_reading: str | None = None
    long_horizon: bool = False
    scene: str | None = None  # the floor plan, e.g. FloorPlan301
    room: str = "kitchen"  # the room's scenario name (see safeagentbench.ROOMS)
    scenario: str = "kitchen"  # the scenario that verified the plan
    correction_reason: str | None = None
    note: str | None = None  # why the verdict differs from the label (bundled notes)
    # The report's kind of problem: "hazard" or "not-executable" (None: SAFE,
    # ERROR or no plan); for a step the plan cannot run, the action and
    # whether AI2-THOR itself would refuse it (None: a hazard, or unsaid).
    problem: str | None = None
    action: str | None = None
    ai2thor_refuses: bool | None = None

    @property
    def hazard(self) -> bool:
        """The plan is flagged with a hazard (what recall and false alarms count)."""
        return detected(self.status, self.problem)

    @property
    def not_executable(self) -> bool:
        """The plan is flagged because a step of it cannot run (before any hazard)."""
        return not_executable(self.status, self.problem)

    @property
    def outcome(self) -> str:
        """hazard | not-executable | safe | error | none (no plan verified)."""
        if self.hazard:
            return "hazard"
        if self.not_executable:
            return "not-executable"
        return {"SAFE": "safe", None: "none"}.get(self.status, "error")

    def public(self) -> dict[str, object]:
        out = asdict(self)
        out["time_ms"] = round(self.time_ms, 1)
        return out


def default_corrections_path() -> Path:
    return Path(
        str(resources.files("virf.bench").joinpath("data/safeagentbench_label_corrections.json"))
    )


class TaskNote(Record):
    """A task of a benchmark file and why its verdict differs from its label,
    when the label stands (``notes``): the reader learns the cause, not only
    the verdict.  A :class:`Correction` is a note that also changes the label."""

    when_unknown_key = "{where}: unknown key '{key}'{closest}; expected {expected}"
    located_as = "{what}: {path}"

    file: str
    source_index: Annotated[int, Field(ge=0)]
    line: Annotated[int, Field(ge=1)] | None = None
    # The task's floor plan: source indices restart in each split (kitchens,
    # other rooms), so file and index alone may name two tasks.
    scene: str | None = None
    reason: Annotated[str, Field(min_length=1)]


class Correction(TaskNote):
    """One documented label correction (the bundled file holds the real ones)."""

    label: Literal["safe", "unsafe"]
    corrected: Annotated[
        Literal["safe", "unsafe", "exclude"],
        # The task, not the entry's index, is what a reader of the file knows.
        Says(
            "{what}: correction for {record[file]}:{record[line]} "
            "needs corrected = safe|unsafe|exclude"
        ),
    ]
    relation: str | None = None
    twin: str | None = None


class CorrectionsFile(Record):
    when_not_object = "{where} must be a JSON object with a 'corrections' list"
    when_unknown_key = "{where}: unknown key '{key}'{closest}; expected {expected}"

    description: str = ""
    corrections: Annotated[list[Correction], Field(default_factory=list)]
    notes: Annotated[list[TaskNote], Field(default_factory=list)]


CorrectionKey = tuple[str, int, str | None]
V = TypeVar("V")


def load_annotations(
    path: str | Path | None,
) -> tuple[dict[CorrectionKey, dict[str, Any]], dict[CorrectionKey, str]]:
    """The corrections file read once: (file name, source_index, floor plan)
    -> correction record (as the file writes it), and -> note (why the
    verdict differs from a label that stands).  A record without a floor plan
    applies to that index in any."""
    if path is None:
        return {}, {}
    data = parse_json(read_input_file(path, "label corrections"), f"label corrections {path}")
    checked = CorrectionsFile.parse(data, str(path))
    corrections: dict[CorrectionKey, dict[str, Any]] = {}
    for c, raw in zip(checked.corrections, data.get("corrections", []), strict=True):
        key = (Path(c.file).name, c.source_index, c.scene)
        if key in corrections:
            raise InputError(
                f"{path}: two corrections for {c.file}:{c.line or c.source_index} "
                f"({c.scene or 'any floor plan'}); keep one"
            )
        corrections[key] = raw
    notes = {(Path(n.file).name, n.source_index, n.scene): n.reason for n in checked.notes}
    return corrections, notes


def load_corrections(path: str | Path | None) -> dict[CorrectionKey, dict[str, Any]]:
    return load_annotations(path)[0]


def load_notes(path: str | Path | None) -> dict[CorrectionKey, str]:
    return load_annotations(path)[1]


def correction_for(task: Task, corrections: Mapping[CorrectionKey, V]) -> V | None:
    """The task's entry (a correction, a note): the one for its floor plan,
    else the one for its index in any floor plan."""
    idx = task.data.get("source_index")
    if not isinstance(idx, int):
        return None
    name = Path(task.file).name
    return corrections.get((name, idx, task.scene_name)) or corrections.get((name, idx, None))


class PlanLine(Record):
    """One line of a ``--plans`` file."""

    # Every problem of a line gets the one message that shows the whole format.
    when_not_object = '{what}: expected {{"file": ..., "line": N, "plan": [...]}}'
    when_missing = when_not_object
    when_unknown_key = when_not_object

    file: Annotated[str, Says(when_not_object)]
    line: Annotated[int, Says(when_not_object)]
    plan: Annotated[list[str], Says(when_not_object)]


def load_plans(path: str | Path | None) -> dict[tuple[str, int], list[str]]:
    """Plans for tasks that have none (long-horizon): JSON lines with ``file``,
    ``line`` (1-based) and ``plan`` (a list of action strings)."""
    if path is None:
        return {}
    out = {}
    for i, raw in enumerate(read_input_file(path, "plans").splitlines(), start=1):
        if not raw.strip():
            continue
        where = f"{path}:{i}"
        try:
            data = parse_json(raw, where)
        except InputError:
            data = None  # reported as the line's format, as any other problem
        rec = PlanLine.parse(data, where)
        out[(Path(rec.file).as_posix(), rec.line)] = list(rec.plan)
    return out


def match_plans(
    tasks: Sequence[Task], plans: Mapping[tuple[str, int], list[str]]
) -> dict[tuple[str, int], list[str]]:
    """The plans keyed by the task they are for: a plan's ``file`` is the
    name the reports give the file, its path, or its bare name when no other
    file has that name.  A plan no task matches, or that two tasks match, is
    an input error."""
    names: dict[str, set[str]] = defaultdict(set)
    for t in tasks:
        names[Path(t.file).name].add(t.file)
    lines = {(t.file, t.line) for t in tasks}
    out: dict[tuple[str, int], list[str]] = {}
    for (given, line), plan in plans.items():
        known = {t.file for t in tasks}
        files = {given} & known
        if not files:  # a longer path to the file: its longest matching name
            tails = [f for f in known if given.endswith("/" + f)]
            files = {f for f in tails if len(f) == max(map(len, tails))}
        if not files and len(names.get(Path(given).name, ())) == 1:
            files = set(names[Path(given).name])
        found = sorted(f for f in files if (f, line) in lines)
        if not found:
            raise InputError(
                f"--plans names a task that is not among the files: {given} line {line}"
            )
        if len(found) > 1:
            raise InputError(
                f"--plans: '{given}' line {line} names a task in {' and '.join(found)}; "
                "write the file as the report names it"
            )
        out[(found[0], line)] = plan
    return out


def final_world(sim: Simulator, scene_state: WorldState, plan: Sequence[PlanStep]) -> WorldState:
    return simulate(sim, scene_state, plan).final


def run_task(
    task: Task,
    verifier: Verifier,
    plan_override: list[str] | None,
    correction: Mapping[str, Any] | None,
) -> TaskResult:
    vocab: Vocabulary = verifier.vocab
    started = time.perf_counter()
    req = task.requirement(vocab)
    parsed: bool | None = None
    reading: str | None = None
    if req is not None:
        parsed = isinstance(req, Requirement)
        reading = req.describe() if isinstance(req, Requirement) else f"unreadable: {req.reason}"
    steps = plan_override if plan_override is not None else task.steps
    status = violated = concept_cat = problem = action = None
    refuses: bool | None = None
    dangerous: int | None = None
    goal: bool | None = None
    reason = "no plan given (long-horizon tasks ship none; pass --plans)" if not steps else ""
    if steps:
        try:
            case = task.to_case(vocab, plan_override)
        except UnparsedPlan as exc:
            status, reason = "ERROR", f"reference plan does not parse: {exc}"
        else:
            report = case.verify(verifier)
            status, dangerous, reason = report.status, report.dangerous_step, report.reason
            problem, action = report.problem, report.action
            if report.violations:
                violated = report.violations[0].id
                concept_cat = report.violations[0].category
                refuses = report.violations[0].ai2thor_refuses
            if task.final_state is not None:
                world = final_world(verifier.sim, verifier.sim.initial(case.scene), case.plan)
                goal = check_goals(task.final_state, world, vocab).satisfied
    elapsed = (time.perf_counter() - started) * 1000
    source_index = task.data.get("source_index")
    corrected = str(correction["corrected"]) if correction else task.label
    return TaskResult(
        file=task.file,
        line=task.line,
        source_index=int(source_index) if isinstance(source_index, int) else None,
        instruction=task.instruction,
        label=task.label,
        corrected_label=corrected,
        category=task.category,
        status=status,
        dangerous_step=dangerous,
        violated_concept=violated,
        concept_category=concept_cat,
        goal_satisfied=goal,
        reason=reason,
        time_ms=elapsed,
        requirement=None if req is None else req.text,
        requirement_parsed=parsed,
        requirement_reading=reading,
        long_horizon=task.is_long_horizon,
        scene=task.scene_name,
        room=task.room.name,
        scenario=verifier.tbox.scenario,
        correction_reason=str(correction["reason"]) if correction else None,
        problem=problem,
        action=action,
        ai2thor_refuses=refuses,
    )


def run_benchmark(
    paths: Iterable[str | Path],
    verifier: Verifier | Callable[[Task], Verifier],
    plans: dict[tuple[str, int], list[str]] | None = None,
    corrections: Mapping[CorrectionKey, dict[str, Any]] | None = None,
    on_task: Callable[[TaskResult], None] | None = None,
    tasks: list[Task] | None = None,
    notes: Mapping[CorrectionKey, str] | None = None,
) -> list[TaskResult]:
    """Verify every task's reference plan.  ``verifier`` is one verifier for
    every task, or a function giving the verifier of a task (its room's
    scenario)."""
    plans = plans or {}
    corrections = corrections or {}
    if tasks is None:
        tasks = load_task_files(paths)
    verifier_for = (lambda _task: verifier) if isinstance(verifier, Verifier) else verifier
    results = []
    plans = match_plans(tasks, plans)
    for task in tasks:
        corr = correction_for(task, corrections)
        plan = plans.get((task.file, task.line))
        result = run_task(task, verifier_for(task), plan, corr)
        note = correction_for(task, notes or {})
        if note is not None:
            result = dataclasses.replace(result, note=str(note))
        results.append(result)
        if on_task:
            on_task(result)
    return results
