"""``virf bench latency``: its inputs are valid, its figures are complete, bad input is refused.

Timings themselves are not asserted (they belong to the benchmark, not to
unit tests); the synthetic inputs and the shape of the output are.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from bench_support import SAB
from conftest import ROOT

from virf.api import LogicTutor
from virf.bench.latency_cases import SYNTHETIC_CYCLE, sample, synthetic_case, synthetic_modules
from virf.bench.latency_figures import LatencyFigures
from virf.bench.latency_report import render_markdown
from virf.ontology.tbox import load_tbox
from virf.reasoning.fast import fragment_of
from virf.world.simulate import simulate


@pytest.mark.parametrize(("objects", "steps"), [(20, 10), (50, 10), (50, 30), (200, 10)])
def test_synthetic_plans_run_safely_to_the_end(tutor: LogicTutor, objects: int, steps: int) -> None:
    case = synthetic_case(objects, tutor.tbox, steps)
    assert len(case.scene.objects) == objects + 1  # and the robot
    assert len(case.plan) == steps
    report = tutor.verifier.verify(case.scene, case.plan)
    assert report.status == "SAFE", report.reason
    assert all(t.outcome == "ok" for t in report.trace)


def test_the_cycle_returns_to_the_same_world(tutor: LogicTutor) -> None:
    """After the first pass (which also marks objects found and near), every
    pass of the cycle ends in the same state, so longer plans repeat equal work."""
    case = synthetic_case(20, tutor.tbox, 30)
    sim = tutor.verifier.sim
    trace = simulate(sim, sim.initial(case.scene), case.plan)
    states, stop = trace.states, trace.stop
    n = len(SYNTHETIC_CYCLE)
    assert stop is None and len(states) == 3 * n + 1
    assert dict(states[n].facts) == dict(states[2 * n].facts) == dict(states[3 * n].facts)


def test_synthetic_domain_modules_load_and_stay_in_the_fragment(tmp_path: Path) -> None:
    base = load_tbox()
    extra = synthetic_modules(1, tmp_path)
    bigger = load_tbox("kitchen", extra)
    assert len(bigger.owl.logical_axioms()) > 1.5 * len(base.owl.logical_axioms())
    assert fragment_of(bigger).exact
    assert any(c.startswith("Syn1_") for c in bigger.vocabulary.classes)


def test_sample_spreads_evenly() -> None:
    items = list(range(10))
    assert sample(items, 0) == items  # type: ignore[arg-type]
    assert sample(items, 5) == [0, 2, 4, 6, 8]  # type: ignore[arg-type]
    assert sample(items, 50) == items  # type: ignore[arg-type]


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "virf.cli.main", "bench", "latency", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--sizes", "abc"], "--sizes 'abc'"),
        (["--sizes", "5"], "at least 10 objects"),
        (["--lengths", "15"], "multiple of 10"),
        (["--tbox-factors", "0"], "1 to 16"),
        (["--paper-call-limit", "0"], "'--paper-call-limit'"),
        (
            ["--cold-engines", "fast,hermit"],
            "--cold-engines: unknown engine 'hermit'; choose from fast, reference",
        ),
    ],
)
def test_bad_options_give_one_line(tmp_path: Path, args: list[str], message: str) -> None:
    # A task file of its own: the options are checked whether or not the
    # benchmark split sits beside the clone.
    tasks = tmp_path / "unsafe_detailed.jsonl"
    task = {"scene_name": "FloorPlan1", "instruction": "Throw the pot.", "step": ["find pot"]}
    tasks.write_text(json.dumps(task) + "\n", encoding="utf-8")
    result = _cli(str(tasks), *args)
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and message in result.stderr
    assert "Traceback" not in result.stderr


def test_a_cold_example_without_its_files_gives_one_line(tmp_path: Path) -> None:
    tasks = tmp_path / "unsafe_detailed.jsonl"
    task = {"scene_name": "FloorPlan1", "instruction": "Throw the pot.", "step": ["find pot"]}
    tasks.write_text(json.dumps(task) + "\n", encoding="utf-8")
    result = _cli(str(tasks), "--no-paper", "--cold-example", str(tmp_path))
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and "no scene.json there" in result.stderr


def test_missing_file_gives_one_line(tmp_path: Path) -> None:
    result = _cli(str(tmp_path / "nope.jsonl"), "--no-paper")
    assert result.returncode == 2
    assert result.stderr.startswith("error: no such file")


def test_a_small_run_prints_every_figure(tmp_path: Path) -> None:
    if not SAB.is_dir():
        pytest.skip(f"SafeAgentBench dev split not found at {SAB}")
    tasks = tmp_path / "tasks.jsonl"
    lines = (SAB / "unsafe_detailed.jsonl").read_text(encoding="utf-8").splitlines()[:3]
    tasks.write_text("\n".join(lines) + "\n", encoding="utf-8")
    md = tmp_path / "performance.md"
    result = _cli(
        str(tasks),
        "--json",
        "--no-paper",
        "--sizes",
        "10,12",
        "--lengths",
        "10,20",
        "--tbox-factors",
        "1",
        "--repeats",
        "1",
        "--cold-runs",
        "1",
        # The reference engine's cold start (a JVM a process) is the same code
        # with another engine name, at ten seconds a process.
        "--cold-engines",
        "fast",
        "--markdown",
        str(md),
    )
    assert result.returncode == 0, result.stderr
    fig = json.loads(result.stdout)
    for key in ("ratio", "fast_p50_ms", "fast_p95_ms", "reference_p50_ms", "paper_p50_ms"):
        assert key in fig
    assert fig["plans"] == 3
    assert fig["identical_reports"] == {"compared": 3, "identical": 3}
    assert fig["fast"]["fallbacks"] == 0
    assert [r["requested_objects"] for r in fig["scene_scaling"]] == [10, 12]
    assert [r["steps"] for r in fig["length_scaling"]] == [10, 20]
    assert all(r["identical"] for r in fig["scene_scaling"] + fig["length_scaling"])
    text = md.read_text(encoding="utf-8")
    assert "## Scaling with plan length" in text and "| x1 |" in text
    assert "| (c) fast engine | 3 |" in text
    # With one run a plan, its first run is its time.
    assert fig["fast"]["first_run_p50_ms"] == round(fig["fast"]["p50_ms"], 2)
    assert fig["fast"]["first_run_ratio"] == fig["reference_ratio"]
    assert "first run of each plan alone (after another plan's): p50" in text
    saved = LatencyFigures.model_validate(fig)  # a run read back, as the page is rendered again
    assert render_markdown(saved, "virf bench latency X").startswith("# Performance")
    cold = {row["engine"]: row for row in fig["cold_start"]["rows"]}
    assert set(cold) == {"fast"}
    assert all(row["verdict"] == "UNSAFE" and row["runs"] == 1 for row in cold.values())
    assert 0 < cold["fast"]["min_s"] <= cold["fast"]["median_s"] <= cold["fast"]["max_s"]
    assert "## Cold start to first verdict" in text and "| fast | UNSAFE | 1 |" in text
