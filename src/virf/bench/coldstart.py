"""Cold start to first verdict: ``virf verify`` as a fresh process, timed.

What a robot stack pays when it calls the CLI once: interpreter start,
imports, loading the knowledge base, simulating and classifying, printing the
report.  Each run is a new process, so nothing is warm but the operating
system's file cache and Python's bytecode cache, as after any installation
(the first run fills both and is not counted; ``PYTHONDONTWRITEBYTECODE`` is
lifted for the runs so that it can).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Final

from virf.bench.latency_figures import ColdStartRow
from virf.errors import EnvironmentProblem
from virf.processes import run

# virf verify's exit codes for a verdict; anything else means it did not answer.
VERDICT_EXITS = {0: "SAFE", 1: "UNSAFE", 3: "UNKNOWN", 4: "ERROR"}
# A run that takes longer has hung.
RUN_LIMIT_S: Final = 600.0
# Each run goes through a guard (virf.processes), so that it ends with the
# benchmark; the guard's own start and its polling would be timed with it.
# This stopwatch, started under the guard, times the command alone and adds
# the seconds as stderr's last line, after MARK.
MARK: Final = "virf-cold-start-seconds "
STOPWATCH: Final = (
    "import subprocess, sys, time\n"
    "start = time.perf_counter()\n"
    "code = subprocess.call(sys.argv[1:])\n"
    f"sys.stderr.write('\\n{MARK}' + repr(time.perf_counter() - start) + '\\n')\n"
    "sys.exit(code)\n"
)


def virf_command() -> list[str]:
    """The installed ``virf`` script next to this interpreter, else the module."""
    script = Path(sys.executable).with_name("virf")
    return [str(script)] if script.is_file() else [sys.executable, "-m", "virf.cli.main"]


def cold_start(
    scene: str | Path,
    plan: str | Path,
    engine: str = "fast",
    runs: int = 5,
    tick: Callable[[], None] | None = None,
) -> ColdStartRow:
    """Wall-clock seconds of ``runs`` fresh ``virf verify`` processes, after one
    uncounted run that warms the file cache."""
    argv = [*virf_command(), "verify", "--engine", engine, str(scene), str(plan)]
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    times: list[float] = []
    verdict = ""
    timed = [sys.executable, "-I", "-c", STOPWATCH, *argv]
    for i in range(runs + 1):
        try:
            done = run(timed, timeout=RUN_LIMIT_S, env=env)
        except subprocess.TimeoutExpired:
            raise EnvironmentProblem(
                f"virf verify did not answer within {RUN_LIMIT_S:g} s in the cold-start run"
            ) from None
        said, mark, seconds = done.stderr.rstrip().rpartition("\n" + MARK)
        if done.returncode not in VERDICT_EXITS or not mark:
            said = done.stderr if not mark else said
            line = (said.strip().splitlines() or ["no message"])[-1]
            raise EnvironmentProblem(
                f"virf verify exited with {done.returncode} in the cold-start run: {line}"
            )
        verdict = VERDICT_EXITS[done.returncode]
        if i:
            times.append(float(seconds))
        if tick:
            tick()
    return ColdStartRow(
        engine=engine,
        runs=runs,
        verdict=verdict,
        median_s=round(statistics.median(times), 3),
        min_s=round(min(times), 3),
        max_s=round(max(times), 3),
    )


def cold_start_rows(
    scene: str | Path,
    plan: str | Path,
    engines: Sequence[str] = ("fast", "reference"),
    runs: int = 5,
    tick: Callable[[], None] | None = None,
) -> list[ColdStartRow]:
    return [cold_start(scene, plan, engine, runs, tick) for engine in engines]
