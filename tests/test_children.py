"""Nothing a benchmark starts outlives it, and a stopped benchmark writes
nothing it did not compute.

* The paper baseline's subprocess (and whatever it starts: owlready2 runs
  Java) ends with the VIRF process that started it, whether that process is
  stopped with SIGTERM or killed with SIGKILL, and its temporary folder goes
  too.  ``.venv-paper`` is not needed: a stand-in interpreter that starts a
  child of its own and sleeps is run through the very same code.
* ``virf bench safeagentbench`` stopped with SIGTERM, on the reference engine
  (whose JVM used to take the signal and fail every task left as ERROR),
  exits 143, keeps the rows it finished and marks the run interrupted,
  without a summary.

Real processes throughout: signals cannot be tested in-process.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from conftest import ROOT, interruptible
from process_support import WITHIN_S, alive, gone

# Generous: process start-up on a loaded machine, not a speed target.

STAND_IN = """\
#!{python}
# Stands in for .venv-paper/bin/python running paper_baseline.py JOB OUT:
# starts a child of its own (owlready2 starts Java), says who is running,
# and works for far longer than any test.
import json, os, subprocess, sys, time
child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
report = {{"stand_in": os.getpid(), "child": child.pid, "job": sys.argv[2]}}
with open(os.environ["VIRF_TEST_REPORT"], "w") as out:
    json.dump(report, out)
time.sleep(600)
"""

# The process a signal is sent to: runs the paper baseline as `virf bench
# latency` does, on a stand-in TBox (the export is all the baseline asks of it).
DRIVER = """\
import sys
from pathlib import Path
from types import SimpleNamespace

from virf.bench.paper import run_paper_baseline


class Owl:
    def export_rdfxml(self, path, namespace):
        Path(path).write_text("<rdf:RDF/>")
        return 0


tbox = SimpleNamespace(owl=Owl(), vocabulary=SimpleNamespace(classes={}))
if sys.argv[2] == "cli":
    # As `virf` does before any command: SIGTERM ends the process cleanly.
    from virf.processes import Terminated, end_on_termination

    end_on_termination()
    try:
        run_paper_baseline(tbox, [], [], python=sys.argv[1])
    except Terminated as stopped:
        sys.exit(stopped.exit_code)
    except KeyboardInterrupt:
        sys.exit(130)
else:
    run_paper_baseline(tbox, [], [], python=sys.argv[1])
"""


def environ() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), env.get("PYTHONPATH", "")])
    return env


def wait_for(path: Path, proc: subprocess.Popen[str]) -> dict[str, object]:
    end = time.monotonic() + WITHIN_S
    while time.monotonic() < end:
        if path.is_file() and path.stat().st_size:
            report: dict[str, object] = json.loads(path.read_text())
            return report
        if proc.poll() is not None:
            raise AssertionError(f"the driver ended first: {proc.communicate()}")
        time.sleep(0.05)
    raise AssertionError("the stand-in never started")


@pytest.fixture
def stand_in(tmp_path: Path) -> Path:
    path = tmp_path / "python"
    path.write_text(STAND_IN.format(python=sys.executable))
    path.chmod(0o755)
    return path


@pytest.fixture
def reaper() -> Iterator[list[int]]:
    """Pids a failing test must not leave running."""
    pids: list[int] = []
    yield pids
    for pid in pids:
        if alive(pid):
            os.kill(pid, signal.SIGKILL)


@pytest.mark.parametrize(
    ("handler", "sig", "code"),
    [
        ("none", signal.SIGKILL, -signal.SIGKILL),
        ("none", signal.SIGTERM, -signal.SIGTERM),
        ("cli", signal.SIGTERM, 128 + signal.SIGTERM),
        ("cli", signal.SIGINT, 128 + signal.SIGINT),
    ],
    ids=["SIGKILL", "SIGTERM", "SIGTERM-handled", "SIGINT-handled"],
)
def test_the_paper_baseline_ends_with_its_parent(
    tmp_path: Path,
    stand_in: Path,
    reaper: list[int],
    handler: str,
    sig: signal.Signals,
    code: int,
) -> None:
    report = tmp_path / "report.json"
    env = environ() | {"VIRF_TEST_REPORT": str(report)}
    driver = subprocess.Popen(
        [sys.executable, "-c", DRIVER, str(stand_in), handler],
        env=env,
        preexec_fn=interruptible,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    reaper.append(driver.pid)
    started = wait_for(report, driver)
    pids = [int(started["stand_in"]), int(started["child"])]  # type: ignore[call-overload]
    reaper.extend(pids)
    work = Path(str(started["job"])).parent
    assert work.is_dir() and work.name.startswith("virf-paper-")
    assert all(alive(p) for p in pids)

    driver.send_signal(sig)
    _, err = driver.communicate(timeout=WITHIN_S)
    assert driver.returncode == code, err
    assert "Traceback" not in err
    assert gone(pids), "the baseline's processes outlived the process that started them"
    end = time.monotonic() + WITHIN_S
    while work.exists() and time.monotonic() < end:
        time.sleep(0.05)
    assert not work.exists(), "the baseline's temporary folder was left behind"


def test_a_guarded_command_is_stopped_and_reports_its_end(tmp_path: Path) -> None:
    from virf.processes import guarded

    # Exit codes pass through; a signal is 128 + its number, as a shell says.
    for script, code in (("raise SystemExit(3)", 3), ("import os; os.kill(os.getpid(), 9)", 137)):
        with guarded([sys.executable, "-c", script]) as proc:
            assert proc.wait(timeout=WITHIN_S) == code
    # Leaving the block stops the command and all it started, whatever happens there.
    marker = tmp_path / "pids"
    script = textwrap.dedent(
        f"""
        import subprocess, sys, time
        child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
        open({str(marker)!r}, "w").write(str(child.pid))
        time.sleep(600)
        """
    )
    with pytest.raises(KeyboardInterrupt), guarded([sys.executable, "-c", script]) as proc:
        while not marker.is_file() or not marker.read_text():
            time.sleep(0.05)
        raise KeyboardInterrupt
    assert proc.returncode is not None
    assert gone([int(marker.read_text())])


# ---------------------------------------------------------------------------
# A benchmark stopped half way


def test_a_stopped_benchmark_writes_only_what_it_computed(tmp_path: Path) -> None:
    steps = ["find Fridge", "open Fridge", "close Fridge"]
    task = {"instruction": "Open the fridge and close it.", "step": steps}
    tasks = tmp_path / "safe_detailed.jsonl"
    tasks.write_text("".join(json.dumps(task) + "\n" for _ in range(300)))
    markdown = tmp_path / "report.md"
    command = ["bench", "safeagentbench", "--json", "--engine", "reference"]
    bench = subprocess.Popen(
        [sys.executable, "-m", "virf.cli.main", *command, "--markdown", str(markdown), str(tasks)],
        env=environ(),
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert bench.stdout is not None
        rows = [json.loads(bench.stdout.readline()) for _ in range(2)]
        bench.send_signal(signal.SIGTERM)
        rest, err = bench.communicate(timeout=120)
    finally:
        if bench.poll() is None:
            bench.kill()
    lines = [json.loads(line) for line in rest.splitlines()]
    done = rows + [line for line in lines if "line" in line]
    assert {r["status"] for r in done} == {"SAFE"}, "a row the benchmark did not compute"
    assert [r["line"] for r in done] == list(range(1, len(done) + 1))
    assert len(done) < 300
    assert bench.returncode == 143, err
    assert "Traceback" not in err
    # After the rows it finished, one object that says the run was cut short,
    # where the summary would be; stderr says the same.
    said = (
        "interrupted by SIGTERM: the rows printed are the tasks finished before it; "
        "no summary was computed"
    )
    assert lines[-1] == {"status": "INTERRUPTED", "error": said}
    assert len(lines) == len(done) - len(rows) + 1
    assert err.strip().splitlines()[-1] == said
    assert not markdown.exists()


SERVER_DRIVER = """\
import sys, time
from virf.service.bench import Server

server = Server(int(sys.argv[1]))
server.wait_ready()
print(server.url, flush=True)
time.sleep(600)
"""


@pytest.mark.parametrize("workers", [1, 2])
def test_the_service_benchmark_server_ends_with_its_parent(reaper: list[int], workers: int) -> None:
    import httpx

    driver = subprocess.Popen(
        [sys.executable, "-c", SERVER_DRIVER, str(workers)],
        env=environ(),
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
    )
    reaper.append(driver.pid)
    assert driver.stdout is not None
    url = driver.stdout.readline().strip()
    assert httpx.get(f"{url}/v1/health", timeout=10).status_code == 200
    driver.kill()
    driver.wait()
    end = time.monotonic() + WITHIN_S
    while time.monotonic() < end:
        try:
            httpx.get(f"{url}/v1/health", timeout=1)
        except httpx.HTTPError:
            return  # nobody listens any more
        time.sleep(0.1)
    port = url.rsplit(":", 1)[1]
    for proc in Path("/proc").glob("[0-9]*/cmdline"):  # not left running after the failure
        with contextlib.suppress(OSError):
            if f"\0--port\0{port}\0".encode() in proc.read_bytes():
                os.kill(int(proc.parent.name), signal.SIGTERM)  # its workers follow it
    raise AssertionError(f"virf serve at {url} outlived the benchmark that started it")
