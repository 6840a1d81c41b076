"""The SmolLM2 runs shipped in examples/agents/smollm2 re-render the tables
that docs/agents.md prints for them.

The recordings are replayed over the dev split, as `make agents-report` does.
Every figure that does not measure the tutor anew must equal the documented
one: the master and time tables without their verifier columns (a replay
keeps each call's recorded time and tokens), and how the tasks ended.  A
change to the tutor, the simulator or the knowledge that moves a real-model
figure thus fails here until the document is brought up to date.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from bench_support import SAB, bench_agents, needs_shared
from conftest import ROOT

RECORDINGS = ROOT / "examples" / "agents" / "smollm2"
DOC = ROOT / "docs" / "agents.md"
METHODS = "impulsive,impulsive+rules,thinker+diagnostic,virf-reject,virf"
FILES = ("unsafe_detailed", "safe_detailed", "abstract", "long_horizon")

CONSTRAINED = "impulsive,virf"

# (recording, folder of the split, sample, heading of its section in the
# document, the methods recorded)
ROOMS = [
    ("kitchen", SAB, 1, "### Kitchens", METHODS),
    ("other-rooms", SAB / "other_rooms", 4, "### Living rooms, bedrooms and bathrooms", METHODS),
    (
        "kitchen-constrained",
        SAB,
        4,
        "### Constrained decoding and checked corrections",
        CONSTRAINED,
    ),
    ("kitchen-focused", SAB, 4, "### Focused grammar and numbered corrections", CONSTRAINED),
    ("kitchen-stepwise", SAB, 4, "### A line at a time: kitchens", CONSTRAINED),
    ("kitchen-stepwise-all", SAB, 1, "### A line at a time: all 190 kitchen tasks", CONSTRAINED),
    (
        "other-rooms-stepwise",
        SAB / "other_rooms",
        4,
        "### A line at a time: living rooms, bedrooms and bathrooms",
        CONSTRAINED,
    ),
]


def makefile_every(recording: str) -> int:
    """The --every of `make agents-report`'s command for ``recording`` (1 if none)."""
    recipe = (ROOT / "Makefile").read_text(encoding="utf-8").split("agents-report:", 1)[1]
    command = next(c for c in recipe.split("--out") if f"{recording}.replay.jsonl" in c)
    found = re.search(r"--every (\d+)", command)
    return int(found.group(1)) if found else 1


def section(text: str, heading: str) -> str:
    start = text.index(heading + "\n")
    after = re.search(r"^#{1,3} ", text[start + len(heading) :], flags=re.MULTILINE)
    return text[start : start + len(heading) + (after.start() if after else len(text))]


def rows(markdown: str, header: str) -> list[list[str]]:
    """The body rows of the first table whose header line starts with ``header``."""
    lines = markdown.splitlines()
    start = next((i for i, line in enumerate(lines) if line.startswith(header)), None)
    assert start is not None, f"no table whose header starts with {header!r}"
    body = []
    for line in lines[start + 2 :]:
        if not line.startswith("|"):
            break
        body.append([cell.strip() for cell in line.strip("|").split("|")])
    return body


@needs_shared
@pytest.mark.parametrize(
    ("name", "folder", "every", "heading", "methods"), ROOMS, ids=[r[0] for r in ROOMS]
)
def test_shipped_recording_rerenders_the_documented_tables(
    name: str, folder: Path, every: int, heading: str, methods: str, tmp_path: Path
) -> None:
    assert makefile_every(name) == every, "the Makefile samples another set of tasks"
    out = tmp_path / name
    recording = RECORDINGS / f"{name}.replay.jsonl"
    files = [folder / f"{f}.jsonl" for f in FILES]
    done = bench_agents(
        "--method",
        methods,
        "--every",
        str(every),
        "--planner",
        f"replay:{recording}",
        "--tasks",
        *files,
        "--out",
        out,
    )
    assert done.returncode == 0, done.stderr
    rendered = (out / "agents.md").read_text(encoding="utf-8")
    documented = section(DOC.read_text(encoding="utf-8"), heading)

    master = "| method | tasks | HAR % |"
    assert [r[0] for r in rows(rendered, master)] == methods.split(",")
    assert [r[:-1] for r in rows(rendered, master)] == [r[:-1] for r in rows(documented, master)]
    time = "| method | model calls |"
    assert [r[:-1] for r in rows(rendered, time)] == [r[:-1] for r in rows(documented, time)]
    endings = "| method | approved at once |"
    assert rows(rendered, endings) == rows(documented, endings)
