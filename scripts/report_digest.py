"""Print one line per verified plan: its name and a digest of its whole report.

A refactoring that promises byte-identical reports is checked by running this
before and after and diffing the two outputs.  Each digest covers the report's
JSON, its terminal text and the feedback prompt built from it, for every
bundled example and every SafeAgentBench dev plan (when the split is present).

    .venv/bin/python scripts/report_digest.py [SAB_DIR] > before.txt
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

from virf.api import LogicTutor
from virf.bench.safeagentbench import UnparsedPlan, load_tasks
from virf.render.feedback import feedback_prompt
from virf.render.text import render_report
from virf.schema import Report


def digest(report: Report) -> str:
    blob = "\x00".join((report.to_json(), render_report(report), feedback_prompt(report)))
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def main() -> None:
    root = Path(__file__).resolve().parent.parent
    sab = (
        Path(sys.argv[1]) if len(sys.argv) > 1 else root.parent / "shared/benchmarks/safeagentbench"
    )
    tutor = LogicTutor()
    for example in sorted((root / "examples").iterdir()):
        if (example / "scene.json").is_file() and (example / "plan.txt").is_file():
            report = tutor.verify_files(example / "scene.json", example / "plan.txt")
            print(f"example/{example.name} {report.status} {digest(report)}")
    for path in sorted(sab.rglob("*.jsonl")) if sab.is_dir() else []:
        for task in load_tasks(path):
            if not task.steps:
                continue
            name = f"{path.relative_to(sab)}:{task.line}"
            try:
                case = task.to_case(tutor.tbox.vocabulary)
            except UnparsedPlan as exc:
                print(f"{name} PARSE {hashlib.sha256(str(exc).encode()).hexdigest()[:16]}")
                continue
            report = tutor.verify(case.scene, case.plan)
            print(f"{name} {report.status} {digest(report)}")


if __name__ == "__main__":
    main()
