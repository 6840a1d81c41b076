"""``make benchmarks``: SafeAgentBench fetched at a pinned commit and arranged
as the development split VIRF's reports use (kitchens at the top,
``other_rooms/``, each task with its upstream line as ``source_index``).
This machine has no internet, so the upstream repository is a local git
repository made here (``SAB_REPO=file://...``), laid out as upstream is:
``dataset/<type>_1009.jsonl``, every room in one file."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared" / "benchmarks" / "safeagentbench"
RECORD = json.loads((ROOT / "scripts" / "safeagentbench_split.json").read_text())
TYPES = ("unsafe_detailed", "safe_detailed", "abstract", "long_horizon")
PARTS = {"kitchens": "", "other_rooms": "other_rooms/"}

needs_git = pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")
needs_make = pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
pytestmark = [needs_git, needs_make]


def _git(where: Path, *args: str) -> str:
    done = subprocess.run(
        ["git", "-C", str(where), "-c", "user.name=test", "-c", "user.email=test@localhost",
         *args],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    return done.stdout.strip()


def _upstream(tmp: Path, task: dict[str, dict[int, dict[str, object]]]) -> tuple[str, str]:
    """A git repository laid out as upstream's: ``task[kind][line]`` is the
    task on that line of ``dataset/<kind>_1009.jsonl``, the other lines
    tasks of a held-out floor plan.  Returns its file:// URL and commit."""
    repo = tmp / "upstream-repo"
    (repo / "dataset").mkdir(parents=True)
    for kind in TYPES:
        lines = [
            json.dumps(task[kind].get(i, {"scene_name": "FloorPlan5", "instruction": f"held {i}"}))
            for i in range(max(task[kind]) + 3)
        ]
        (repo / "dataset" / f"{kind}_1009.jsonl").write_text("\n".join(lines) + "\n")
    (repo / "README.md").write_text("SafeAgentBench\n")
    _git(repo, "init", "-q")
    _git(repo, "add", "-A")
    _git(repo, "commit", "-q", "-m", "tasks")
    return repo.resolve().as_uri(), _git(repo, "rev-parse", "HEAD")


def _make(*args: str) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("MAKEFLAGS", "MFLAGS")}
    return subprocess.run(
        ["make", "--no-print-directory", "-C", str(ROOT), f"PYTHON={sys.executable}", *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )


def _synthetic() -> dict[str, dict[int, dict[str, object]]]:
    """A task on every line the split takes, named after its place."""
    return {
        kind: {
            i: {"scene_name": "FloorPlan1" if part == "kitchens" else "FloorPlan201",
                "instruction": f"{kind} {part} {i}"}
            for part in PARTS
            for i in RECORD["split"][kind][part]
        }
        for kind in TYPES
    }  # fmt: skip


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/benchmarks is not present")
def test_the_fetched_split_is_the_one_in_shared(tmp_path: Path) -> None:
    """Upstream's tasks at the lines the split records come out as the
    files in ../shared, byte for byte."""
    task: dict[str, dict[int, dict[str, object]]] = {kind: {} for kind in TYPES}
    for kind in TYPES:
        for prefix in PARTS.values():
            for line in (SHARED / f"{prefix}{kind}.jsonl").read_text().splitlines():
                row = json.loads(line)
                task[kind][row.pop("source_index")] = row
    url, commit = _upstream(tmp_path, task)
    out = tmp_path / "out"
    done = _make("benchmarks", f"SAB_REPO={url}", f"SAB_COMMIT={commit}", f"SAB_FETCHED={out}")
    assert done.returncode == 0, done.stdout + done.stderr
    assert f"the development split is in {out}" in done.stdout
    for kind in TYPES:
        for prefix in PARTS.values():
            name = f"{prefix}{kind}.jsonl"
            assert (out / name).read_bytes() == (SHARED / name).read_bytes(), name
    assert _git(out / "upstream", "rev-parse", "HEAD") == commit
    assert _make("sab-split", f"SAB={out}").returncode == 0
    # Fetching again reuses the clone and gives the same files.
    again = _make("benchmarks", f"SAB_REPO={url}", f"SAB_COMMIT={commit}", f"SAB_FETCHED={out}")
    assert again.returncode == 0, again.stderr


def test_other_tasks_are_arranged_but_refused(tmp_path: Path) -> None:
    """Tasks that are not the split's (another commit, changed files) are
    arranged the same way, and the target fails with one line saying so;
    the split check the agent report depends on refuses them too."""
    url, commit = _upstream(tmp_path, _synthetic())
    out = tmp_path / "out"
    done = _make("benchmarks", f"SAB_REPO={url}", f"SAB_COMMIT={commit}", f"SAB_FETCHED={out}")
    assert done.returncode != 0
    [line] = [x for x in done.stderr.splitlines() if x.startswith("error:")]
    assert "not the recorded development split" in line, done.stderr
    assert "Traceback" not in done.stderr
    for kind in TYPES:
        for part, prefix in PARTS.items():
            rows = [json.loads(x) for x in (out / f"{prefix}{kind}.jsonl").read_text().splitlines()]
            assert [r["source_index"] for r in rows] == RECORD["split"][kind][part]
            assert all(r["instruction"] == f"{kind} {part} {r['source_index']}" for r in rows)
            assert all(list(r)[-1] == "source_index" for r in rows)
    refused = _make("sab-split", f"SAB={out}")
    assert refused.returncode != 0
    assert "is not the development split's file" in refused.stderr
    assert _make("sab-files", f"SAB={out}").returncode == 0


@pytest.mark.parametrize(
    ("commit", "message"),
    [
        ("38ca3ab", "SAB_COMMIT must be a full 40-digit commit hash, not '38ca3ab'"),
        ("0" * 40, f"has no commit {'0' * 40}"),
    ],
)
def test_a_bad_commit_is_one_line(tmp_path: Path, commit: str, message: str) -> None:
    url, _ = _upstream(tmp_path, _synthetic())
    done = _make(
        "benchmarks", f"SAB_REPO={url}", f"SAB_COMMIT={commit}", f"SAB_FETCHED={tmp_path / 'o'}"
    )
    assert done.returncode != 0
    assert message in done.stderr and "Traceback" not in done.stderr, done.stderr


def test_without_the_files_the_reports_say_what_to_run(tmp_path: Path) -> None:
    for target in ("sab-files", "sab-split"):
        done = _make(target, f"SAB={tmp_path / 'none'}")
        assert done.returncode != 0
        assert "run 'make benchmarks' to fetch it, or set SAB=DIR" in done.stderr


def test_the_reports_depend_on_the_benchmark_check() -> None:
    """The targets that read $(SAB) check it first, before any bootstrap."""
    makefile = (ROOT / "Makefile").read_text()
    for target, check in (
        ("agents-report", "sab-split"),
        ("bench-report", "sab-files"),
        ("bench-latency", "sab-files"),
    ):
        rule = re.search(rf"^{target}:(.*)$", makefile, re.M)
        assert rule is not None and rule.group(1).split()[0] == check, target


def test_the_default_sab_is_shared_when_present_else_the_fetched_folder() -> None:
    value = _make("--eval=show-sab: ; @echo $(SAB)", "show-sab").stdout.strip()
    expected = "../shared/benchmarks/safeagentbench" if SHARED.is_dir() else "data/safeagentbench"
    assert value == expected
