"""The paper baseline, bounded: a reasoner call past its limit is stopped with
all it started, and the figures computed from it say they are lower bounds;
and nothing a latency run starts (the baseline, pip, the cold-start
processes) outlives it.

``.venv-paper`` is not needed: a stand-in interpreter speaks the baseline
script's events, and on a snapshot that names ``Slow_1`` starts a child of
its own (owlready2 starts Java) and sleeps far past any limit.  Real
processes throughout: stopping a process group cannot be tested in-process.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from conftest import ROOT, interruptible
from process_support import WITHIN_S, alive, gone

from virf.bench.latency import paper_figures
from virf.bench.latency_figures import LatencyFigures
from virf.bench.latency_report import latency_table, ratio_text, render_markdown, scaling_table
from virf.bench.paper import OVER_LIMIT, run_paper_baseline
from virf.render.tables import to_markdown
from virf.schema import Fact, FactKind

# Generous: process start-up on a loaded machine, not a speed target.
LIMIT_S = 1.0

STAND_IN = """\
#!{python}
# Stands in for .venv-paper/bin/python running paper_baseline.py JOB OUT.
import json, os, subprocess, sys, time

job = json.load(open(sys.argv[2]))


def emit(**event):
    print(json.dumps(event), flush=True)


emit(event="ready", owlready2="stand-in", java="none")
for n, plan in enumerate(job["plans"]):
    for k, snapshot in enumerate(plan["snapshots"]):
        emit(event="call", plan=n, step=k)
        if any(fact["s"] == "Slow_1" for fact in snapshot):
            child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
            with open(os.environ["VIRF_TEST_REPORT"], "a") as out:
                out.write(json.dumps({{"stand_in": os.getpid(), "child": child.pid}}) + "\\n")
            time.sleep(600)
        emit(event="step", plan=n, step=k, ms=5.0, findings=[], consistent=True)
emit(event="end", peak_rss_kb={{"self": 2048}})
"""

# Stands in for `virf verify` (cold start) and for .venv-paper's python (pip,
# the owlready2 check): starts a child, says who runs, and sleeps.
SLEEPER = """\
#!{python}
import json, os, subprocess, sys, time
child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
with open(os.environ["VIRF_TEST_REPORT"], "a") as out:
    out.write(json.dumps({{"stand_in": os.getpid(), "child": child.pid}}) + "\\n")
time.sleep(600)
"""

# The process a signal is sent to, running one of the latency run's children.
DRIVER = """\
import sys
from pathlib import Path
from types import SimpleNamespace

from virf.processes import Terminated, end_on_termination

end_on_termination()  # as `virf` does before any command
what, stand_in = sys.argv[1], sys.argv[2]
try:
    if what == "paper":
        from virf.bench.paper import run_paper_baseline
        from virf.schema import Fact, FactKind


        class Owl:
            def export_rdfxml(self, path, namespace):
                Path(path).write_text("<rdf:RDF/>")
                return 0


        tbox = SimpleNamespace(owl=Owl(), vocabulary=SimpleNamespace(classes={}))
        slow = [Fact("Slow_1", "type", "Fridge", FactKind.TYPE)]
        run_paper_baseline(tbox, [("p", [slow])], [], python=stand_in, call_limit_s=600)
    elif what == "coldstart":
        from virf.bench import coldstart

        coldstart.virf_command = lambda: [stand_in]
        coldstart.cold_start("scene.json", "plan.txt", runs=1)
    else:
        from virf.bench import paper

        paper.ensure_paper_env(sys.argv[3])
except Terminated as stopped:
    sys.exit(stopped.exit_code)
except KeyboardInterrupt:
    sys.exit(130)
"""


class Owl:
    """Just enough of a TBox for the baseline: its export."""

    def export_rdfxml(self, path: Path, namespace: str | None) -> int:
        Path(path).write_text("<rdf:RDF/>", encoding="utf-8")
        return 0


TBOX: Any = SimpleNamespace(owl=Owl(), vocabulary=SimpleNamespace(classes={}))


def started(report: Path) -> list[int]:
    """Every pid the stand-ins said they started."""
    if not report.is_file():
        return []
    rows = [json.loads(line) for line in report.read_text().splitlines() if line]
    return [pid for row in rows for pid in (row["stand_in"], row["child"])]


def executable(path: Path, template: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(template.format(python=sys.executable))
    path.chmod(0o755)
    return path


@pytest.fixture
def report(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """Where the stand-ins say who runs; what a failing test leaves is killed."""
    path = tmp_path / "started.jsonl"
    monkeypatch.setenv("VIRF_TEST_REPORT", str(path))
    yield path
    for pid in started(path):
        if alive(pid):
            os.kill(pid, signal.SIGKILL)


def snapshot(*names: str) -> list[Fact]:
    return [Fact(name, "type", "Fridge", FactKind.TYPE) for name in names]


def test_a_call_past_the_limit_is_stopped_with_its_children(tmp_path: Path, report: Path) -> None:
    stand_in = executable(tmp_path / "python", STAND_IN)
    plans = [
        ("quick", [snapshot("Fridge_1"), snapshot("Fridge_1")]),
        ("slow", [snapshot("Fridge_1"), snapshot("Slow_1"), snapshot("Fridge_1")]),
        ("after", [snapshot("Fridge_1")]),
    ]
    result = run_paper_baseline(TBOX, plans, [], tmp_path / "work", stand_in, LIMIT_S)

    pids = started(report)
    assert len(pids) == 2, "the slow call never started"
    assert gone(pids), "the stopped call, or the child it started, is still running"
    quick, slow, after = result["plans"]
    assert quick["step_ms"] == [5.0, 5.0] and not quick["over_limit"]
    # Stopped at the limit, counted as the limit; its later steps are not run.
    assert slow["over_limit"]
    assert slow["step_ms"] == [5.0, LIMIT_S * 1000]
    assert slow["findings"] == [[], {"error": OVER_LIMIT}]
    assert slow["consistent"] == [True, None]
    # The script started again on the plans left.
    assert after["step_ms"] == [5.0] and after["consistent"] == [True]
    assert result["calls_over_limit"] == 1
    assert result["owlready2"] == "stand-in"
    assert result["peak_rss_kb"] == {"self": 2048}


def test_figures_from_a_plan_over_the_limit_are_lower_bounds(tmp_path: Path, report: Path) -> None:
    stand_in = executable(tmp_path / "python", STAND_IN)
    plans = [
        ("quick", [snapshot("Fridge_1")] * 2),
        ("slow", [snapshot("Fridge_1"), snapshot("Slow_1")]),
        ("synthetic-20", [snapshot("Slow_1")]),
    ]
    result = run_paper_baseline(TBOX, plans, [], tmp_path / "work", stand_in, LIMIT_S)
    compared = paper_figures(result, {"quick": 1.0, "slow": 2.0}, ["quick", "slow"])
    fig = json.loads(json.dumps(compared.public()))  # as --json writes it

    paper = fig["paper"]
    assert paper["calls_over_limit"] == 2 and paper["calls"] == 5
    assert paper["plans"] == 2 and paper["plans_lower_bound"] == 1 and paper["lower_bound"]
    rows = {row["plan"]: row for row in paper["rows"]}
    assert rows["quick"] == {"plan": "quick", "ms": 10.0, "lower_bound": False, "calls": [5.0, 5.0]}
    assert rows["slow"] == {
        "plan": "slow",
        "ms": 1005.0,
        "lower_bound": True,
        "calls": [5.0, OVER_LIMIT],
    }
    # Ratios 10 (exact) and 502.5 (at least): their median is at least 256.2.
    assert fig["ratio"] == 256.2 and fig["ratio_lower_bound"]
    assert ratio_text(compared) == "≥ 256.2×"
    # A fully timed set of plans is exact.
    exact = paper_figures(result, {"quick": 1.0}, ["quick"])
    assert not exact.ratio_lower_bound and ratio_text(exact) == "10×"

    data = figures(fig)
    data["scene_scaling"][0] |= {"paper_ms": 1000.0, "paper_lower_bound": True}
    full = LatencyFigures.model_validate(data)
    table = "\n".join(to_markdown(latency_table(full, terminal=False)))
    assert "| (a) paper: owlready2 + Pellet per step | 2 | ≥ " in table
    terminal = latency_table(full, terminal=True)
    assert any("2 of 5 calls > limit (1 s)" in cell for row in terminal.rows for cell in row)
    assert "≥ 1000" in "\n".join(to_markdown(scaling_table(full, "scene_scaling", terminal=False)))
    text = render_markdown(full, "virf bench latency X --paper-call-limit 1")
    assert "**ratio a/c** (median over the plans timed both ways): **≥ 256.2×**" in text
    assert "**2** of its 5 reasoner calls hit the 1 s limit" in text
    assert "1 of the 2 plans timed are lower bounds" in text
    assert "still running after 1 s (`--paper-call-limit`) is stopped" in text


def figures(paper: dict[str, Any]) -> dict[str, Any]:
    """A latency run's figures around the paper method's (the rest made up)."""
    times = {"p50_ms": 20.0, "p95_ms": 60.0, "mean_ms": 27.0}
    row = {
        "requested_objects": 20,
        "objects": 21,
        "steps": 10,
        "status": "SAFE",
        "fast_ms": 10.0,
        "reference_ms": 900.0,
        "reference_2_workers_ms": 600.0,
        "identical": True,
    }
    return {
        "machine": {"cpus": 2, "python": "3.11", "platform": "Linux", "java": "17"},
        "plans": 2,
        "repeats": 3,
        "fast": times | {"reasoner_calls": 10, "fallbacks": 0, "python_heap_peak_mb": 1.0},
        "reference": times | {"plans": 2},
        "identical_reports": {"compared": 2, "identical": 2},
        "memory": {
            "process_rss_after_tbox_mb": 300.0,
            "process_rss_peak_after_fast_mb": 310.0,
            "process_rss_peak_after_reference_mb": 400.0,
            "fast_python_heap_peak_mb": 1.0,
        },
        "scene_scaling": [dict(row)],
        "length_scaling": [dict(row)],
        "tbox_scaling": [],
        **paper,
    }


@pytest.mark.parametrize(
    ("what", "sig"),
    [
        ("paper", signal.SIGTERM),
        ("paper", signal.SIGINT),
        ("coldstart", signal.SIGTERM),
        ("coldstart", signal.SIGKILL),
        ("paper-venv", signal.SIGTERM),
        ("paper-venv", signal.SIGKILL),
    ],
)
def test_a_stopped_latency_run_leaves_no_process(
    tmp_path: Path, report: Path, what: str, sig: signal.Signals
) -> None:
    """The paper baseline in the middle of a call, a cold-start ``virf
    verify``, and ``.venv-paper``'s python run while the venv is checked (as
    pip is): each ends, with what it started, when the run is stopped, even
    by SIGKILL."""
    if what == "paper-venv":
        stand_in = executable(tmp_path / "checkout" / ".venv-paper" / "bin" / "python", SLEEPER)
        args = [str(stand_in), str(tmp_path / "checkout")]
    else:
        stand_in = executable(tmp_path / "python", STAND_IN if what == "paper" else SLEEPER)
        args = [str(stand_in)]
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), env.get("PYTHONPATH", "")])
    driver = subprocess.Popen(
        [sys.executable, "-c", DRIVER, what.split("-")[0], *args],
        env=env,
        preexec_fn=interruptible,
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        end = time.monotonic() + WITHIN_S
        while not started(report) and driver.poll() is None and time.monotonic() < end:
            time.sleep(0.05)
        pids = started(report)
        assert pids and all(alive(p) for p in pids), driver.communicate(timeout=WITHIN_S)
        driver.send_signal(sig)
        _, err = driver.communicate(timeout=WITHIN_S)
    finally:
        if driver.poll() is None:
            driver.kill()
    expected = -sig if sig == signal.SIGKILL else 128 + sig
    assert driver.returncode == expected, err
    assert "Traceback" not in err
    assert gone(pids), "a process the run started outlived it"
