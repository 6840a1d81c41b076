"""``virf bench service``: throughput and latency of ``POST /v1/verify``.

A real ``virf serve`` runs in a process of its own on 127.0.0.1, and a pool
of client threads sends it the reference plans of SafeAgentBench tasks (each
task's scene built as ``virf bench safeagentbench`` builds it), ``c`` requests
in flight at a time for each concurrency ``c``.  Every answer must be a
report (HTTP 200); anything else fails the run.
"""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Self

from virf.bench.metrics import percentile
from virf.bench.safeagentbench import load_tasks
from virf.errors import EnvironmentProblem, InputError
from virf.ontology.tbox import load_tbox
from virf.processes import guarded
from virf.render.tables import Column, TextTable


@dataclass(frozen=True)
class Level:
    concurrency: int
    requests: int
    seconds: float
    p50_ms: float
    p99_ms: float

    @property
    def throughput(self) -> float:
        return self.requests / self.seconds if self.seconds > 0 else 0.0

    def public(self) -> dict[str, object]:
        return {
            "concurrency": self.concurrency,
            "requests": self.requests,
            "seconds": round(self.seconds, 3),
            "throughput_per_s": round(self.throughput, 1),
            "p50_ms": round(self.p50_ms, 1),
            "p99_ms": round(self.p99_ms, 1),
        }


def request_bodies(files: Sequence[Path]) -> list[bytes]:
    """One /v1/verify body per task with a reference plan."""
    vocab = load_tbox().vocabulary
    bodies = []
    for path in files:
        for task in load_tasks(path):
            if not task.steps:
                continue
            payload = {"scene": task.scene_data(vocab), "plan": list(task.steps)}
            bodies.append(json.dumps(payload).encode())
    if not bodies:
        raise InputError("no task with a reference plan in the files given")
    return bodies


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Server:
    """``virf serve`` in a child process, until closed.  The server and its
    workers end with this process however it ends, SIGKILL included
    (:func:`virf.processes.guarded`).  As a context manager it is ready to
    answer inside the block and stopped after it."""

    def __init__(self, workers: int, *options: str) -> None:
        """``options``: more ``virf serve`` options (``--run-log``, ``--planner``)."""
        self.port = _free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self._stack = ExitStack()
        self.process = self._stack.enter_context(
            guarded(
                [
                    sys.executable,
                    "-m",
                    "virf.cli.main",
                    "serve",
                    "--port",
                    str(self.port),
                    "--workers",
                    str(workers),
                    *options,
                ],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
            )
        )

    def wait_ready(self, timeout_s: float = 120.0) -> None:
        import httpx

        started = time.monotonic()
        while time.monotonic() - started < timeout_s:
            if self.process.poll() is not None:
                err = (
                    self.process.stderr.read().decode(errors="replace")
                    if self.process.stderr
                    else ""
                )
                raise EnvironmentProblem(f"virf serve exited: {err.strip().splitlines()[-1:]}")
            try:
                if httpx.get(f"{self.url}/v1/health", timeout=1.0).status_code == 200:
                    return
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
        raise EnvironmentProblem(f"virf serve did not become ready within {timeout_s:g} s")

    def close(self) -> None:
        self._stack.close()  # stops the server and its workers, and waits for them

    def __enter__(self) -> Self:
        try:
            self.wait_ready()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def measure(
    url: str,
    bodies: Sequence[bytes],
    concurrency: int,
    rounds: int,
    tick: Callable[[], None] | None = None,
) -> Level:
    import httpx

    work = [b for _ in range(rounds) for b in bodies]
    latencies: list[float] = []
    limits = httpx.Limits(max_connections=concurrency, max_keepalive_connections=concurrency)
    with httpx.Client(base_url=url, timeout=120.0, limits=limits) as client:

        def one(body: bytes) -> float:
            started = time.perf_counter()
            reply = client.post(
                "/v1/verify", content=body, headers={"content-type": "application/json"}
            )
            elapsed = (time.perf_counter() - started) * 1000
            if reply.status_code != 200:
                raise EnvironmentProblem(
                    f"/v1/verify answered HTTP {reply.status_code}: {reply.text[:200]}"
                )
            if tick is not None:
                tick()
            return elapsed

        started = time.perf_counter()
        with ThreadPoolExecutor(concurrency) as pool:
            latencies = list(pool.map(one, work))
        seconds = time.perf_counter() - started
    return Level(
        concurrency,
        len(work),
        seconds,
        percentile(latencies, 50),
        percentile(latencies, 99),
    )


@dataclass(frozen=True)
class ServiceBench:
    """One run: every concurrency level against one server."""

    plans: int
    server_workers: int
    levels: tuple[Level, ...]

    def public(self) -> dict[str, object]:
        return {
            "plans": self.plans,
            "server_workers": self.server_workers,
            "levels": [level.public() for level in self.levels],
        }


# Told a label and a total, gives the function to call once per unit done.
Progress = Callable[[str, int], Callable[[], None]]


def run_service_bench(
    files: Sequence[Path],
    levels: Sequence[int],
    server_workers: int,
    rounds: int,
    progress: Progress | None = None,
) -> ServiceBench:
    """Send every task's reference plan ``rounds`` times at each concurrency
    level to a ``virf serve`` of ``server_workers`` processes started for
    the run (and stopped after it, however it ends)."""
    bodies = request_bodies(files)
    results = []
    with Server(server_workers) as server:
        measure(server.url, bodies[:8], 1, 1)  # warm every worker's tutor and caches
        for level in levels:
            total = len(bodies) * rounds
            tick = progress(f"concurrency {level}", total) if progress else None
            results.append(measure(server.url, bodies, level, rounds, tick))
    return ServiceBench(len(bodies), server_workers, tuple(results))


def table(run: ServiceBench) -> TextTable:
    levels, workers, plans = run.levels, run.server_workers, run.plans
    base = levels[0].throughput if levels else 0.0
    return TextTable.of(
        (
            Column("concurrency", "right"),
            Column("requests", "right"),
            Column("throughput /s", "right"),
            Column("× conc. " + str(levels[0].concurrency if levels else 1), "right"),
            Column("p50 ms", "right"),
            Column("p99 ms", "right"),
        ),
        [
            (
                str(lv.concurrency),
                str(lv.requests),
                f"{lv.throughput:.1f}",
                f"{lv.throughput / base:.2f}" if base else "-",
                f"{lv.p50_ms:.1f}",
                f"{lv.p99_ms:.1f}",
            )
            for lv in levels
        ],
        title=f"POST /v1/verify: {plans} reference plans, server with {workers} worker(s)",
    )
