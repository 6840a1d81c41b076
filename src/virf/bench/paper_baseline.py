"""The paper's per-step verification call, timed: owlready2 + its bundled Pellet.

Runs inside ``.venv-paper`` (owlready2 0.49), never inside VIRF's venv, so it
imports nothing but the standard library and owlready2::

    python paper_baseline.py JOB.json OUT.json

JOB.json::

    {"tbox": "/abs/tbox.owl", "namespace": "http://virf.dev/ontology#",
     "individual_namespace": "http://virf.dev/ontology/individual#",
     "concepts": ["FridgeLeftOpenDanger", ...],
     "plans": [{"id": "p1", "snapshots": [[fact, ...], ...]}]}

A fact is ``{"s", "p", "o", "kind", "members"}`` with kind ``type`` (s is an
``o``), ``object`` (s p o), ``data`` (s p true|false) or ``closure`` (s is a
``p only {members}``, ``p only Nothing`` when there are none).  Objects that
the TBox already names (``Metal``, ``OnState``) are its individuals, looked up
in ``individual_namespace`` (optional, default ``namespace``) first;
``virf.bench.paper.export_tbox`` moves them there.

OUT.json: ``owlready2`` and ``java`` versions; per plan ``id``, ``step_ms``,
``total_ms``, ``findings`` (per snapshot a list of ``{"concept",
"individual"}``, or ``{"error": ...}`` when that snapshot failed) and
``consistent`` (per snapshot; ``null`` on error); ``peak_rss_kb`` with
``self`` and ``children`` (getrusage) and ``self_vmhwm``.

Every snapshot costs what one step of the paper's verifier costs, and all of
it is timed: a fresh World, loading the TBox file, building the ABox,
``sync_reasoner_pellet`` (a new JVM) and reading the concepts' instances.

Events, one JSON object a line on stdout, tell the caller how far the run is,
so that it can stop a call that runs past its limit (``virf.bench.paper``
does, with the whole process group: the JVM goes too)::

    {"event": "ready", "owlready2": "0.49", "java": "..."}
    {"event": "call", "plan": 0, "step": 0}            a reasoner call starts
    {"event": "step", "plan": 0, "step": 0, "ms": ..., "findings": [...],
     "consistent": true}                               it ended (findings as OUT.json)
    {"event": "end", "peak_rss_kb": {...}}

``plan`` counts the job's plans from 0.  Whatever else would reach stdout
(owlready2 or Java printing) goes to stderr instead, so the events stay
readable.
"""

from __future__ import annotations

import importlib
import json
import os
import resource
import subprocess
import sys
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any, TextIO

KINDS = ("type", "object", "data", "closure")

Emit = Callable[..., None]


class JobError(Exception):
    """The job file is malformed; one line says where."""


def main(argv: list[str] | None = None, events: TextIO | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    stream = sys.stdout if events is None else events

    def emit(event: str, **fields: Any) -> None:
        stream.write(json.dumps({"event": event, **fields}) + "\n")
        stream.flush()

    if len(args) != 2:
        print("usage: python paper_baseline.py JOB.json OUT.json", file=sys.stderr)
        return 2
    try:
        job = load_job(Path(args[0]))
    except JobError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        # Imported here so that a wrong interpreter gets one clear line.
        owl: Any = importlib.import_module("owlready2")
    except ImportError:
        print(
            f"error: owlready2 is not installed for {sys.executable}; "
            "run this script with .venv-paper/bin/python",
            file=sys.stderr,
        )
        return 2
    out: dict[str, Any] = {
        "owlready2": str(owl.VERSION),
        "java": java_version(str(owl.JAVA_EXE)),
        "plans": [],
    }
    emit("ready", owlready2=out["owlready2"], java=out["java"])
    plans = job["plans"]
    for n, plan in enumerate(plans, 1):
        out["plans"].append(run_plan(owl, job, plan, partial(emit, plan=n - 1)))
        total = out["plans"][-1]["total_ms"]
        print(
            f"paper baseline: plan {n}/{len(plans)} {plan['id']}: "
            f"{len(plan['snapshots'])} snapshots, {total:.0f} ms",
            file=sys.stderr,
        )
    out["peak_rss_kb"] = {
        "self": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
        "children": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss,
        "self_vmhwm": vm_hwm_kb(),
    }
    emit("end", peak_rss_kb=out["peak_rss_kb"])
    try:
        Path(args[1]).write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    except OSError as exc:
        print(f"error: cannot write {args[1]}: {exc.strerror}", file=sys.stderr)
        return 2
    return 0


def load_job(path: Path) -> dict[str, Any]:
    try:
        job = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise JobError(f"cannot read job file {path}: {exc.strerror}") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise JobError(f"job file {path} is not JSON: {exc}") from None
    if not isinstance(job, dict):
        raise JobError("job must be a JSON object")
    for key in ("tbox", "namespace"):
        if not isinstance(job.get(key), str) or not job[key]:
            raise JobError(f"job needs a string '{key}'")
    if not Path(job["tbox"]).is_file():
        raise JobError(f"TBox file not found: {job['tbox']}")
    job.setdefault("individual_namespace", job["namespace"])
    concepts = job.get("concepts")
    if not isinstance(concepts, list) or not all(isinstance(c, str) for c in concepts):
        raise JobError("job needs 'concepts', a list of class names")
    plans = job.get("plans")
    if not isinstance(plans, list):
        raise JobError("job needs 'plans', a list")
    for i, plan in enumerate(plans):
        where = f"plans[{i}]"
        if not isinstance(plan, dict) or not isinstance(plan.get("snapshots"), list):
            raise JobError(f"{where} needs 'id' and a list 'snapshots'")
        plan["id"] = str(plan.get("id", i))
        for k, snapshot in enumerate(plan["snapshots"]):
            if not isinstance(snapshot, list):
                raise JobError(f"{where}.snapshots[{k}] is not a list of facts")
            for j, fact in enumerate(snapshot):
                check_fact(fact, f"{where}.snapshots[{k}][{j}]")
    return job


def check_fact(fact: Any, where: str) -> None:
    if not isinstance(fact, dict) or fact.get("kind") not in KINDS:
        raise JobError(f"{where}: a fact needs 'kind', one of {', '.join(KINDS)}")
    for key in ("s", "p", "o"):
        if not isinstance(fact.get(key), str):
            raise JobError(f"{where}: '{key}' must be a string")
    if fact["kind"] == "data" and fact["o"] not in ("true", "false"):
        raise JobError(f"{where}: a data fact's 'o' must be 'true' or 'false'")
    members = fact.get("members", [])
    if not isinstance(members, list) or not all(isinstance(m, str) for m in members):
        raise JobError(f"{where}: 'members' must be a list of names")


def vm_hwm_kb() -> int | None:
    """This process's own peak RSS.  Linux keeps ``ru_maxrss`` across fork and
    exec, so RUSAGE_SELF also reports the parent's size at spawn time (about
    300 MB when VIRF's JVM process starts this script); VmHWM starts afresh
    at exec."""
    try:
        status = Path("/proc/self/status").read_text(encoding="ascii")
    except OSError:
        return None
    for line in status.splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1])
    return None


def java_version(java: str) -> str:
    try:
        done = subprocess.run([java, "-version"], capture_output=True, text=True, check=False)
    except OSError as exc:
        return f"unavailable ({java}: {exc.strerror})"
    lines = (done.stderr or done.stdout).splitlines()
    return lines[0].strip() if lines else "unknown"


def run_plan(
    owl: Any, job: dict[str, Any], plan: dict[str, Any], emit: Emit | None = None
) -> dict[str, Any]:
    step_ms: list[float] = []
    findings: list[Any] = []
    consistent: list[bool | None] = []
    for k, facts in enumerate(plan["snapshots"]):
        if emit:
            emit("call", step=k)
        ms, result = run_snapshot(owl, job, facts)
        step_ms.append(round(ms, 1))
        if "error" in result:
            findings.append(result)
            consistent.append(None)
        else:
            findings.append(result["findings"])
            consistent.append(result["consistent"])
        if emit:
            emit("step", step=k, ms=step_ms[-1], findings=findings[-1], consistent=consistent[-1])
    return {
        "id": plan["id"],
        "step_ms": step_ms,
        "total_ms": round(sum(step_ms), 1),
        "findings": findings,
        "consistent": consistent,
    }


def run_snapshot(
    owl: Any, job: dict[str, Any], facts: list[dict[str, Any]]
) -> tuple[float, dict[str, Any]]:
    """One reasoner call the paper's way; (wall ms, result or {"error": ...})."""
    start = time.perf_counter()
    world = owl.World()
    try:
        onto = world.get_ontology(Path(job["tbox"]).resolve().as_uri()).load()
        abox = build_abox(owl, world, onto, job, facts)
        try:
            owl.sync_reasoner_pellet(world, infer_property_values=True, debug=0)
        except owl.OwlReadyInconsistentOntologyError:
            return _ms(start), {"consistent": False, "findings": []}
        found = []
        for concept in job["concepts"]:
            cls = world[job["namespace"] + concept]
            if not isinstance(cls, owl.ThingClass):
                raise ValueError(f"concept '{concept}' is not a class of the TBox")
            hits = {i.iri for i in cls.instances(world=world)}
            found += [
                {"concept": concept, "individual": n} for n in sorted(abox) if abox[n] in hits
            ]
        return _ms(start), {"consistent": True, "findings": found}
    except Exception as exc:  # a Java failure or an owlready2 limit: this snapshot only
        return _ms(start), {"error": f"{type(exc).__name__}: {_first_line(str(exc))}"[:500]}
    finally:
        world.close()


def build_abox(
    owl: Any, world: Any, onto: Any, job: dict[str, Any], facts: list[dict[str, Any]]
) -> dict[str, str]:
    """Assert ``facts`` in ``onto``; the ABox individuals' names -> IRIs.

    Like VIRF's engines, the ABox is the facts' subjects and the objects of
    their property assertions; closure members do not count.
    """
    ns, ind_ns = job["namespace"], job["individual_namespace"]
    space = onto.get_namespace(ns)
    made: dict[str, Any] = {}

    def entity(name: str, want: type, what: str) -> Any:
        found = world[ns + name]
        if not isinstance(found, want):
            raise ValueError(f"'{name}' is not {what} of the TBox")
        return found

    def cls(name: str) -> Any:
        return entity(name, owl.ThingClass, "a class")

    types: dict[str, list[str]] = {}
    for f in facts:
        if f["kind"] == "type":
            types.setdefault(f["s"], []).append(f["o"])

    def individual(name: str) -> Any:
        if name in made:
            return made[name]
        found = world[ind_ns + name]
        if found is None:
            found = world[ns + name]
        if found is None:
            classes = [cls(c) for c in types.get(name, ())] or [owl.Thing]
            found = classes[0](name, namespace=space)
            for c in classes[1:]:
                found.is_a.append(c)
        elif isinstance(found, owl.Thing):
            for c in types.get(name, ()):
                found.is_a.append(cls(c))
        else:
            raise ValueError(f"'{name}' names a class or property of the TBox, not an individual")
        made[name] = found
        return found

    def prop(name: str, data: bool = False) -> Any:
        if data:
            return entity(name, owl.DataPropertyClass, "a data property")
        return entity(name, owl.ObjectPropertyClass, "an object property")

    abox: dict[str, str] = {}
    for f in facts:
        subject = individual(f["s"])
        abox[f["s"]] = subject.iri
        if f["kind"] == "object":
            value = individual(f["o"])
            abox[f["o"]] = value.iri
            prop(f["p"])[subject].append(value)
        elif f["kind"] == "data":
            prop(f["p"], data=True)[subject].append(f["o"] == "true")
        elif f["kind"] == "closure":
            members = [individual(m) for m in f.get("members", [])]
            filler = owl.OneOf(members) if members else owl.Nothing
            subject.is_a.append(prop(f["p"]).only(filler))
    return abox


def _first_line(message: str) -> str:
    """The line of a Java error that names the problem, not its stack frames."""
    lines = [ln.strip() for ln in message.splitlines()]
    useful = [
        ln for ln in lines if ln and not ln.startswith("at ") and ln != "Java error message is:"
    ]
    return useful[0] if useful else ""


def _ms(start: float) -> float:
    return (time.perf_counter() - start) * 1000.0


def event_stream() -> TextIO:
    """Stdout, kept for the events; file descriptor 1 itself now leads to
    stderr, so that nothing printed by owlready2 or a child can be mistaken
    for an event."""
    events = os.fdopen(os.dup(1), "w", encoding="utf-8")
    sys.stdout.flush()
    os.dup2(2, 1)
    return events


if __name__ == "__main__":
    sys.exit(main(events=event_stream()))
