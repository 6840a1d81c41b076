"""``virf bench latency``: how long verification takes, three ways, on the same inputs.

* (a) the paper's method: owlready2 + Pellet, one reasoner call per step on a
  fresh copy of ontology + ABox (:mod:`virf.bench.paper`, its own venv);
* (b) the reference engine (HermiT in-process, :mod:`virf.reasoning.reference`);
* (c) the fast engine (:mod:`virf.reasoning.fast`).

(b) and (c) time the whole Logic Tutor (simulation, classification of every
snapshot, minimal explanations, report); (a) times the paper's reasoner calls
for the same snapshots, stopping at the first snapshot where it finds a
hazard, as the paper's loop does; a call past ``--paper-call-limit`` is
stopped and counted as the limit, and every figure that rests on it is
reported as a lower bound ("≥").  Inputs: the SafeAgentBench reference plans
given on the command line, and a 10-step plan over synthetic kitchens of
growing size.  The TBox scaling rows load extra synthetic domain modules
(copies of the kitchen layer under new class names).  The containment rows
time the fast engine on chains of boxes nested ever deeper (``encloses`` is
transitive), and the deadline rows how soon each engine stops once a
verification's timeout has passed.
"""

from __future__ import annotations

import gc
import os
import platform
import re
import resource
import statistics
import tempfile
import time
import tracemalloc
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from virf.api import LogicTutor
from virf.bench.case import Case
from virf.bench.coldstart import cold_start_rows
from virf.bench.metrics import comparable, percentile
from virf.bench.paper import OVER_LIMIT, PAPER_CALL_LIMIT_S
from virf.bench.safeagentbench import ROOMS, UNKNOWN_ROOM, UnparsedPlan, load_tasks
from virf.errors import InputError
from virf.ontology.jvm import java_version
from virf.ontology.tbox import TBox, load_tbox, ontology_dir
from virf.reasoning import Engine, make_engine
from virf.render.tables import TextTable, to_markdown
from virf.schema import Report
from virf.verify.verifier import Verifier
from virf.world.plan import parse_plan
from virf.world.scene import build_scene

# A figure with nothing behind it (no plan timed) is NaN, not a number that
# could pass for a time.
NOT_MEASURED = float("nan")
SCENE_SIZES = (20, 50, 200, 1000)
PLAN_LENGTHS = (10, 20, 40, 80)
CHAIN_LENGTHS = (100, 300, 1000)
# Moves the outermost box of a chain and puts it back: the whole chain moves
# with it, and every snapshot holds the chain.
CHAIN_PLAN = ("find Box_0", "pick Box_0", "find CounterTop_1", "put CounterTop_1")
# The deadline rows: chains that take each engine several times the timeout.
DEADLINE_S = 0.5
DEADLINE_CHAINS = (("fast", 4000), ("reference", 3000))
# Ten safe steps that put everything back where it was, so a plan of any
# multiple of ten steps is the cycle repeated (after the first pass, which also
# marks objects as found and near, every pass ends in the same state).
SYNTHETIC_CYCLE = (
    "find Apple_1",
    "pick Apple_1",
    "find Fridge_1",
    "open Fridge_1",
    "put Fridge_1",
    "find Apple_1",
    "pick Apple_1",
    "close Fridge_1",
    "find CounterTop_1",
    "put CounterTop_1",
)
# Harmless things to fill a kitchen with (only types the catalogue knows are used).
FILLER = [
    "Apple",
    "Bread",
    "Tomato",
    "Potato",
    "Lettuce",
    "Egg",
    "Mug",
    "Cup",
    "Bowl",
    "Plate",
    "Fork",
    "Spoon",
    "ButterKnife",
    "Spatula",
    "Ladle",
    "SaltShaker",
    "PepperShaker",
    "DishSponge",
    "PaperTowelRoll",
    "Bottle",
    "Book",
    "CreditCard",
    "Vase",
    "Statue",
    "Kettle",
    "Pan",
    "Pot",
    "WineBottle",
    "SoapBottle",
    "Newspaper",
    "KeyChain",
    "CellPhone",
    "Pen",
    "Pencil",
    "Watch",
    "TissueBox",
    "Box",
    "Candle",
]


def dev_cases(files: Sequence[str | Path], tbox: TBox, room: str | None = None) -> list[Case]:
    """Every task in ``files`` that ships a reference plan (only those of
    ``room``, a room's scenario name, when given)."""
    vocab = tbox.vocabulary
    out = []
    for f in files:
        for task in load_tasks(f):
            if not task.steps or (room is not None and task.room.name != room):
                continue
            where = "" if task.room.name == "kitchen" else f"{task.room.name}/"
            try:
                out.append(task.to_case(vocab, name=f"{where}{Path(task.file).name}:{task.line}"))
            except UnparsedPlan:
                continue
    return out


@dataclass(frozen=True)
class RoomGroup:
    """One room's dev plans, with verifiers over the room's rules."""

    room: str
    cases: list[Case]
    fast: Verifier
    reference: Verifier


def room_groups(
    files: Sequence[str | Path], kitchen: TBox, fast: Engine, reference: Engine
) -> list[RoomGroup]:
    """The tasks with a reference plan in ``files``, by room (the kitchen's
    with the given engines, each other room's with engines of its own)."""
    groups = []
    for room in (*ROOMS, UNKNOWN_ROOM):
        tbox = kitchen if room.name == "kitchen" else load_tbox(room.name)
        cases = dev_cases(files, tbox, room=room.name)
        if not cases:
            continue
        engines = (
            (fast, reference)
            if tbox is kitchen
            else (
                make_engine("fast", tbox),
                make_engine("reference", tbox),
            )
        )
        verifiers = [LogicTutor.over(tbox, engine).verifier for engine in engines]
        groups.append(RoomGroup(room.name, cases, *verifiers))
    return groups


def synthetic_scene(objects: int, tbox: TBox) -> dict[str, Any]:
    """A kitchen with ``objects`` objects on which the synthetic plan runs safely."""
    vocab = tbox.vocabulary
    fixed = [
        ("Fridge", "Fridge_1"),
        ("DiningTable", "DiningTable_1"),
        ("Microwave", "Microwave_1"),
        ("Sink", "Sink_1"),
        ("Faucet", "Faucet_1"),
        ("Apple", "Apple_1"),
        ("Mug", "Mug_1"),
    ]
    if objects < len(fixed) + 2:
        raise InputError(f"a synthetic scene needs at least {len(fixed) + 2} objects")
    instances = [{"class_name": c, "instance_name": n} for c, n in fixed]
    assertions: list[dict[str, str]] = [
        {"subject": "Fridge_1", "property": "hasState", "object": "ClosedState"},
        {"subject": "Microwave_1", "property": "hasState", "object": "ClosedState"},
        {"subject": "Microwave_1", "property": "hasState", "object": "OffState"},
        {"subject": "Faucet_1", "property": "hasState", "object": "OffState"},
        {"subject": "Mug_1", "property": "hasState", "object": "EmptyState"},
    ]
    counters = max(1, (objects - len(fixed)) // 10)
    for i in range(1, counters + 1):
        instances.append({"class_name": "CounterTop", "instance_name": f"CounterTop_{i}"})
    assertions.append({"subject": "Apple_1", "property": "isOn", "object": "CounterTop_1"})
    assertions.append({"subject": "Mug_1", "property": "isOn", "object": "CounterTop_1"})
    kinds = [k for k in FILLER if k in vocab.classes]
    seen: dict[str, int] = {"Apple": 1, "Mug": 1}
    i = 0
    while len(instances) < objects:
        kind = kinds[i % len(kinds)]
        seen[kind] = seen.get(kind, 0) + 1
        name = f"{kind}_{seen[kind]}"
        instances.append({"class_name": kind, "instance_name": name})
        place = f"CounterTop_{i % counters + 1}"
        assertions.append({"subject": name, "property": "isOn", "object": place})
        i += 1
    return {
        "description": f"synthetic kitchen with {objects} objects",
        "instances": instances,
        "assertions": assertions,
        "unlocated_by_default": True,
    }


def synthetic_case(objects: int, tbox: TBox, steps: int = 10) -> Case:
    """The synthetic kitchen with the ten-step cycle repeated to ``steps`` steps."""
    vocab = tbox.vocabulary
    scene = build_scene(synthetic_scene(objects, tbox), vocab, name=f"synthetic-{objects}")
    cycles = max(1, steps // len(SYNTHETIC_CYCLE))
    name = f"synthetic-{objects}" + (f"x{steps}" if steps != len(SYNTHETIC_CYCLE) else "")
    return Case(name, scene, parse_plan(list(SYNTHETIC_CYCLE) * cycles))


def chain_scene(boxes: int) -> dict[str, Any]:
    """Box_0 on a counter, Box_1 inside it, Box_2 inside Box_1, and so on:
    containment ``boxes`` deep, whose transitive closure has boxes²/2 pairs."""
    instances = [{"class_name": "CounterTop", "instance_name": "CounterTop_1"}]
    instances += [{"class_name": "Box", "instance_name": f"Box_{i}"} for i in range(boxes)]
    assertions = [{"subject": "Box_0", "property": "isOn", "object": "CounterTop_1"}]
    assertions += [
        {"subject": f"Box_{i}", "property": "contains", "object": f"Box_{i + 1}"}
        for i in range(boxes - 1)
    ]
    return {
        "description": f"{boxes} boxes, each inside the previous one",
        "instances": instances,
        "assertions": assertions,
    }


def chain_case(boxes: int, tbox: TBox) -> Case:
    scene = build_scene(chain_scene(boxes), tbox.vocabulary, name=f"chain-{boxes}")
    return Case(f"chain-{boxes}", scene, parse_plan(list(CHAIN_PLAN)))


HAZARD_CHAIN_PLAN = ("find Box_0", "pick Box_0", "find Vase_1", "drop Box_0")
HAZARD_CHAINS = (10, 100)


def hazard_chain_case(boxes: int, tbox: TBox) -> Case:
    """The containment chain with a dumbbell in the innermost box and a vase
    on the counter: dropping Box_0 by the vase is a hazard through the whole
    chain, so its explanation lists every link (boxes + 5 facts)."""
    data = chain_scene(boxes)
    data["instances"] += [
        {"class_name": "Dumbbell", "instance_name": "Dumbbell_1"},
        {"class_name": "Vase", "instance_name": "Vase_1"},
    ]
    data["assertions"] += [
        {"subject": f"Box_{boxes - 1}", "property": "contains", "object": "Dumbbell_1"},
        {"subject": "Vase_1", "property": "isOn", "object": "CounterTop_1"},
    ]
    scene = build_scene(data, tbox.vocabulary, name=f"hazard-chain-{boxes}")
    return Case(f"hazard-chain-{boxes}", scene, parse_plan(list(HAZARD_CHAIN_PLAN)))


def deadline_row(tbox: TBox, engine: Engine, boxes: int, timeout_s: float) -> dict[str, Any]:
    """How long a verification that cannot finish in time takes to give up."""
    case = chain_case(boxes, tbox)
    verifier = LogicTutor.over(tbox, engine, timeout_s=timeout_s).verifier
    start = time.perf_counter()
    report = verifier.verify(case.scene, case.plan)
    return {
        "engine": engine.name,
        "objects": boxes,
        "timeout_s": timeout_s,
        "status": report.status,
        "elapsed_ms": round((time.perf_counter() - start) * 1000, 1),
    }


def synthetic_modules(copies: int, folder: Path) -> tuple[str, ...]:
    """``copies`` renamed copies of the kitchen domain layer (for TBox scaling)."""
    source = (ontology_dir() / "kitchen.omn").read_text(encoding="utf-8")
    names = sorted(set(re.findall(r"^Class: :(\w+)", source, flags=re.M)), key=len, reverse=True)
    pattern = re.compile(r":(" + "|".join(re.escape(n) for n in names) + r")\b")
    out = []
    for k in range(1, copies + 1):
        text = pattern.sub(lambda m, k=k: f":Syn{k}_{m.group(1)}", source)  # type: ignore[misc]
        text = text.replace(
            "<http://virf.dev/ontology/kitchen>", f"<http://virf.dev/ontology/synthetic-{k}>"
        )
        text = re.sub(r':id "([^"]+)"', lambda m, k=k: f':id "SYN{k}-{m.group(1)}"', text)  # type: ignore[misc]
        path = folder / f"synthetic-{k}.omn"
        path.write_text(text, encoding="utf-8")
        out.append(str(path))
    return tuple(out)


def time_plans(
    verifier: Verifier, cases: Sequence[Case], repeats: int, tick: Callable[[], None] | None = None
) -> tuple[list[float], list[Report]]:
    """Per-case median wall time (ms) of a full verification, and the reports."""
    # What earlier phases left on the heap (reports, TBoxes) is moved out of
    # the collector's reach, so it does not tax the cases timed now.
    gc.collect()
    gc.freeze()
    times, reports = [], []
    for case in cases:
        runs = []
        report = None
        for _ in range(repeats):
            start = time.perf_counter()
            report = verifier.verify(case.scene, case.plan, case.requirements)
            runs.append((time.perf_counter() - start) * 1000)
        assert report is not None
        times.append(statistics.median(runs))
        reports.append(report)
        if tick:
            tick()
    return times, reports


def summary(values: Sequence[float]) -> dict[str, float]:
    """Median, 95th percentile and mean; each NaN (not measured) without values."""
    if not values:
        return {"p50_ms": NOT_MEASURED, "p95_ms": NOT_MEASURED, "mean_ms": NOT_MEASURED}
    return {
        "p50_ms": round(percentile(values, 50), 2),
        "p95_ms": round(percentile(values, 95), 2),
        "mean_ms": round(statistics.fmean(values), 2),
    }


def sample(cases: Sequence[Case], n: int) -> list[Case]:
    """``n`` cases spread evenly over the list (all when n <= 0 or n >= len)."""
    if n <= 0 or n >= len(cases):
        return list(cases)
    step = len(cases) / n
    return [cases[int(i * step)] for i in range(n)]


def _paper_plans(verifier: Verifier, cases: Sequence[Case]) -> list[tuple[str, list[list[Any]]]]:
    return [(c.name, [sorted(s) for s in verifier.snapshots(c.scene, c.plan)]) for c in cases]


def _paper_plan_ms(plan: dict[str, Any]) -> tuple[float, bool] | None:
    """Sequential time of the paper's loop, steps up to its first finding,
    and whether that time is exact: it is a lower bound when a call was
    stopped at the limit first (that call counts as the limit)."""
    total = 0.0
    for ms, found, consistent in zip(
        plan["step_ms"], plan["findings"], plan["consistent"], strict=False
    ):
        if isinstance(found, dict) and found.get("error") == OVER_LIMIT:
            return total + ms, False
        if ms is None or (consistent is None and isinstance(found, dict)):
            return None  # a call failed: the plan has no time
        total += ms
        if found or consistent is False:
            break
    return total, True


def _paper_row(plan: dict[str, Any], time: tuple[float, bool] | None) -> dict[str, Any]:
    return {
        "plan": plan["id"],
        "ms": None if time is None else round(time[0], 1),
        "lower_bound": time is not None and not time[1],
        "calls": [
            OVER_LIMIT if _over_limit(found) else ms
            for ms, found in zip(plan["step_ms"], plan["findings"], strict=False)
        ],
    }


def _over_limit(found: Any) -> bool:
    return isinstance(found, dict) and found.get("error") == OVER_LIMIT


def paper_figures(
    result: dict[str, Any], fast_ms: dict[str, float], compared: Sequence[str]
) -> dict[str, Any]:
    """The paper method's figures from :func:`virf.bench.paper.run_paper_baseline`'s
    result: ``compared`` names the dev-split plans (timed by the fast engine in
    ``fast_ms`` too), the others are scaling rows.  A figure computed from a
    plan with a call stopped at the limit is a lower bound, and says so."""
    times = {plan["id"]: _paper_plan_ms(plan) for plan in result["plans"]}
    timed = [(name, times[name]) for name in compared if times.get(name) is not None]
    paper_ms = [t[0] for _, t in timed if t is not None]
    bounded = sum(1 for _, t in timed if t is not None and not t[1])
    ratios = [t[0] / fast_ms[name] for name, t in timed if t is not None]
    steps = [s for p in result["plans"] for s in zip(p["step_ms"], p["findings"], strict=False)]
    step_ms = [ms for ms, _ in steps if isinstance(ms, (int, float))]
    calls_over = sum(1 for _, found in steps if _over_limit(found))
    limit = result.get("call_limit_s")
    paper: dict[str, Any] = summary(paper_ms) | {
        "plans": len(paper_ms),
        "plans_lower_bound": bounded,
        "lower_bound": bounded > 0,
        "calls": len(steps),
        "calls_over_limit": calls_over,
        "call_limit_s": limit,
        "per_call_p50_ms": round(percentile(step_ms, 50), 1) if step_ms else NOT_MEASURED,
        "per_call_lower_bound": calls_over > 0,
        "owlready2": result.get("owlready2"),
        "peak_rss_mb": _paper_rss(result),
        # Every plan, each call's time or "> limit".
        "rows": [_paper_row(plan, times[plan["id"]]) for plan in result["plans"]],
    }
    fast_p50 = percentile(list(fast_ms.values()), 50)
    return {
        "paper": paper,
        "paper_p50_ms": paper["p50_ms"],
        "ratio": round(statistics.median(ratios), 1) if ratios else None,
        "ratio_of_medians": round(paper["p50_ms"] / fast_p50, 1) if paper_ms else None,
        # A median of lower bounds is a lower bound of the median.
        "ratio_lower_bound": bounded > 0,
        "paper_call_limit_s": limit,
    }


def rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def run_latency(
    files: Sequence[str | Path],
    *,
    repeats: int = 3,
    reference_sample: int = 0,
    paper_sample: int = 20,
    paper: bool = True,
    sizes: Sequence[int] = SCENE_SIZES,
    paper_max_objects: int = 200,
    paper_call_limit_s: float = PAPER_CALL_LIMIT_S,
    tbox_factors: Sequence[int] = (1, 4),
    lengths: Sequence[int] = PLAN_LENGTHS,
    chains: Sequence[int] = CHAIN_LENGTHS,
    deadline_s: float = DEADLINE_S,
    cold: tuple[Path, Path] | None = None,
    cold_runs: int = 5,
    cold_engines: Sequence[str] = ("fast", "reference"),
    progress: Callable[[str, int], Callable[[], None]] | None = None,
) -> dict[str, Any]:
    """All figures of ``virf bench latency`` as one dict.  ``cold``: the scene
    and plan whose cold start to first verdict is timed, as fresh processes."""

    def bar(label: str, total: int) -> Callable[[], None]:
        return progress(label, total) if progress else (lambda: None)

    # First, while this process holds no JVM and no caches that could slow
    # the machine down for the fresh processes.
    cold_rows: list[dict[str, Any]] = []
    if cold is not None and cold_runs > 0:
        tick = bar("cold start", len(cold_engines) * (cold_runs + 1))
        cold_rows = cold_start_rows(*cold, engines=cold_engines, runs=cold_runs, tick=tick)

    tbox = load_tbox()
    fast = make_engine("fast", tbox)
    reference = make_engine("reference", tbox)
    vf, vr = LogicTutor.over(tbox, fast).verifier, LogicTutor.over(tbox, reference).verifier
    # Each room's plans with its own rules, as `virf bench safeagentbench` checks them.
    rooms = room_groups(files, tbox, fast, reference)
    cases = [c for group in rooms for c in group.cases]
    if not cases:
        raise InputError("no task with a reference plan in the given files")
    synthetic = [synthetic_case(n, tbox) for n in sizes]
    out: dict[str, Any] = {
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "platform": platform.platform(),
            "java": java_version(),
        },
        "plans": len(cases),
        "repeats": repeats,
    }
    if cold_rows:
        out["cold_start"] = {"example": str(cold[0].parent) if cold else "", "rows": cold_rows}
    rss_start = rss_mb()

    # (c) fast engine: a warm-up pass, then the median of `repeats` runs per plan.
    tick = bar("fast engine: warm-up", len(cases))
    for group in rooms:
        time_plans(group.fast, group.cases, 1, tick)
    stats_before = [group.fast.engine.stats() for group in rooms]
    tick = bar("fast engine", len(cases))
    fast_ms, fast_reports = [], []
    for group in rooms:
        group_ms, group_reports = time_plans(group.fast, group.cases, repeats, tick)
        fast_ms += group_ms
        fast_reports += group_reports
        out.setdefault("rooms", []).append({"room": group.room, "plans": len(group.cases)})
        out["rooms"][-1] |= summary(group_ms)
    stats_after = [group.fast.engine.stats() for group in rooms]
    calls = sum(
        a.get("calls", 0) - b.get("calls", 0)
        for a, b in zip(stats_after, stats_before, strict=True)
    )
    falls = sum(
        a.get("fallbacks", 0) - b.get("fallbacks", 0)
        for a, b in zip(stats_after, stats_before, strict=True)
    )
    tracemalloc.start()
    for case in rooms[0].cases[:20]:
        rooms[0].fast.verify(case.scene, case.plan, case.requirements)
    fast_heap = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    rss_fast = rss_mb()

    # (b) reference engine, one run per plan (after a short JVM warm-up).
    ref_cases = sample(cases, reference_sample)
    chosen = {c.name for c in ref_cases}
    for case in ref_cases[:3]:
        vr.verify(case.scene, case.plan, case.requirements)
    tick = bar("reference engine", len(ref_cases))
    ref_ms, ref_reports = [], []
    for group in rooms:
        picked = [c for c in group.cases if c.name in chosen]
        group_ms, group_reports = time_plans(group.reference, picked, 1, tick)
        ref_ms += group_ms
        ref_reports += group_reports
    ref_cases = [c for group in rooms for c in group.cases if c.name in chosen]
    rss_ref = rss_mb()
    index = {c.name: i for i, c in enumerate(cases)}
    identical = sum(
        comparable(r) == comparable(fast_reports[index[c.name]])
        for c, r in zip(ref_cases, ref_reports, strict=True)
    )
    out["fast"] = summary(fast_ms) | {
        "reasoner_calls": calls,
        "fallbacks": falls,
        "python_heap_peak_mb": round(fast_heap, 1),
    }
    out["reference"] = summary(ref_ms) | {"plans": len(ref_cases)}
    out["identical_reports"] = {"compared": len(ref_cases), "identical": identical}
    # b/c on the plans timed both ways, as a/c is.
    fast_of = {c.name: ms for c, ms in zip(cases, fast_ms, strict=True)}
    both = [r / fast_of[c.name] for c, r in zip(ref_cases, ref_ms, strict=True) if fast_of[c.name]]
    out["reference_ratio"] = round(statistics.median(both), 1) if both else None
    out["memory"] = {
        "process_rss_after_tbox_mb": round(rss_start, 1),
        "process_rss_peak_after_fast_mb": round(rss_fast, 1),
        "process_rss_peak_after_reference_mb": round(rss_ref, 1),
        "fast_python_heap_peak_mb": round(fast_heap, 1),
    }
    out["fast_p50_ms"] = out["fast"]["p50_ms"]
    out["fast_p95_ms"] = out["fast"]["p95_ms"]
    out["reference_p50_ms"] = out["reference"]["p50_ms"]
    out["reference_p95_ms"] = out["reference"]["p95_ms"]

    # Scaling with scene size (the 10-step plan) and plan length (50 objects).
    # The reference engine is also timed with two workers (parallel steps).
    vr2 = LogicTutor.over(tbox, reference.fork(), workers=2).verifier

    def scaling_row(case: Case) -> dict[str, Any]:
        f_ms, f_rep = time_plans(vf, [case], repeats)
        r_ms, r_rep = time_plans(vr, [case], 1)
        p_ms, p_rep = time_plans(vr2, [case], 1)
        return {
            "objects": len(case.scene.objects),
            "steps": len(case.plan),
            "status": f_rep[0].status,
            "fast_ms": round(f_ms[0], 2),
            "reference_ms": round(r_ms[0], 1),
            "reference_2_workers_ms": round(p_ms[0], 1),
            "identical": comparable(f_rep[0]) == comparable(r_rep[0]) == comparable(p_rep[0]),
        }

    rows = []
    tick = bar("scene scaling", len(synthetic))
    for n, case in zip(sizes, synthetic, strict=True):
        rows.append(scaling_row(case) | {"requested_objects": n})
        tick()
    out["scene_scaling"] = rows
    by_length = []
    tick = bar("plan-length scaling", len(lengths))
    for steps in lengths:
        by_length.append(scaling_row(synthetic_case(50, tbox, steps)))
        tick()
    out["length_scaling"] = by_length
    by_depth = []
    tick = bar("containment chains", len(chains))
    for boxes in chains:
        c_ms, c_rep = time_plans(vf, [chain_case(boxes, tbox)], repeats)
        by_depth.append(
            {
                "objects": boxes,
                "steps": len(CHAIN_PLAN),
                "status": c_rep[0].status,
                "fast_ms": round(c_ms[0], 2),
            }
        )
        tick()
    out["chain_scaling"] = by_depth
    hazards = []
    tick = bar("hazard chains", len(HAZARD_CHAINS))
    for boxes in HAZARD_CHAINS:
        h_ms, h_rep = time_plans(vf, [hazard_chain_case(boxes, tbox)], repeats)
        found = h_rep[0].violations
        hazards.append(
            {
                "objects": boxes,
                "status": h_rep[0].status,
                "explained_facts": len(found[0].triggering_facts) if found else 0,
                "fast_ms": round(h_ms[0], 2),
            }
        )
        tick()
    out["hazard_chains"] = hazards
    tick = bar("deadline", len(DEADLINE_CHAINS))
    out["deadline"] = []
    for which, boxes in DEADLINE_CHAINS:
        out["deadline"].append(
            deadline_row(tbox, fast if which == "fast" else reference, boxes, deadline_s)
        )
        tick()

    # (a) the paper's method, on a sample of the same plans and the smaller scenes.
    out["paper_call_limit_s"] = paper_call_limit_s
    if paper:
        from virf.bench.paper import run_paper_baseline

        # The paper's method exports the kitchen's TBox: the kitchen's plans.
        paper_cases = sample([c for c in cases if not c.name.count("/")], paper_sample)
        small = [c for c, n in zip(synthetic, sizes, strict=True) if n <= paper_max_objects]
        # In a temporary folder of its own, removed whatever happens.
        result = run_paper_baseline(
            tbox,
            _paper_plans(vf, paper_cases + small),
            sorted(tbox.vocabulary.uscs),
            call_limit_s=paper_call_limit_s,
        )
        fast_by_name = {c.name: ms for c, ms in zip(cases, fast_ms, strict=True)}
        out |= paper_figures(result, fast_by_name, [c.name for c in paper_cases])
        by_plan = {row["plan"]: row for row in out["paper"]["rows"]}
        for row in rows:
            timed = by_plan.get(f"synthetic-{row['requested_objects']}")
            row["paper_ms"] = timed["ms"] if timed else None
            row["paper_lower_bound"] = bool(timed and timed["lower_bound"])
    else:
        out["paper_p50_ms"] = None
        out["ratio"] = None

    # Scaling with TBox size: x1 and xN (N-1 synthetic copies of the kitchen layer).
    tb_rows = []
    base_case = next((c for c in synthetic if c.name == "synthetic-50"), synthetic[0])
    tick = bar("TBox scaling", len(tbox_factors))
    with tempfile.TemporaryDirectory(prefix="virf-tbox-") as work:
        for factor in tbox_factors:
            extra = synthetic_modules(factor - 1, Path(work)) if factor > 1 else ()
            big = load_tbox("kitchen", extra)
            engines: list[Engine] = [make_engine("fast", big), make_engine("reference", big)]
            vfb, vrb = [LogicTutor.over(big, engine).verifier for engine in engines]
            scene = build_scene(synthetic_scene(50, big), big.vocabulary, name=base_case.name)
            case = Case(base_case.name, scene, base_case.plan)
            time_plans(vfb, [case], 1)
            f_ms, f_rep = time_plans(vfb, [case], repeats)
            r_ms, r_rep = time_plans(vrb, [case], 1)
            tb_rows.append(
                {
                    "factor": factor,
                    "logical_axioms": len(big.owl.logical_axioms()),
                    "fast_ms": round(f_ms[0], 2),
                    "reference_ms": round(r_ms[0], 1),
                    "identical": comparable(f_rep[0]) == comparable(r_rep[0]),
                }
            )
            tick()
    out["tbox_scaling"] = tb_rows
    return out


def _paper_rss(result: dict[str, Any]) -> float | None:
    peak = result.get("peak_rss_kb")
    if isinstance(peak, dict):
        values = [v for v in peak.values() if isinstance(v, (int, float))]
        return round(max(values) / 1024, 1) if values else None
    if isinstance(peak, (int, float)):
        return round(peak / 1024, 1)
    return None


# The tables below are printed by `virf bench latency` and written into
# performance.md from the same rows; the terminal words some headers shorter.


COLD_TARGET_S = 0.25
# The figures issue 29 asks for (printed beside the measured ones).
TARGETS = {
    "p50_ms": 4.0,
    "p95_ms": 10.0,
    "vs_reference": 300.0,
    "vs_paper": 300.0,
    "objects_1000_ms": 50.0,
    "chain_1000_ms": 100.0,
    "hazard_chain_100_ms": 100.0,
}


def targets_table(fig: dict[str, Any]) -> TextTable:
    """Each figure issue 29 asks for, beside what this run measured."""

    def row_ms(key: str, objects: int) -> float | None:
        rows = fig.get(key, [])
        return next(
            (r["fast_ms"] for r in rows if r.get("requested_objects", r["objects"]) == objects),
            None,
        )

    fast = fig["fast"]
    cold = next(
        (r for r in fig.get("cold_start", {}).get("rows", []) if r["engine"] == "fast"), None
    )
    rows: list[tuple[str, str, float | None, bool]] = [
        ("fast p50 per plan, ms", "≤", fast["p50_ms"], True),
        ("fast p95 per plan, ms", "≤", fast["p95_ms"], True),
        ("reference / fast (b/c), ×", "≥", fig.get("reference_ratio"), False),
        ("paper / fast (a/c), ×", "≥", fig.get("ratio"), False),
        ("cold first verdict, s", "≤", cold["median_s"] if cold else None, True),
        ("10-step plan, 1,000 objects, ms", "≤", row_ms("scene_scaling", 1000), True),
        ("1,000-box chain, ms", "≤", row_ms("chain_scaling", 1000), True),
        ("100-box hazard chain explained, ms", "≤", row_ms("hazard_chains", 100), True),
    ]
    goals = [
        TARGETS["p50_ms"],
        TARGETS["p95_ms"],
        TARGETS["vs_reference"],
        TARGETS["vs_paper"],
        COLD_TARGET_S,
        TARGETS["objects_1000_ms"],
        TARGETS["chain_1000_ms"],
        TARGETS["hazard_chain_100_ms"],
    ]
    table = []
    for (name, way, value, at_most), goal in zip(rows, goals, strict=True):
        if value is None or value != value:
            table.append((name, f"{way} {goal:g}", "not measured", "-"))
            continue
        met = value <= goal if at_most else value >= goal
        shown = f"{value:.0f}" if "×" in name else f"{value:.3g}"
        if name.startswith("paper") and fig.get("ratio_lower_bound"):
            shown = f"≥ {shown}"  # a lower bound that meets the goal meets it
        table.append((name, f"{way} {goal:g}", shown, "yes" if met else "no"))
    return TextTable.of(("figure", "target", "measured", "met"), table)


def reference_ratio(fig: dict[str, Any]) -> str:
    """How many times faster the fast engine is than the reference engine."""
    value = fig.get("reference_ratio")
    return "not measured" if not value else f"{value:g}×"


def cold_start_table(fig: dict[str, Any]) -> TextTable:
    """Cold start to first verdict, one row per engine."""
    return TextTable.of(
        ("engine", "verdict", "runs", "median s", "min s", "max s"),
        [
            (
                row["engine"],
                row["verdict"],
                str(row["runs"]),
                f"{row['median_s']:.3f}",
                f"{row['min_s']:.3f}",
                f"{row['max_s']:.3f}",
            )
            for row in fig.get("cold_start", {}).get("rows", [])
        ],
    )


def at_least(value: float, lower_bound: bool, digits: int = 0) -> str:
    """A figure, written "≥ N" when it is a lower bound."""
    return ("≥ " if lower_bound else "") + f"{value:.{digits}f}"


def ratio_text(fig: dict[str, Any], key: str = "ratio") -> str:
    """Ratio a/c as "N×", "≥ N×" when a plan it was computed from hit the
    call limit, or "not measured"."""
    value = fig.get(key)
    if value is None:
        return "not measured"
    return ("≥ " if fig.get("ratio_lower_bound") else "") + f"{value:g}×"


def latency_table(fig: dict[str, Any], *, terminal: bool) -> TextTable:
    """Per-plan latency of (a), (b) and (c); the terminal adds a note per method."""
    fast, ref, paper = fig["fast"], fig["reference"], fig.get("paper")
    rows: list[tuple[str, ...]] = []
    if paper:
        bound = paper.get("lower_bound", False)
        per_call = at_least(paper["per_call_p50_ms"], paper.get("per_call_lower_bound", False))
        over = ""
        if paper.get("calls_over_limit"):
            over = (
                f"; {paper['calls_over_limit']} of {paper['calls']} calls "
                f"{OVER_LIMIT} ({paper['call_limit_s']:g} s)"
            )
        rows.append(
            (
                "(a) paper: owlready2 + Pellet per step",
                str(paper["plans"]),
                at_least(paper["p50_ms"], bound),
                at_least(paper["p95_ms"], bound),
                at_least(paper["mean_ms"], bound),
                f"per call p50 {per_call} ms{over}; owlready2 {paper['owlready2']}",
            )
        )
    rows += [
        (
            "(b) reference engine (HermiT)",
            str(ref["plans"]),
            f"{ref['p50_ms']:.0f}",
            f"{ref['p95_ms']:.0f}",
            f"{ref['mean_ms']:.0f}",
            "with minimal explanations",
        ),
        (
            "(c) fast engine",
            str(fig["plans"]),
            f"{fast['p50_ms']:.1f}",
            f"{fast['p95_ms']:.1f}",
            f"{fast['mean_ms']:.1f}",
            f"{fast['reasoner_calls']} calls, {fast['fallbacks']} fallbacks",
        ),
    ]
    if terminal:
        return TextTable.of(
            ("method", "plans", "p50 ms", "p95 ms", "mean ms", "note"),
            rows,
            title=f"Per-plan verification latency ({fig['plans']} SafeAgentBench plans)",
        )
    return TextTable.of(
        ("method", "plans timed", "p50 ms", "p95 ms", "mean ms"), [r[:-1] for r in rows]
    )


def scaling_table(fig: dict[str, Any], key: str, *, terminal: bool) -> TextTable:
    """``key`` is scene_scaling (per object) or length_scaling (per step)."""
    per = "objects" if key == "scene_scaling" else "steps"
    rows = []
    for row in fig[key]:
        size = row.get("requested_objects", row["objects"]) if per == "objects" else row["steps"]
        paper_ms = row.get("paper_ms")
        rows.append(
            (
                str(size),
                row["status"],
                f"{row['fast_ms']:.1f}",
                f"{row['fast_ms'] / size:.3f}",
                f"{row['reference_ms']:.0f}",
                f"{row['reference_2_workers_ms']:.0f}",
                "-"
                if paper_ms is None
                else at_least(paper_ms, row.get("paper_lower_bound", False)),
                "yes" if row["identical"] else "NO",
            )
        )
    one = per.rstrip("s")
    if terminal:
        title = {
            "objects": "Scaling with scene size (10-step plan)",
            "steps": "Scaling with plan length (50-object scene)",
        }[per]
        return TextTable.of(
            (
                per,
                "verdict",
                "fast ms",
                f"fast ms/{one}",
                "reference ms",
                "reference, 2 workers",
                "paper ms",
                "same",
            ),
            rows,
            title=title,
        )
    return TextTable.of(
        (
            per,
            "verdict",
            "fast ms",
            f"fast ms per {one}",
            "reference ms",
            "reference, 2 workers, ms",
            "paper ms",
            "reports identical",
        ),
        rows,
    )


def tbox_table(fig: dict[str, Any], *, terminal: bool) -> TextTable:
    rows = [
        (
            f"x{row['factor']}",
            str(row["logical_axioms"]),
            f"{row['fast_ms']:.1f}",
            f"{row['reference_ms']:.0f}",
            "yes" if row["identical"] else "NO",
        )
        for row in fig["tbox_scaling"]
    ]
    same = "same" if terminal else "reports identical"
    return TextTable.of(
        ("TBox", "logical axioms", "fast ms", "reference ms", same),
        rows,
        title="Scaling with TBox size (50-object scene, 10-step plan)" if terminal else None,
    )


def chain_markdown(fig: dict[str, Any]) -> list[str]:
    """The containment-chain and deadline sections of performance.md."""
    lines: list[str] = []
    if fig.get("chain_scaling"):
        lines += [
            "",
            "## Scaling with containment depth (fast engine)",
            "",
            f"Boxes nested in one another, Box_0 on a counter, and a {len(CHAIN_PLAN)}-step plan",
            "that moves Box_0 and puts it back. `encloses` is transitive, so the chain's",
            "closure has n²/2 pairs; the fast engine does not materialise it",
            "([fast-engine.md](fast-engine.md)).",
            "",
        ]
        chain = TextTable.of(
            ("boxes", "verdict", "fast ms", "fast ms per box"),
            [
                (
                    str(row["objects"]),
                    row["status"],
                    f"{row['fast_ms']:.1f}",
                    f"{row['fast_ms'] / row['objects']:.3f}",
                )
                for row in fig["chain_scaling"]
            ],
        )
        lines += to_markdown(chain)
    if fig.get("hazard_chains"):
        lines += [
            "",
            "The same chain with a dumbbell in the innermost box and a vase on the counter;",
            f"the plan ({', '.join(HAZARD_CHAIN_PLAN)}) drops Box_0 by the vase. The hazard",
            "runs through every link, and the report's minimal explanation lists them all:",
            "",
        ]
        hazard = TextTable.of(
            ("boxes", "verdict", "facts in the explanation", "fast ms"),
            [
                (
                    str(row["objects"]),
                    row["status"],
                    str(row["explained_facts"]),
                    f"{row['fast_ms']:.1f}",
                )
                for row in fig["hazard_chains"]
            ],
        )
        lines += to_markdown(hazard)
    if fig.get("deadline"):
        lines += [
            "",
            "## The deadline",
            "",
            "`--timeout` is one deadline for the whole verification. The engines stop inside",
            "a step once it passes, and the report is ERROR (fail closed). Chains that take",
            "each engine several times the timeout:",
            "",
        ]
        deadline = TextTable.of(
            ("engine", "boxes", "timeout s", "verdict", "stopped after ms"),
            [
                (
                    row["engine"],
                    str(row["objects"]),
                    f"{row['timeout_s']:g}",
                    row["status"],
                    f"{row['elapsed_ms']:.0f}",
                )
                for row in fig["deadline"]
            ],
        )
        lines += to_markdown(deadline)
    return lines


def render_markdown(fig: dict[str, Any], command: str) -> str:
    """docs/performance.md: the figures of one run, the machine, how to reproduce."""
    m = fig["machine"]
    fast = fig["fast"]
    paper = fig.get("paper")
    same = fig["identical_reports"]
    limit = fig.get("paper_call_limit_s") or PAPER_CALL_LIMIT_S
    lines = [
        "# Performance",
        "",
        "<!-- GENERATED by `virf bench latency --markdown`; edit latency.py, not this file. -->",
        "",
        "How long the Logic Tutor takes to verify a plan, measured three ways on the same inputs:",
        "",
        "* **(a) the paper's method**: owlready2 0.49 with its bundled Pellet, one reasoner call",
        "  per plan step on a fresh copy of ontology + ABox, stopping at the first step where",
        "  it finds a hazard (the paper's loop). It runs in its own virtualenv (`.venv-paper`):",
        "  owlready2 0.50/0.51 bundle jars built for Java 25 and fail on Java 17.",
        f"  A reasoner call still running after {limit:g} s (`--paper-call-limit`) is stopped,",
        "  with its JVM and every process it started, and counts as that long: the plan",
        "  stops there and its time is a lower bound, written ≥, as is every median, mean",
        "  and ratio a/c computed from it. A plan whose every call finished is an exact",
        "  figure; a plan with a call that failed has no time.",
        "* **(b) the reference engine**: HermiT 1.4 in-process (OWLAPI 5 through JPype), one",
        "  fresh reasoner per question, including the minimal explanations of the report.",
        "* **(c) the fast engine** (the default): the same reports from compiled rules and",
        "  verified candidate models ([fast-engine.md](fast-engine.md)).",
        "",
        "(b) and (c) time the whole `Verifier.verify` call: simulation, classification of",
        "every snapshot, minimal triggering facts, background axioms and the report. (a) times",
        "only the reasoner calls. The fast engine's time per plan is the median of",
        f"{fig.get('repeats', 3)} runs after one warm-up pass; the reference engine's and the",
        "paper method's are single runs. Before each timed phase the benchmark runs",
        "`gc.collect(); gc.freeze()`, so what earlier phases left on the heap does not tax it.",
        "",
        "## Machine",
        "",
        f"* {m['cpus']} CPUs, Python {m['python']}, Java {m['java']}",
        f"* {m['platform']}",
        "",
        "## Per-plan latency on the SafeAgentBench dev split",
        "",
        f"{fig['plans']} reference plans (every task in the given files that ships one),",
        "each verified with its room's rules.",
        "",
        *to_markdown(latency_table(fig, terminal=False)),
        "",
    ]
    if fig.get("rooms"):
        by_room = TextTable.of(
            ("room", "plans", "fast p50 ms", "fast p95 ms"),
            [
                (r["room"], str(r["plans"]), f"{r['p50_ms']:.1f}", f"{r['p95_ms']:.1f}")
                for r in fig["rooms"]
            ],
        )
        lines += ["The fast engine by room:", "", *to_markdown(by_room), ""]
    lines += [
        f"* **ratio a/c** (median over the plans timed both ways): **{ratio_text(fig)}**"
        + (
            f"; ratio of the medians: {ratio_text(fig, 'ratio_of_medians')}"
            if fig.get("ratio_of_medians")
            else ""
        ),
        f"* reports of (b) and (c) identical: **{same['identical']}/{same['compared']}**",
        f"* fast engine: {fast['reasoner_calls']} engine calls, **{fast['fallbacks']}** handed to "
        "the reference engine",
    ]
    if paper:
        per_call = at_least(paper["per_call_p50_ms"], paper.get("per_call_lower_bound", False))
        lines.append(
            f"* paper method: one reasoner call takes {per_call} ms (p50); "
            "each call starts a JVM and classifies the whole TBox again"
        )
        if "calls_over_limit" in paper:
            lines.append(
                f"* paper method: **{paper['calls_over_limit']}** of its {paper['calls']} "
                f"reasoner calls hit the {paper['call_limit_s']:g} s limit and were stopped; "
                f"{paper['plans_lower_bound']} of the {paper['plans']} plans timed are "
                "lower bounds"
            )
    lines += [
        "",
        "Targets (issue 29): with explanations, over the dev plans of every room, fast",
        f"p50 at most {TARGETS['p50_ms']:g} ms and p95 at most {TARGETS['p95_ms']:g} ms per plan;",
        f"at least {TARGETS['vs_reference']:g}× faster than the reference engine (b/c) and"
        f" {TARGETS['vs_paper']:g}× than the paper's method (a/c), each the median of the",
        f"per-plan ratios over the plans timed both ways. This run: b/c = {reference_ratio(fig)},",
        f"a/c = {ratio_text(fig)}. Every target beside this run's figure: [Targets](#targets).",
        "",
    ]
    cold = fig.get("cold_start")
    if cold:
        lines += [
            "## Cold start to first verdict",
            "",
            f"`virf verify` on `{cold['example']}` as a fresh process, from start to exit:",
            "interpreter, imports, loading the knowledge base, simulation, classification,",
            "the printed report. The fast engine reads the compiled knowledge artifact and",
            "does not start the JVM; the reference engine starts it and loads the modules.",
            "One uncounted run first fills the file cache and Python's bytecode cache, as",
            "after any installation.",
            "",
            *to_markdown(cold_start_table(fig)),
            "",
            f"Target: the fast engine's median at most {COLD_TARGET_S} s.",
            "",
        ]
    lines += [
        "## Memory",
        "",
    ]
    mem = fig["memory"]
    lines += [
        f"* process RSS after loading the TBox (JVM included): {mem['process_rss_after_tbox_mb']:.0f} MB",
        f"* peak RSS after the fast-engine runs: {mem['process_rss_peak_after_fast_mb']:.0f} MB; "
        f"Python heap peak of the fast engine (tracemalloc): {mem['fast_python_heap_peak_mb']:.1f} MB",
        f"* peak RSS after the reference-engine runs: "
        f"{mem['process_rss_peak_after_reference_mb']:.0f} MB",
    ]
    if paper and paper.get("peak_rss_mb"):
        lines.append(
            f"* paper method: peak RSS {paper['peak_rss_mb']:.0f} MB (script plus its Pellet JVMs)"
        )
    for key, title in (
        ("scene_scaling", "Scaling with scene size (the same 10-step plan)"),
        ("length_scaling", "Scaling with plan length (50-object scene)"),
    ):
        lines += ["", f"## {title}", "", *to_markdown(scaling_table(fig, key, terminal=False))]
    lines += chain_markdown(fig)
    lines += ["", "## Targets", "", *to_markdown(targets_table(fig))]
    lines += [
        "",
        "## Scaling with TBox size (50-object scene, 10-step plan)",
        "",
        "x4 adds three synthetic domain modules: copies of the kitchen layer with renamed",
        "classes, loaded as extra imports.",
        "",
        *to_markdown(tbox_table(fig, terminal=False)),
    ]
    lines += [
        "",
        "## Reproduce",
        "",
        "```",
        "make bench-latency      # creates .venv-paper (owlready2 0.49) on first use",
        command,
        "```",
        "",
        "`--json` prints every figure as one object (`ratio`, `fast_p50_ms`, `fast_p95_ms`,",
        "`reference_p50_ms`, `paper_p50_ms`, the scaling rows, memory, machine). Under",
        "`paper`, `rows` gives each plan's time and each call's, `\"> limit\"` for a call",
        "stopped; `lower_bound` and `ratio_lower_bound` say which figures are lower bounds.",
        "`--paper-sample N` times the paper's method on N plans spread over the split",
        "(0 = all; each of its calls takes seconds to minutes); `--paper-call-limit S` stops",
        "a call after S seconds; `--no-paper` skips the paper's method.",
        "",
    ]
    return "\n".join(lines)
