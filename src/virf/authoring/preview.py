"""Effect preview: the verdicts a candidate would change if accepted.

Every bundled example (a folder of ``<name>/scene.json`` + ``plan.txt``) and
every task of a benchmark file is verified twice, with the workspace as it
is and with the candidate added; the items whose verdict or violated concept
differ are the preview.  Explanations are left out: verdicts are the same
without them, and the preview is about verdicts.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from virf.api import LogicTutor
from virf.authoring.models import Preview, PreviewChange
from virf.errors import VirfError
from virf.migrations import now
from virf.ontology.tbox import load_tbox

if TYPE_CHECKING:
    from virf.authoring.workspace import Workspace


def _verdict(status: str, concept: str | None) -> str:
    return f"{status} ({concept})" if concept else status


def effect_preview(
    ws: Workspace,
    module: Path,
    axiom: str,
    *,
    tasks: Path | None = None,
    examples: Path | None = None,
) -> Preview:
    from virf.bench.runner import run_task
    from virf.bench.safeagentbench import load_tasks
    from virf.world.plan import load_plan_file

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
    return Preview(
        axiom=axiom,
        examples=counted,
        tasks=len(task_list),
        tasks_file=str(tasks) if tasks is not None else None,
        changes=tuple(changes),
        computed_at=now(),
    )
