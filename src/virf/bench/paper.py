"""The paper's verification method, run as a latency baseline.

The paper's verifier calls owlready2's bundled Pellet once per plan step, on a
fresh copy of the ontology plus that step's ABox.  ``paper_baseline.py``
reproduces exactly that in a separate virtualenv (``.venv-paper``): owlready2
is not a VIRF dependency, and from 0.50 on it bundles Jena jars built for
Java 25 (Pellet then fails on Java 17 with UnsupportedClassVersionError), so
the baseline pins 0.49, the last release that runs on Java 17.  This
module prepares that venv, exports the TBox in a form owlready2 can read,
and runs the script on plans given as VIRF facts, stopping any reasoner call
that outlasts its limit (the script and every process it started, as one
process group) and starting the script again on the plans left.
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import IO, Any

from virf.errors import EnvironmentProblem, InputError, VirfError
from virf.ontology.iri import NS
from virf.ontology.tbox import TBox
from virf.processes import guarded, run, stop
from virf.schema import Fact, FactKind

# TBox individuals move here in the export: every one of them is punned with
# a class of the same name, which owlready2 cannot represent (see export_tbox).
INDIVIDUAL_NS = "http://virf.dev/ontology/individual#"
PAPER_VENV = ".venv-paper"
# One Pellet call may take this long before it is stopped (and counted as
# this long: a lower bound).  With the 49 hand-written rules a call took about
# 3 s; with the household knowledge base one ran past 14 minutes.
PAPER_CALL_LIMIT_S = 60.0
# What a call that hit the limit says in place of its findings.
OVER_LIMIT = "> limit"
# How long, once the script is stopped, its progress echo may take to drain.
ECHO_DRAIN_S = 5.0
ECHO_POLL_S = 0.1
OWLREADY2 = "owlready2==0.49"
SCRIPT = Path(__file__).with_name("paper_baseline.py")

PaperPlan = tuple[str, Sequence[Sequence[Fact]]]


def export_tbox(tbox: TBox, path: str | Path, individual_ns: str | None = INDIVIDUAL_NS) -> int:
    """Write the TBox's import closure as one RDF/XML ontology; return its
    number of logical axioms.

    owlready2 reads neither Manchester syntax nor ``owl:imports`` of local
    modules, so the modules are merged.  Axiom annotations (rule texts) are
    dropped: the reasoner never reads them, and a smaller file makes the
    baseline's per-step load faster, never slower, than the paper's.

    Named individuals move to ``individual_ns`` (same local name; ``None``
    keeps them).  They are all punned (``Metal`` is a class and an
    individual), and owlready2 keeps one Python object per IRI: after Pellet
    realises the individual ``Metal`` as a ``Metal``, owlready2 makes the
    class its own superclass and fails.  In OWL 2 DL a punned class and
    individual are unrelated, so the renaming leaves every entailment as is.
    """
    target = Path(path).resolve()
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        return tbox.owl.export_rdfxml(target, individual_ns)
    except OSError as exc:
        raise EnvironmentProblem(f"cannot write the TBox to {target}: {exc}") from None
    except Exception as exc:  # OWLAPI wraps an I/O failure in its own exception
        if isinstance(exc, VirfError):
            raise
        raise EnvironmentProblem(f"cannot write the TBox to {target}: {exc}") from None


def ensure_paper_env(root: str | Path) -> Path:
    """The python of ``root/.venv-paper``, created with owlready2 0.49 if missing."""
    venv = Path(root).resolve() / PAPER_VENV
    python = venv / "bin" / "python"
    hint = (
        f"run 'python3.11 -m venv {venv} && {venv}/bin/pip install {OWLREADY2}' (needs PyPI access)"
    )
    if shutil.which("java") is None:
        raise EnvironmentProblem(
            "java not found: the paper baseline runs Pellet on a Java runtime "
            "(apt-get install openjdk-17-jre-headless)"
        )
    wanted = OWLREADY2.split("==")[1]
    if _owlready2_version(python) == wanted:
        return python
    base = shutil.which("python3.11") or sys.executable
    steps = [[base, "-m", "venv", str(venv)]] if not python.exists() else []
    steps.append([str(python), "-m", "pip", "install", "--quiet", OWLREADY2])
    for cmd in steps:
        # Guarded: pip, and what it starts, ends with the benchmark.
        try:
            done = run(cmd)
        except OSError:
            done = None
        if done is None or done.returncode != 0:
            raise EnvironmentProblem(f"cannot set up the paper baseline venv: {hint}")
    found = _owlready2_version(python)
    if found != wanted:
        raise EnvironmentProblem(f"{venv} has owlready2 {found or 'missing'}, not {wanted}: {hint}")
    return python


def _owlready2_version(python: Path) -> str | None:
    if not python.exists():
        return None
    try:
        done = run([str(python), "-c", "import owlready2; print(owlready2.VERSION)"])
    except OSError:
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def fact_json(fact: Fact) -> dict[str, Any]:
    """A fact in the job format of ``paper_baseline.py``."""
    out: dict[str, Any] = {
        "s": fact.subject,
        "p": fact.predicate,
        "o": fact.object,
        "kind": str(fact.kind),
    }
    if fact.kind is FactKind.CLOSURE:
        # Job files keep their old "o" (the members comma-joined) so they do
        # not change; the script reads "members".
        out["o"] = ",".join(fact.members)
        out["members"] = list(fact.members)
    return out


def run_paper_baseline(
    tbox: TBox,
    plans: Sequence[PaperPlan],
    concepts: Sequence[str],
    workdir: str | Path | None = None,
    python: str | Path | None = None,
    call_limit_s: float | None = PAPER_CALL_LIMIT_S,
) -> dict[str, Any]:
    """Time the paper's per-step reasoner call on every snapshot of ``plans``.

    ``plans`` holds ``(plan_id, snapshots)`` with each snapshot a list of
    facts.  ``python`` defaults to the ``.venv-paper`` of the checkout this
    module lives in (created on first use).  Returns what the script's
    OUT.json holds: per plan ``step_ms``, ``total_ms``, ``findings`` and
    ``consistent`` per snapshot (a snapshot that failed in Java is
    ``{"error": ...}`` instead), and ``over_limit``.

    A reasoner call still running ``call_limit_s`` after it started is
    stopped, with the script and every process it started (the JVM): its
    step counts ``call_limit_s`` (a lower bound), its findings are
    ``{"error": "> limit"}``, the plan's ``over_limit`` is true and its
    later steps are not run (they could only add to a lower bound).  The
    script starts again on the plans left.  ``calls_over_limit`` counts
    such calls.

    The files go to ``workdir``, or to a temporary folder removed at the end,
    however it comes (an error, Ctrl-C, SIGTERM; after SIGKILL, by the
    script's guard).  The script, and the JVMs it starts, end with this
    process (:func:`virf.processes.guarded`).
    """
    unknown = [c for c in concepts if c not in tbox.vocabulary.classes]
    if unknown:
        raise InputError(f"unknown concept '{unknown[0]}'")
    if call_limit_s is not None and call_limit_s <= 0:
        raise InputError(f"the paper's call limit must be positive, not {call_limit_s:g} s")
    if python is None:
        python = ensure_paper_env(_checkout_root())
    if workdir is not None:
        return _run_in(tbox, plans, concepts, Path(workdir).resolve(), python, call_limit_s)
    work = Path(tempfile.mkdtemp(prefix="virf-paper-"))
    try:
        return _run_in(tbox, plans, concepts, work, python, call_limit_s, temporary=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _run_in(
    tbox: TBox,
    plans: Sequence[PaperPlan],
    concepts: Sequence[str],
    work: Path,
    python: str | Path,
    call_limit_s: float | None,
    *,
    temporary: bool = False,
) -> dict[str, Any]:
    work.mkdir(parents=True, exist_ok=True)
    tbox_path = work / "tbox.owl"
    export_tbox(tbox, tbox_path)
    jobs = [
        {"id": pid, "snapshots": [[fact_json(f) for f in snap] for snap in snaps]}
        for pid, snaps in plans
    ]
    done: list[dict[str, Any]] = [
        {"id": pid, "step_ms": [], "findings": [], "consistent": [], "over_limit": False}
        for pid, _ in plans
    ]
    out: dict[str, Any] = {"call_limit_s": call_limit_s, "calls_over_limit": 0}
    peaks: dict[str, int] = {}
    job_path, out_path = work / "job.json", work / "out.json"
    first = 0  # the plans before this one are done
    while True:  # once at least, so that the versions are known without plans too
        job = {
            "tbox": str(tbox_path),
            "namespace": NS,
            "individual_namespace": INDIVIDUAL_NS,
            "concepts": list(concepts),
            "plans": jobs[first:],
        }
        job_path.write_text(json.dumps(job, indent=1), encoding="utf-8")
        out_path.unlink(missing_ok=True)
        cmd = [str(python), str(SCRIPT), str(job_path), str(out_path)]
        run_ = _supervise(cmd, call_limit_s, work if temporary else None)
        for event in run_.events:
            kind = event.get("event")
            if kind == "ready":
                out.setdefault("owlready2", event.get("owlready2"))
                out.setdefault("java", event.get("java"))
            elif kind == "step":
                plan = done[first + int(event["plan"])]
                plan["step_ms"].append(event["ms"])
                plan["findings"].append(event["findings"])
                plan["consistent"].append(event["consistent"])
            elif kind == "end":
                for key, value in (event.get("peak_rss_kb") or {}).items():
                    if isinstance(value, int):
                        peaks[key] = max(value, peaks.get(key, 0))
        if run_.over_limit is None:
            if run_.failure is not None:
                raise EnvironmentProblem(f"paper baseline failed: {run_.failure}")
            break
        assert call_limit_s is not None
        plan = done[first + run_.over_limit]
        plan["step_ms"].append(round(call_limit_s * 1000, 1))
        plan["findings"].append({"error": OVER_LIMIT})
        plan["consistent"].append(None)
        plan["over_limit"] = True
        out["calls_over_limit"] += 1
        print(
            f"paper baseline: plan {plan['id']}: a reasoner call ran past "
            f"{call_limit_s:g} s and was stopped; the plan's time is a lower bound",
            file=sys.stderr,
        )
        first += run_.over_limit + 1
        if first == len(jobs):
            break
    for plan in done:
        plan["total_ms"] = round(sum(plan["step_ms"]), 1)
    out["plans"] = done
    out["peak_rss_kb"] = peaks
    return out


class _Run:
    """What one run of the script said: its events; which of its plans (an
    index into its job) had a call stopped at the limit; or, when it failed,
    its last line."""

    def __init__(self) -> None:
        self.events: list[dict[str, Any]] = []
        self.over_limit: int | None = None
        self.failure: str | None = None


def _supervise(cmd: list[str], call_limit_s: float | None, temporary: Path | None) -> _Run:
    """Run the script, echoing its progress lines, until it ends or a call
    outlasts ``call_limit_s``; then stop it and all it started.

    The script and its children end with this process, however it ends;
    ``temporary`` is its folder, removed by the guard if this process dies
    first (:func:`virf.processes.guarded`)."""
    result = _Run()
    last: list[str] = []
    done = threading.Event()
    try:
        with guarded(cmd, remove=temporary, stdout=subprocess.PIPE, stderr=subprocess.PIPE) as proc:
            assert proc.stdout is not None and proc.stderr is not None
            # A descriptor of its own: closing proc.stderr while the echo
            # reads it would wait for the read, for ever if something that
            # escaped the group still held the pipe.
            echo = threading.Thread(
                target=_echo,
                args=(os.dup(proc.stderr.fileno()), last, done),
                name="paper-echo",
                daemon=True,
            )
            echo.start()
            try:
                result.over_limit = _follow(proc, _Lines(proc.stdout), call_limit_s, result)
                # At the limit: the call, its JVM and the script go now, as a group.
                stop(proc)
            finally:
                done.set()
            code = proc.returncode
            echo.join(ECHO_DRAIN_S)
    except OSError as exc:
        result.failure = f"cannot start {cmd[0]}: {exc.strerror}"
        return result
    if result.over_limit is None and code != 0:
        result.failure = (last[-1] if last else f"exit code {code}").removeprefix("error: ")
    return result


def _follow(
    proc: subprocess.Popen[bytes], lines: _Lines, call_limit_s: float | None, result: _Run
) -> int | None:
    """Collect the script's events into ``result`` until it ends; the plan
    (its index in the job) whose call outlasted ``call_limit_s``, if one did."""
    deadline: float | None = None
    call: int | None = None
    while True:
        wait = None if deadline is None else deadline - time.monotonic()
        try:
            line = lines.next(wait)
        except EOFError:
            # The script is ending: let it, so its exit status is its own.
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(ECHO_DRAIN_S)
            return None
        if line is None:
            return call
        try:
            event = json.loads(line)
        except json.JSONDecodeError:
            continue  # not an event: nothing the script meant to say
        if not isinstance(event, dict):
            continue
        result.events.append(event)
        if event.get("event") == "call" and call_limit_s is not None:
            call = int(event["plan"])
            deadline = time.monotonic() + call_limit_s
        elif event.get("event") == "step":
            deadline = None


def _echo(fd: int, last: list[str], done: threading.Event) -> None:
    """Copy the script's stderr (its progress lines) to ours, keeping the
    last line said, until the pipe ends or, once ``done``, falls quiet."""
    pending = b""
    try:
        while True:
            ready, _, _ = select.select([fd], [], [], ECHO_POLL_S)
            if not ready:
                if done.is_set():
                    break
                continue
            chunk = os.read(fd, 65536)
            if not chunk:
                break
            *lines, pending = (pending + chunk).split(b"\n")
            for raw in lines:
                _say(raw, last)
        if pending:
            _say(pending, last)
    except (OSError, ValueError):
        return  # our stderr is gone: nothing left to echo to
    finally:
        os.close(fd)


def _say(raw: bytes, last: list[str]) -> None:
    line = raw.decode("utf-8", "replace")
    sys.stderr.write(line + "\n")
    if line.strip():
        last[:] = [line.strip()]


class _Lines:
    """Lines from a pipe, each awaited no longer than asked (a plain
    ``readline`` cannot be given a time limit)."""

    def __init__(self, stream: IO[bytes]) -> None:
        self.fd = stream.fileno()
        self.buffer = b""
        self.ended = False

    def next(self, timeout: float | None) -> str | None:
        """The next line; ``None`` when ``timeout`` seconds pass first;
        EOFError once the pipe is closed and every line read."""
        end = None if timeout is None else time.monotonic() + timeout
        while b"\n" not in self.buffer and not self.ended:
            wait = None if end is None else max(0.0, end - time.monotonic())
            ready, _, _ = select.select([self.fd], [], [], wait)
            if not ready:
                return None
            chunk = os.read(self.fd, 65536)
            if chunk:
                self.buffer += chunk
            else:
                self.ended = True
        if not self.buffer:
            raise EOFError
        line, _, self.buffer = self.buffer.partition(b"\n")
        return line.decode("utf-8", "replace")


def _checkout_root() -> Path:
    # src/virf/bench/paper.py -> the repository root, where .venv-paper lives.
    return Path(__file__).resolve().parents[3]
