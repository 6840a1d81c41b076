"""The paper's verification method, run as a latency baseline.

The paper's verifier calls owlready2's bundled Pellet once per plan step, on a
fresh copy of the ontology plus that step's ABox.  ``paper_baseline.py``
reproduces exactly that in a separate virtualenv (``.venv-paper``): owlready2
is not a VIRF dependency, and from 0.50 on it bundles Jena jars built for
Java 25 (Pellet then fails on Java 17 with UnsupportedClassVersionError), so
the baseline pins 0.49, the last release that runs on Java 17.  This
module prepares that venv, exports the TBox in a form owlready2 can read,
and runs the script on plans given as VIRF facts.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from virf.errors import EnvironmentProblem, InputError, VirfError
from virf.ontology.iri import NS
from virf.ontology.tbox import TBox
from virf.processes import guarded
from virf.schema import Fact, FactKind

# TBox individuals move here in the export: every one of them is punned with
# a class of the same name, which owlready2 cannot represent (see export_tbox).
INDIVIDUAL_NS = "http://virf.dev/ontology/individual#"
PAPER_VENV = ".venv-paper"
# One Pellet call may take this long.  With the 49 hand-written rules a call
# took about 3 s; with the household knowledge base one ran past 14 minutes.
PAPER_CALL_TIMEOUT_S = 120.0
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
        try:
            subprocess.run(cmd, check=True, capture_output=True, text=True)
        except (OSError, subprocess.CalledProcessError):
            raise EnvironmentProblem(f"cannot set up the paper baseline venv: {hint}") from None
    found = _owlready2_version(python)
    if found != wanted:
        raise EnvironmentProblem(f"{venv} has owlready2 {found or 'missing'}, not {wanted}: {hint}")
    return python


def _owlready2_version(python: Path) -> str | None:
    if not python.exists():
        return None
    try:
        done = subprocess.run(
            [str(python), "-c", "import owlready2; print(owlready2.VERSION)"],
            capture_output=True,
            text=True,
            check=True,
        )
    except (OSError, subprocess.CalledProcessError):
        return None
    return done.stdout.strip()


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
    call_timeout_s: float | None = PAPER_CALL_TIMEOUT_S,
) -> dict[str, Any]:
    """Time the paper's per-step reasoner call on every snapshot of ``plans``.

    ``plans`` holds ``(plan_id, snapshots)`` with each snapshot a list of
    facts.  ``python`` defaults to the ``.venv-paper`` of the checkout this
    module lives in (created on first use).  Returns the script's OUT.json:
    per plan ``step_ms``, ``total_ms``, ``findings`` and ``consistent`` per
    snapshot (a snapshot that failed in Java, or whose reasoner call took
    more than ``call_timeout_s``, is ``{"error": ...}`` instead).

    The files go to ``workdir``, or to a temporary folder removed at the end,
    however it comes (an error, Ctrl-C, SIGTERM; after SIGKILL, by the
    script's guard).  The script, and the JVMs it starts, end with this
    process (:func:`virf.processes.guarded`).
    """
    unknown = [c for c in concepts if c not in tbox.vocabulary.classes]
    if unknown:
        raise InputError(f"unknown concept '{unknown[0]}'")
    if python is None:
        python = ensure_paper_env(_checkout_root())
    if workdir is not None:
        return _run_in(tbox, plans, concepts, Path(workdir).resolve(), python, call_timeout_s)
    work = Path(tempfile.mkdtemp(prefix="virf-paper-"))
    try:
        return _run_in(tbox, plans, concepts, work, python, call_timeout_s, temporary=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _run_in(
    tbox: TBox,
    plans: Sequence[PaperPlan],
    concepts: Sequence[str],
    work: Path,
    python: str | Path,
    call_timeout_s: float | None,
    *,
    temporary: bool = False,
) -> dict[str, Any]:
    work.mkdir(parents=True, exist_ok=True)
    tbox_path = work / "tbox.owl"
    export_tbox(tbox, tbox_path)
    job = {
        "tbox": str(tbox_path),
        "namespace": NS,
        "individual_namespace": INDIVIDUAL_NS,
        "concepts": list(concepts),
        "call_timeout_s": call_timeout_s,
        "plans": [
            {"id": pid, "snapshots": [[fact_json(f) for f in snap] for snap in snaps]}
            for pid, snaps in plans
        ],
    }
    job_path, out_path = work / "job.json", work / "out.json"
    job_path.write_text(json.dumps(job, indent=1), encoding="utf-8")
    out_path.unlink(missing_ok=True)
    last = _stream(
        [str(python), str(SCRIPT), str(job_path), str(out_path)], work if temporary else None
    )
    if last is not None:
        raise EnvironmentProblem(f"paper baseline failed: {last.removeprefix('error: ')}")
    result: dict[str, Any] = json.loads(out_path.read_text(encoding="utf-8"))
    return result


def _stream(cmd: list[str], temporary: Path | None = None) -> str | None:
    """Run ``cmd``, echoing its progress lines; its last line if it failed.

    The command and all it starts end with this process, however it ends;
    ``temporary`` is its folder, removed by the guard if this process dies
    first (:func:`virf.processes.guarded`)."""
    last = ""
    try:
        with guarded(cmd, remove=temporary, stderr=subprocess.PIPE, text=True) as proc:
            assert proc.stderr is not None
            for line in proc.stderr:
                sys.stderr.write(line)
                last = line.strip() or last
            code = proc.wait()
    except OSError as exc:
        return f"cannot start {cmd[0]}: {exc.strerror}"
    if code == 0:
        return None
    return last or f"exit code {code}"


def _checkout_root() -> Path:
    # src/virf/bench/paper.py -> the repository root, where .venv-paper lives.
    return Path(__file__).resolve().parents[3]
