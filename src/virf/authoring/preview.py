"""Effect preview: the verdicts a candidate would change if accepted.

Every bundled example (a folder of ``<name>/scene.json`` + ``plan.txt``) and
every task of a benchmark file is verified twice, with the workspace as it
is and with the candidate added; the items whose verdict or violated concept
differ are the preview.  Explanations are left out: verdicts are the same
without them, and the preview is about verdicts.

A class learned from answers also has the scene it was learned from verified
again, without the answers (with the class known, it should need none), and
``virf kb test`` run with and without the candidate: a failure only the
candidate brings is listed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from virf.api import LogicTutor
from virf.authoring import layers
from virf.authoring.checks import check_row, current_axiom
from virf.authoring.models import Preview, PreviewChange
from virf.errors import InputError, VirfError, clip
from virf.files import write_atomically
from virf.migrations import now
from virf.ontology.tbox import load_tbox

if TYPE_CHECKING:
    from virf.authoring.workspace import Workspace


def preview(
    ws: Workspace,
    cid: int,
    axiom: str | None = None,
    tasks: Path | None = None,
    examples: Path | None = None,
) -> Preview:
    """The effect preview of candidate ``cid`` with ``axiom`` (else the axiom
    checked last), which must pass its checks; stored as its latest preview."""
    row = ws.store.candidate(cid)
    ws.store.undecided(cid)
    if examples is not None and not examples.is_dir():
        raise InputError(f"examples folder {clip(str(examples))} does not exist")
    if tasks is not None and not tasks.is_file():
        raise InputError(f"benchmark file {clip(str(tasks))} does not exist")
    text = axiom if axiom is not None else current_axiom(ws.store, cid, row.axiom)
    report = check_row(ws, row, text)
    if not report.passed:
        failed = next(i for i in report.items if i.severity == "error")
        raise InputError(f"candidate {cid} does not pass its checks: {failed.message}")
    ws.cache_dir.mkdir(exist_ok=True)
    module = ws.cache_dir / f"preview-{cid}.omn"
    write_atomically(module, layers.candidate_module(ws.layout, report.module_text))
    scenes: list[tuple[str, dict[str, Any], tuple[str, ...]]] = []
    if row.origin == "answer":
        from virf.authoring.learned import learned_of

        learned = learned_of(row)
        scenes.append(
            (f"scene {learned.scene_name} (learned from)", row.draft["scene"], learned.plan)
        )
    result = effect_preview(
        ws,
        module,
        text,
        tasks=tasks,
        examples=examples,
        scenes=scenes,
        kb_test=row.origin == "answer",
    )
    ws.store.add_preview(cid, text, result.model_dump(mode="json"))
    return result


def _verdict(status: str, concept: str | None) -> str:
    return f"{status} ({concept})" if concept else status


def effect_preview(
    ws: Workspace,
    module: Path,
    axiom: str,
    *,
    tasks: Path | None = None,
    examples: Path | None = None,
    scenes: Sequence[tuple[str, Mapping[str, Any], Sequence[str]]] = (),
    kb_test: bool = False,
) -> Preview:
    """``scenes`` are further (label, scene data, plan) items; ``kb_test``
    runs ``virf kb test`` with and without the candidate."""
    from virf.bench.runner import run_task
    from virf.bench.safeagentbench import load_tasks
    from virf.world.plan import load_plan_file, parse_plan

    before = LogicTutor(ws.scenario, explain=False, kb=ws.root)
    after = LogicTutor.over(
        load_tbox(ws.scenario, extra_modules=(str(module),), kb=ws.root), "fast", explain=False
    )
    changes: list[PreviewChange] = []
    cases = sorted(p.parent for p in examples.glob("*/plan.txt")) if examples else []
    counted = 0
    for case in cases:
        try:
            plan = load_plan_file(case / "plan.txt")
            a = before.verifier.verify(before.scene(case / "scene.json"), plan)
            b = after.verifier.verify(after.scene(case / "scene.json"), plan)
        except VirfError:
            continue  # an example this scenario cannot read says nothing about the axiom
        counted += 1
        va = _verdict(a.status, a.violations[0].id if a.violations else None)
        vb = _verdict(b.status, b.violations[0].id if b.violations else None)
        if va != vb:
            changes.append(PreviewChange(item=f"example {case.name}", before=va, after=vb))
    counted_scenes = 0
    for label, data, lines in scenes:
        try:
            plan = parse_plan(list(lines))
            a = before.verifier.verify(before.scene(dict(data)), plan)
            b = after.verifier.verify(after.scene(dict(data)), plan)
        except VirfError as exc:
            changes.append(PreviewChange(item=label, before="?", after=f"cannot verify: {exc}"))
            continue
        counted_scenes += 1
        va = _verdict(a.status, a.violations[0].id if a.violations else None)
        vb = _verdict(b.status, b.violations[0].id if b.violations else None)
        if va != vb:
            changes.append(PreviewChange(item=label, before=va, after=vb))
    task_list = load_tasks(tasks) if tasks is not None else []
    for task in task_list:
        ra = run_task(task, before.verifier, None, None)
        rb = run_task(task, after.verifier, None, None)
        va, vb = (
            _verdict(str(ra.status), ra.violated_concept),
            _verdict(str(rb.status), rb.violated_concept),
        )
        if va != vb:
            changes.append(
                PreviewChange(
                    item=f"{Path(task.file).name}:{task.line}",
                    instruction=task.instruction,
                    before=va,
                    after=vb,
                    concept=rb.violated_concept,
                )
            )
    summary, added = _kb_test(before, after) if kb_test else (None, ())
    return Preview(
        axiom=axiom,
        examples=counted,
        tasks=len(task_list),
        tasks_file=str(tasks) if tasks is not None else None,
        changes=tuple(changes),
        computed_at=now(),
        scenes=counted_scenes,
        kb_test=summary,
        kb_test_failures=added,
    )


def _kb_test(before: LogicTutor, after: LogicTutor) -> tuple[str, tuple[str, ...]]:
    """``virf kb test`` (minimal pairs, and the sweeps where the household
    rules are loaded) with and without the candidate: a summary line and the
    failures only the candidate brings."""
    from virf.verify.kbtest import run_kb_test
    from virf.verify.sweeps import HOUSEHOLD_MODULE

    sweeps = any(u.module == HOUSEHOLD_MODULE for u in after.tbox.vocabulary.uscs.values())

    def failures(tutor: LogicTutor) -> tuple[set[str], int, int]:
        result = run_kb_test(tutor.tbox, tutor.engine, sweeps=sweeps)
        found = {f"{p.rule} pair {p.index}: {p.problem}" for p in result.failures}
        found |= {
            f"sweep {s.sweep} {s.case}: expected {s.expected}, got {s.got}" for s in result.sweeps
        }
        return found, len(result.pairs), result.sweep_cases

    old, _, _ = failures(before)
    new, pairs, cases = failures(after)
    added = tuple(sorted(new - old))
    swept = f" and {cases} sweep cases" if sweeps else ""
    summary = (
        f"virf kb test with the candidate: {pairs} minimal pairs{swept}, {len(new)} failing "
        f"({len(old)} without it)"
    )
    return summary, added
