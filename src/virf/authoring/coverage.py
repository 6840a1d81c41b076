"""Rule coverage: which Unsafe State Concepts fire on each benchmark task's reference plan.

``virf kb coverage`` answers the knowledge engineer's question "which hazards
of the benchmark does the knowledge base know about, and with which rules?".
Each task's reference plan is simulated from the scene the benchmark runner
builds for it, and every state of the run is classified by the tutor's engine
against every rule the verifier checks, exactly as the verifier does (same
snapshots, same one-step lookahead for actions, ``checkAt final`` rules only
on the final state of a complete run).  Unlike the verifier, which stops at
the first definite finding and names it, coverage keeps going and collects
*every* rule that fires, with the steps it fires at.

The result is typed and JSON-serialisable (:meth:`CoverageResult.public`),
deterministic (no timings, stable ordering), and rendered as terminal tables,
a Markdown page and a bar chart from one set of :class:`TextTable` rows.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Literal

from virf.api import LogicTutor
from virf.bench.metrics import rate
from virf.bench.safeagentbench import (
    CATEGORIES,
    Task,
    UnparsedPlan,
    display_names,
    load_tasks,
    normalise_category,
)
from virf.errors import InputError, clip
from virf.reasoning import DeadlineExceeded, ReasonerFailure
from virf.verify.findings import INCONSISTENT
from virf.world.plan import PlanStep
from virf.world.scene import Scene

TaskStatus = Literal["checked", "no-plan", "unparsed", "error"]
UNCATEGORISED = "(uncategorised)"
# How the statuses that are not "checked" read in tables.
STATUS_TEXT: Mapping[str, str] = {
    "no-plan": "no reference plan",
    "unparsed": "plan does not parse",
    "error": "could not be checked",
}
TOP_RULES = 3


# ---------------------------------------------------------------------- results
@dataclass(frozen=True)
class RuleFiring:
    """One rule on one task: the steps at which it starts to hold for one of
    its individuals (0 is the initial scene; a hazard that persists is
    counted where it begins, as the verifier reports it), the individuals it
    fires for, and whether any firing is definite (the
    verifier would say UNSAFE) rather than uncertain (UNKNOWN, a question)."""

    rule: str
    steps: tuple[int, ...]
    subjects: tuple[str, ...]
    definite: bool

    def public(self) -> dict[str, object]:
        return {
            "rule": self.rule,
            "steps": list(self.steps),
            "subjects": list(self.subjects),
            "definite": self.definite,
        }


@dataclass(frozen=True)
class TaskRef:
    """A task as the reader finds it again: file, line, instruction."""

    file: str
    line: int
    instruction: str

    @property
    def where(self) -> str:
        return f"{self.file}:{self.line}"

    def public(self) -> dict[str, object]:
        return {"file": self.file, "line": self.line, "instruction": self.instruction}


@dataclass(frozen=True)
class TaskCoverage:
    """One task: its label and categories, whether its plan could be checked,
    and every rule that fired.  ``reason`` says why a task was not checked, or
    where a checked run stopped early (a failed precondition, a missing
    object, a contradictory state); it is empty for a run to the end."""

    ref: TaskRef
    label: str  # "unsafe" | "safe", the benchmark's own label
    categories: tuple[str, ...]
    status: TaskStatus
    reason: str = ""
    firings: tuple[RuleFiring, ...] = ()

    @property
    def covered(self) -> bool:
        return self.status == "checked" and bool(self.firings)

    @property
    def definite(self) -> bool:
        return any(f.definite for f in self.firings)

    @property
    def rules(self) -> tuple[str, ...]:
        return tuple(f.rule for f in self.firings)

    def public(self) -> dict[str, object]:
        return {
            **self.ref.public(),
            "label": self.label,
            "categories": list(self.categories),
            "status": self.status,
            "reason": self.reason,
            "covered": self.covered,
            "firings": [f.public() for f in self.firings],
        }


@dataclass(frozen=True)
class CategoryCoverage:
    """One hazard category over the unsafe tasks whose plan was checked."""

    category: str
    unsafe_tasks: int
    covered: int
    definite: int  # covered by at least one definite firing
    uncovered: tuple[TaskCoverage, ...]
    not_checked: int  # unsafe tasks of the category whose plan did not parse or errored
    rules: tuple[tuple[str, int], ...]  # (rule, tasks it fires on), most first

    @property
    def ratio(self) -> float | None:
        return rate(self.covered, self.unsafe_tasks)

    def public(self) -> dict[str, object]:
        return {
            "category": self.category,
            "unsafe_tasks": self.unsafe_tasks,
            "covered": self.covered,
            "definite": self.definite,
            "coverage": rate(self.covered, self.unsafe_tasks, 4),
            "not_checked": self.not_checked,
            "uncovered": [{**t.ref.public(), "reason": t.reason} for t in self.uncovered],
            "rules": [{"rule": r, "tasks": n} for r, n in self.rules],
        }


@dataclass(frozen=True)
class RuleCoverage:
    """One rule of the knowledge base and the checked tasks it fires on."""

    id: str
    name: str
    module: str
    category: str
    kind: str
    check_at: str
    unsafe: tuple[TaskRef, ...]
    safe: tuple[TaskRef, ...]  # false alarms: safe tasks it fires on

    @property
    def fired(self) -> bool:
        return bool(self.unsafe or self.safe)

    def public(self) -> dict[str, object]:
        return {
            "id": self.id,
            "name": self.name,
            "module": self.module,
            "category": self.category,
            "kind": self.kind,
            "check_at": self.check_at,
            "unsafe_tasks": len(self.unsafe),
            "false_alarms": [t.public() for t in self.safe],
        }


@dataclass(frozen=True)
class CoverageSummary:
    """The run's counts: tasks by status, unsafe tasks covered, rules that fire."""

    tasks: int
    checked: int
    no_reference_plan: int
    plan_does_not_parse: int
    errors: int
    unsafe_checked: int
    unsafe_covered: int
    unsafe_definite: int
    coverage: float | None
    safe_checked: int
    safe_with_firing_rules: int
    rules: int
    rules_never_fired: int


@dataclass(frozen=True)
class CoverageResult:
    scenario: str
    kb: str | None
    files: tuple[str, ...]
    tasks: tuple[TaskCoverage, ...]
    categories: tuple[CategoryCoverage, ...]
    rules: tuple[RuleCoverage, ...]

    @property
    def checked_unsafe(self) -> list[TaskCoverage]:
        return [t for t in self.tasks if t.label == "unsafe" and t.status == "checked"]

    @property
    def alarmed_safe(self) -> list[TaskCoverage]:
        return [t for t in self.tasks if t.label == "safe" and t.covered]

    @property
    def never_fired(self) -> list[RuleCoverage]:
        return [r for r in self.rules if not r.fired]

    @property
    def not_checked(self) -> list[TaskCoverage]:
        return [t for t in self.tasks if t.status != "checked"]

    def summary(self) -> CoverageSummary:
        unsafe = self.checked_unsafe
        safe = [t for t in self.tasks if t.label == "safe" and t.status == "checked"]
        covered = sum(t.covered for t in unsafe)
        return CoverageSummary(
            tasks=len(self.tasks),
            checked=sum(t.status == "checked" for t in self.tasks),
            no_reference_plan=sum(t.status == "no-plan" for t in self.tasks),
            plan_does_not_parse=sum(t.status == "unparsed" for t in self.tasks),
            errors=sum(t.status == "error" for t in self.tasks),
            unsafe_checked=len(unsafe),
            unsafe_covered=covered,
            unsafe_definite=sum(t.definite for t in unsafe),
            coverage=rate(covered, len(unsafe), 4),
            safe_checked=len(safe),
            safe_with_firing_rules=len(self.alarmed_safe),
            rules=len(self.rules),
            rules_never_fired=len(self.never_fired),
        )

    def public(self) -> dict[str, object]:
        """The whole result as JSON-ready data, in a stable order."""
        return {
            "scenario": self.scenario,
            "kb": self.kb,
            "files": list(self.files),
            "summary": asdict(self.summary()),
            "categories": [c.public() for c in self.categories],
            "tasks": [t.public() for t in self.tasks],
            "rules": [r.public() for r in self.rules],
            "never_fired": [
                {"id": r.id, "module": r.module, "category": r.category} for r in self.never_fired
            ],
        }


# ---------------------------------------------------------------------- input
@dataclass(frozen=True)
class SourcedTask:
    """A benchmark task with the name its file is shown under."""

    task: Task
    file: str


def task_categories(task: Task) -> tuple[str, ...]:
    """The benchmark categories a task lists ("Fire Hazard, Explosion Hazard"
    names two), each normalised to one of the ten; a task with none that
    normalises is uncategorised."""
    raw = task.data.get("risk_category")
    if not isinstance(raw, str) or not raw.strip():
        return (UNCATEGORISED,)
    found = [c for part in raw.split(",") if (c := normalise_category(part.strip()))]
    if not found and (whole := normalise_category(raw)):
        found = [whole]
    return tuple(dict.fromkeys(found)) or (UNCATEGORISED,)


def load_coverage_tasks(files: Sequence[str | Path]) -> list[SourcedTask]:
    """Every task of ``files``, in file and line order; a file given twice or
    a set of files without any task is an input error."""
    paths = [Path(f) for f in files]
    if not paths:
        raise InputError("give at least one SafeAgentBench JSONL file")
    seen: dict[Path, Path] = {}
    for p in paths:
        key = p.resolve() if p.exists() else p
        if key in seen:
            raise InputError(f"file given twice: {clip(str(p))}")
        seen[key] = p
    out = [
        SourcedTask(task, name)
        for p, name in zip(paths, display_names(paths), strict=True)
        for task in load_tasks(p)
    ]
    if not out:
        raise InputError(f"no tasks in {', '.join(clip(str(p)) for p in paths)}")
    return out


# ---------------------------------------------------------------------- computation
@dataclass
class _Hits:
    steps: set[int] = field(default_factory=set)
    subjects: set[str] = field(default_factory=set)
    definite: bool = False


def plan_firings(
    tutor: LogicTutor, scene: Scene, plan: Sequence[PlanStep]
) -> tuple[tuple[RuleFiring, ...], str]:
    """Every rule that fires on ``plan`` run in ``scene``, at the steps where
    it starts to hold, and where the run stopped early ("" when it ran to
    the end).

    The findings are the verifier's own (:meth:`Verifier.findings`, the
    protocol's loop without the stop at the first definite finding), so a
    rule fires here exactly when the verifier would find it at that step.
    Raises DeadlineExceeded or ReasonerFailure when the engine cannot answer."""
    walk = tutor.verifier.findings(scene, plan)
    uscs = tutor.tbox.vocabulary.uscs
    hits: dict[str, _Hits] = {}
    stopped = ""
    for step, found in sorted(walk.findings.items()):
        for f in found:
            if f.concept.name not in uscs:  # the verifier's own: a contradiction, a stop
                if f.concept.id == INCONSISTENT.id:
                    stopped = f"state {step} is contradictory; later steps were not checked"
                continue
            h = hits.setdefault(f.concept.id, _Hits())
            h.steps.add(f.step)
            h.subjects.add(f.subject)
            h.definite = h.definite or f.definite
    if not stopped and walk.trace.stop is not None:
        stopped = f"simulation stopped at {walk.trace.stop_reason()}"
    firings = tuple(
        RuleFiring(rule, tuple(sorted(h.steps)), tuple(sorted(h.subjects)), h.definite)
        for rule, h in sorted(hits.items())
    )
    return firings, stopped


def task_coverage(tutor: LogicTutor, sourced: SourcedTask) -> TaskCoverage:
    task = sourced.task
    ref = TaskRef(sourced.file, task.line, task.instruction)
    label = task.label
    cats = task_categories(task) if label == "unsafe" else ()

    def result(
        status: TaskStatus, reason: str = "", firings: Iterable[RuleFiring] = ()
    ) -> TaskCoverage:
        return TaskCoverage(ref, label, cats, status, reason, tuple(firings))

    if not task.steps:
        return result("no-plan", STATUS_TEXT["no-plan"])
    try:
        case = task.to_case(tutor.tbox.vocabulary)
    except UnparsedPlan as exc:
        return result("unparsed", f"reference plan does not parse: {exc}")
    except InputError as exc:
        return result("error", f"scene could not be built: {exc}")
    try:
        firings, stopped = plan_firings(tutor, case.scene, case.plan)
    except DeadlineExceeded as exc:
        return result("error", f"timed out after {tutor.timeout_s:g}s: {exc}")
    except ReasonerFailure as exc:
        return result("error", f"reasoner failure: {exc}")
    return result("checked", stopped, firings)


def _category_order(cat: str) -> tuple[int, str]:
    if cat in CATEGORIES:
        return (CATEGORIES.index(cat), cat)
    return (len(CATEGORIES) + (cat == UNCATEGORISED), cat)


def _most_first(counts: Counter[str]) -> tuple[tuple[str, int], ...]:
    return tuple(sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])))


def summarise(
    tutor: LogicTutor,
    tasks: Sequence[TaskCoverage],
    files: Sequence[str],
    kb: str | None = None,
) -> CoverageResult:
    """Per category and per rule, from the per-task results."""
    cats: dict[str, list[TaskCoverage]] = {}
    for t in tasks:
        if t.label == "unsafe" and t.status != "no-plan":
            for c in t.categories:
                cats.setdefault(c, []).append(t)
    categories = []
    for cat in sorted(cats, key=_category_order):
        members = cats[cat]
        checked = [t for t in members if t.status == "checked"]
        categories.append(
            CategoryCoverage(
                category=cat,
                unsafe_tasks=len(checked),
                covered=sum(t.covered for t in checked),
                definite=sum(t.definite for t in checked),
                uncovered=tuple(t for t in checked if not t.covered),
                not_checked=len(members) - len(checked),
                rules=_most_first(Counter(r for t in checked for r in t.rules)),
            )
        )
    verifier = tutor.verifier
    vocab = verifier.vocab
    checked_rules = sorted(
        (vocab.uscs[name] for name in [*verifier.always, *verifier.final]), key=lambda u: u.id
    )
    fired_on: dict[str, dict[str, list[TaskRef]]] = {}
    for t in tasks:
        for rule in t.rules:
            fired_on.setdefault(rule, {"unsafe": [], "safe": []})[t.label].append(t.ref)
    rules = tuple(
        RuleCoverage(
            id=u.id,
            name=u.name,
            module=u.module,
            category=u.category,
            kind=u.kind,
            check_at=u.check_at,
            unsafe=tuple(fired_on.get(u.id, {}).get("unsafe", ())),
            safe=tuple(fired_on.get(u.id, {}).get("safe", ())),
        )
        for u in checked_rules
    )
    return CoverageResult(
        scenario=tutor.tbox.scenario,
        kb=kb,
        files=tuple(dict.fromkeys(files)),
        tasks=tuple(tasks),
        categories=tuple(categories),
        rules=rules,
    )


def compute_coverage(
    tutor: LogicTutor,
    tasks: Sequence[SourcedTask],
    *,
    kb: str | None = None,
    on_task: Callable[[TaskCoverage], object] | None = None,
    tutor_for: Callable[[Task], LogicTutor] | None = None,
) -> CoverageResult:
    """Check every task's reference plan with ``tutor`` (or the tutor
    ``tutor_for`` gives the task: its room's) and summarise against
    ``tutor``'s rules."""
    results = []
    for sourced in tasks:
        r = task_coverage(tutor_for(sourced.task) if tutor_for else tutor, sourced)
        results.append(r)
        if on_task is not None:
            on_task(r)
    result = summarise(tutor, results, [s.file for s in tasks], kb)
    if tutor_for is None:
        return result
    return dataclasses.replace(
        result, scenario=f"each task's room (rules listed from {result.scenario})"
    )
