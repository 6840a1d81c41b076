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
import resource
import statistics
import tempfile
import time
import tracemalloc
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from virf.api import LogicTutor
from virf.bench.case import Case
from virf.bench.coldstart import cold_start_rows
from virf.bench.latency_cases import (
    CHAIN_PLAN,
    chain_case,
    hazard_chain_case,
    room_groups,
    sample,
    synthetic_case,
    synthetic_modules,
    synthetic_scene,
)
from virf.bench.latency_figures import (
    ChainRow,
    ColdStart,
    DeadlineRow,
    FastTimings,
    HazardChainRow,
    Identical,
    LatencyFigures,
    Machine,
    Memory,
    PaperComparison,
    PaperRow,
    PaperTimings,
    ReferenceTimings,
    RoomTimings,
    ScalingRow,
    TBoxRow,
)
from virf.bench.metrics import comparable, percentile
from virf.bench.paper import OVER_LIMIT, PAPER_CALL_LIMIT_S
from virf.errors import InputError
from virf.ontology.jvm import java_version
from virf.ontology.tbox import TBox, load_tbox
from virf.reasoning import Engine, make_engine
from virf.schema import Fact, Report
from virf.verify.verifier import Verifier
from virf.world.scene import build_scene

# A figure with nothing behind it (no plan timed) is NaN, not a number that
# could pass for a time.
NOT_MEASURED = float("nan")
SCENE_SIZES = (20, 50, 200, 1000)
PLAN_LENGTHS = (10, 20, 40, 80)
CHAIN_LENGTHS = (100, 300, 1000)
# The deadline rows: chains that take each engine several times the timeout.
DEADLINE_S = 0.5
DEADLINE_CHAINS = (("fast", 4000), ("reference", 3000))
HAZARD_CHAINS = (10, 100)


def deadline_row(tbox: TBox, engine: Engine, boxes: int, timeout_s: float) -> DeadlineRow:
    """How long a verification that cannot finish in time takes to give up."""
    case = chain_case(boxes, tbox)
    verifier = LogicTutor.over(tbox, engine, timeout_s=timeout_s).verifier
    start = time.perf_counter()
    report = case.verify(verifier)
    return DeadlineRow(
        engine=engine.name,
        objects=boxes,
        timeout_s=timeout_s,
        status=report.status,
        elapsed_ms=round((time.perf_counter() - start) * 1000, 1),
    )


def time_plans(
    verifier: Verifier,
    cases: Sequence[Case],
    repeats: int,
    tick: Callable[[], None] | None = None,
    firsts: list[float] | None = None,
) -> tuple[list[float], list[Report]]:
    """Per-case median wall time (ms) of a full verification, and the
    reports; each case's first run also goes into ``firsts``."""
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
            report = case.verify(verifier)
            runs.append((time.perf_counter() - start) * 1000)
        assert report is not None
        times.append(statistics.median(runs))
        if firsts is not None:
            firsts.append(runs[0])
        reports.append(report)
        if tick:
            tick()
    return times, reports


def timings(values: Sequence[float]) -> dict[str, float]:
    """Median, 95th percentile and mean, as the fields of a :class:`Timings`;
    each NaN (not measured) without values."""
    if not values:
        return {"p50_ms": NOT_MEASURED, "p95_ms": NOT_MEASURED, "mean_ms": NOT_MEASURED}
    return {
        "p50_ms": round(percentile(values, 50), 2),
        "p95_ms": round(percentile(values, 95), 2),
        "mean_ms": round(statistics.fmean(values), 2),
    }


def _paper_plans(verifier: Verifier, cases: Sequence[Case]) -> list[tuple[str, list[list[Fact]]]]:
    return [(c.name, [sorted(s) for s in verifier.snapshots(c.scene, c.plan)]) for c in cases]


# The paper baseline's result is JSON its own process wrote
# (:func:`virf.bench.paper.run_paper_baseline`): read as such, not typed here.
TimedPlan = dict[str, Any]


def _paper_plan_ms(plan: TimedPlan) -> tuple[float, bool] | None:
    """Sequential time of the paper's loop, steps up to its first finding,
    and whether that time is exact: it is a lower bound when a call was
    stopped at the limit first (that call counts as the limit)."""
    total = 0.0
    for ms, found, consistent in zip(
        plan["step_ms"], plan["findings"], plan["consistent"], strict=False
    ):
        if _over_limit(found):
            return total + ms, False
        if ms is None or (consistent is None and isinstance(found, dict)):
            return None  # a call failed: the plan has no time
        total += ms
        if found or consistent is False:
            break
    return total, True


def _paper_row(plan: TimedPlan, time: tuple[float, bool] | None) -> PaperRow:
    return PaperRow(
        plan=plan["id"],
        ms=None if time is None else round(time[0], 1),
        lower_bound=time is not None and not time[1],
        calls=tuple(
            OVER_LIMIT if _over_limit(found) else ms
            for ms, found in zip(plan["step_ms"], plan["findings"], strict=False)
        ),
    )


def _over_limit(found: object) -> bool:
    return isinstance(found, dict) and found.get("error") == OVER_LIMIT


def paper_figures(
    result: dict[str, Any], fast_ms: dict[str, float], compared: Sequence[str]
) -> PaperComparison:
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
    paper = PaperTimings(
        **timings(paper_ms),
        plans=len(paper_ms),
        plans_lower_bound=bounded,
        lower_bound=bounded > 0,
        calls=len(steps),
        calls_over_limit=calls_over,
        call_limit_s=limit,
        per_call_p50_ms=round(percentile(step_ms, 50), 1) if step_ms else NOT_MEASURED,
        per_call_lower_bound=calls_over > 0,
        owlready2=result.get("owlready2"),
        peak_rss_mb=_paper_rss(result),
        # Every plan, each call's time or "> limit".
        rows=tuple(_paper_row(plan, times[plan["id"]]) for plan in result["plans"]),
    )
    fast_p50 = percentile(list(fast_ms.values()), 50)
    return PaperComparison(
        paper=paper,
        ratio=round(statistics.median(ratios), 1) if ratios else None,
        ratio_of_medians=round(paper.p50_ms / fast_p50, 1) if paper_ms else None,
        ratio_lower_bound=bounded > 0,
        paper_call_limit_s=limit,
    )


def _paper_rss(result: dict[str, Any]) -> float | None:
    peak = result.get("peak_rss_kb")
    if isinstance(peak, dict):
        values = [v for v in peak.values() if isinstance(v, (int, float))]
        return round(max(values) / 1024, 1) if values else None
    if isinstance(peak, (int, float)):
        return round(peak / 1024, 1)
    return None


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
) -> LatencyFigures:
    """All figures of ``virf bench latency``.  ``cold``: the scene and plan
    whose cold start to first verdict is timed, as fresh processes."""

    def bar(label: str, total: int) -> Callable[[], None]:
        return progress(label, total) if progress else (lambda: None)

    # The sections measured, as LatencyFigures' fields; one left out was not.
    out: dict[str, object] = {}
    # First, while this process holds no JVM and no caches that could slow
    # the machine down for the fresh processes.
    if cold is not None and cold_runs > 0:
        tick = bar("cold start", len(cold_engines) * (cold_runs + 1))
        rows = cold_start_rows(*cold, engines=cold_engines, runs=cold_runs, tick=tick)
        if rows:
            out["cold_start"] = ColdStart(example=str(cold[0].parent), rows=tuple(rows))

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
    machine = Machine(
        cpus=os.cpu_count(),
        python=platform.python_version(),
        platform=platform.platform(),
        java=java_version(),
    )
    rss_start = rss_mb()

    # (c) fast engine: a warm-up pass, then the median of `repeats` runs per plan.
    tick = bar("fast engine: warm-up", len(cases))
    for group in rooms:
        time_plans(group.fast, group.cases, 1, tick)
    stats_before = [group.fast.engine.stats() for group in rooms]
    tick = bar("fast engine", len(cases))
    fast_ms, fast_reports = [], []
    fast_first: list[float] = []
    by_room = []
    for group in rooms:
        group_ms, group_reports = time_plans(group.fast, group.cases, repeats, tick, fast_first)
        fast_ms += group_ms
        fast_reports += group_reports
        by_room.append(RoomTimings(room=group.room, plans=len(group.cases), **timings(group_ms)))
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
        case.verify(rooms[0].fast)
    fast_heap = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    rss_fast = rss_mb()

    # (b) reference engine, one run per plan (after a short JVM warm-up).
    ref_cases = sample(cases, reference_sample)
    chosen = {c.name for c in ref_cases}
    for case in ref_cases[:3]:
        case.verify(vr)
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
    # b/c on the plans timed both ways, as a/c is.
    fast_of = {c.name: ms for c, ms in zip(cases, fast_ms, strict=True)}
    both = [r / fast_of[c.name] for c, r in zip(ref_cases, ref_ms, strict=True) if fast_of[c.name]]
    first_of = {c.name: ms for c, ms in zip(cases, fast_first, strict=True)}
    both_first = [
        r / first_of[c.name] for c, r in zip(ref_cases, ref_ms, strict=True) if first_of[c.name]
    ]

    # Scaling with scene size (the 10-step plan) and plan length (50 objects).
    # The reference engine is also timed with two workers (parallel steps).
    vr2 = LogicTutor.over(tbox, reference.fork(), workers=2).verifier

    def scaling_row(case: Case, requested: int | None = None) -> ScalingRow:
        f_ms, f_rep = time_plans(vf, [case], repeats)
        r_ms, r_rep = time_plans(vr, [case], 1)
        p_ms, p_rep = time_plans(vr2, [case], 1)
        row = ScalingRow(
            objects=len(case.scene.objects),
            steps=len(case.plan),
            status=f_rep[0].status,
            fast_ms=round(f_ms[0], 2),
            reference_ms=round(r_ms[0], 1),
            reference_2_workers_ms=round(p_ms[0], 1),
            identical=comparable(f_rep[0]) == comparable(r_rep[0]) == comparable(p_rep[0]),
        )
        # Only a scene-size row says the size asked for.
        return row if requested is None else row.model_copy(update={"requested_objects": requested})

    by_size = []
    tick = bar("scene scaling", len(synthetic))
    for n, case in zip(sizes, synthetic, strict=True):
        by_size.append(scaling_row(case, n))
        tick()
    by_length = []
    tick = bar("plan-length scaling", len(lengths))
    for steps in lengths:
        by_length.append(scaling_row(synthetic_case(50, tbox, steps)))
        tick()
    by_depth = []
    tick = bar("containment chains", len(chains))
    for boxes in chains:
        c_ms, c_rep = time_plans(vf, [chain_case(boxes, tbox)], repeats)
        by_depth.append(
            ChainRow(
                objects=boxes,
                steps=len(CHAIN_PLAN),
                status=c_rep[0].status,
                fast_ms=round(c_ms[0], 2),
            )
        )
        tick()
    hazards = []
    tick = bar("hazard chains", len(HAZARD_CHAINS))
    for boxes in HAZARD_CHAINS:
        h_ms, h_rep = time_plans(vf, [hazard_chain_case(boxes, tbox)], repeats)
        found = h_rep[0].violations
        hazards.append(
            HazardChainRow(
                objects=boxes,
                status=h_rep[0].status,
                explained_facts=len(found[0].triggering_facts) if found else 0,
                fast_ms=round(h_ms[0], 2),
            )
        )
        tick()
    tick = bar("deadline", len(DEADLINE_CHAINS))
    deadlines = []
    for which, boxes in DEADLINE_CHAINS:
        deadlines.append(
            deadline_row(tbox, fast if which == "fast" else reference, boxes, deadline_s)
        )
        tick()

    # (a) the paper's method, on a sample of the same plans and the smaller scenes.
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
        compared = paper_figures(result, fast_by_name, [c.name for c in paper_cases])
        out |= {name: getattr(compared, name) for name in PaperComparison.model_fields}
        by_plan = {row.plan: row for row in compared.paper.rows}
        for i, row in enumerate(by_size):
            timed = by_plan.get(f"synthetic-{row.size}")
            by_size[i] = row.model_copy(
                update={
                    "paper_ms": timed.ms if timed else None,
                    "paper_lower_bound": bool(timed and timed.lower_bound),
                }
            )
    else:
        out |= {"paper_call_limit_s": paper_call_limit_s, "ratio": None}

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
                TBoxRow(
                    factor=factor,
                    logical_axioms=len(big.owl.logical_axioms()),
                    fast_ms=round(f_ms[0], 2),
                    reference_ms=round(r_ms[0], 1),
                    identical=comparable(f_rep[0]) == comparable(r_rep[0]),
                )
            )
            tick()
    return LatencyFigures.model_validate(
        {
            "machine": machine,
            "plans": len(cases),
            "repeats": repeats,
            "rooms": tuple(by_room),
            "fast": FastTimings(
                **timings(fast_ms),
                reasoner_calls=calls,
                fallbacks=falls,
                python_heap_peak_mb=round(fast_heap, 1),
                first_run_p50_ms=round(percentile(fast_first, 50), 2) if fast_first else None,
                first_run_ratio=round(statistics.median(both_first), 1) if both_first else None,
            ),
            "reference": ReferenceTimings(**timings(ref_ms), plans=len(ref_cases)),
            "identical_reports": Identical(compared=len(ref_cases), identical=identical),
            "reference_ratio": round(statistics.median(both), 1) if both else None,
            "memory": Memory(
                process_rss_after_tbox_mb=round(rss_start, 1),
                process_rss_peak_after_fast_mb=round(rss_fast, 1),
                process_rss_peak_after_reference_mb=round(rss_ref, 1),
                fast_python_heap_peak_mb=round(fast_heap, 1),
            ),
            "scene_scaling": tuple(by_size),
            "length_scaling": tuple(by_length),
            "chain_scaling": tuple(by_depth),
            "hazard_chains": tuple(hazards),
            "deadline": tuple(deadlines),
            "tbox_scaling": tuple(tb_rows),
            **out,
        }
    )
