"""How ``virf bench latency`` shows its figures: the terminal's tables and
docs/performance.md, built from the same rows (the terminal words some
headers shorter)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal, Protocol

from virf.bench.latency_cases import CHAIN_PLAN, HAZARD_CHAIN_PLAN
from virf.bench.latency_figures import (
    ChainRow,
    DeadlineRow,
    HazardChainRow,
    LatencyFigures,
    ScalingRow,
)
from virf.bench.paper import OVER_LIMIT, PAPER_CALL_LIMIT_S
from virf.render.tables import TextTable, to_markdown

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


def _fast_ms_at(
    rows: Sequence[ScalingRow] | Sequence[ChainRow] | Sequence[HazardChainRow], size: int
) -> float | None:
    """The fast engine's time on the row of that many objects (or boxes)."""
    return next(
        (r.fast_ms for r in rows if (r.size if isinstance(r, ScalingRow) else r.objects) == size),
        None,
    )


def targets_table(fig: LatencyFigures) -> TextTable:
    """Each figure issue 29 asks for, beside what this run measured."""
    cold_rows = fig.cold_start.rows if fig.cold_start else ()
    cold = next((r for r in cold_rows if r.engine == "fast"), None)
    rows: list[tuple[str, str, float | None, bool]] = [
        ("fast p50 per plan, ms", "≤", fig.fast.p50_ms, True),
        ("fast p95 per plan, ms", "≤", fig.fast.p95_ms, True),
        ("reference / fast (b/c), ×", "≥", fig.reference_ratio, False),
        ("paper / fast (a/c), ×", "≥", fig.ratio, False),
        ("cold first verdict, s", "≤", cold.median_s if cold else None, True),
        ("10-step plan, 1,000 objects, ms", "≤", _fast_ms_at(fig.scene_scaling, 1000), True),
        ("1,000-box chain, ms", "≤", _fast_ms_at(fig.chain_scaling, 1000), True),
        ("100-box hazard chain explained, ms", "≤", _fast_ms_at(fig.hazard_chains, 100), True),
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
        if name.startswith("paper") and fig.ratio_lower_bound:
            shown = f"≥ {shown}"  # a lower bound that meets the goal meets it
        table.append((name, f"{way} {goal:g}", shown, "yes" if met else "no"))
    return TextTable.of(("figure", "target", "measured", "met"), table)


def first_run_line(fig: LatencyFigures) -> str:
    """The fast engine on each plan's first run alone (nothing of the plan kept)."""
    fast = fig.fast
    if fast.first_run_p50_ms is None:
        return "* fast engine, first run of each plan: not measured"
    ratio = "not measured" if not fast.first_run_ratio else f"{fast.first_run_ratio:g}×"
    return (
        f"* fast engine, first run of each plan alone (after another plan's): "
        f"p50 {fast.first_run_p50_ms:.1f} ms; b/c on those runs {ratio}"
    )


def reference_ratio(fig: LatencyFigures) -> str:
    """How many times faster the fast engine is than the reference engine."""
    value = fig.reference_ratio
    return "not measured" if not value else f"{value:g}×"


def cold_start_table(fig: LatencyFigures) -> TextTable:
    """Cold start to first verdict, one row per engine."""
    return TextTable.of(
        ("engine", "verdict", "runs", "median s", "min s", "max s"),
        [
            (
                row.engine,
                row.verdict,
                str(row.runs),
                f"{row.median_s:.3f}",
                f"{row.min_s:.3f}",
                f"{row.max_s:.3f}",
            )
            for row in (fig.cold_start.rows if fig.cold_start else ())
        ],
    )


def at_least(value: float, lower_bound: bool, digits: int = 0) -> str:
    """A figure, written "≥ N" when it is a lower bound."""
    return ("≥ " if lower_bound else "") + f"{value:.{digits}f}"


class Ratios(Protocol):
    """The paper's method against the fast engine: a whole run's figures, or
    the paper's alone (:class:`~virf.bench.latency_figures.PaperComparison`)."""

    @property
    def ratio(self) -> float | None: ...
    @property
    def ratio_of_medians(self) -> float | None: ...
    @property
    def ratio_lower_bound(self) -> bool: ...


def ratio_text(fig: Ratios, key: Literal["ratio", "ratio_of_medians"] = "ratio") -> str:
    """Ratio a/c as "N×", "≥ N×" when a plan it was computed from hit the
    call limit, or "not measured"."""
    value = fig.ratio if key == "ratio" else fig.ratio_of_medians
    if value is None:
        return "not measured"
    return ("≥ " if fig.ratio_lower_bound else "") + f"{value:g}×"


def latency_table(fig: LatencyFigures, *, terminal: bool) -> TextTable:
    """Per-plan latency of (a), (b) and (c); the terminal adds a note per method."""
    fast, ref, paper = fig.fast, fig.reference, fig.paper
    rows: list[tuple[str, ...]] = []
    if paper:
        bound = paper.lower_bound
        per_call = at_least(paper.per_call_p50_ms, paper.per_call_lower_bound)
        over = ""
        if paper.calls_over_limit:
            limit = paper.call_limit_s
            over = f"; {paper.calls_over_limit} of {paper.calls} calls {OVER_LIMIT} ({limit:g} s)"
        rows.append(
            (
                "(a) paper: owlready2 + Pellet per step",
                str(paper.plans),
                at_least(paper.p50_ms, bound),
                at_least(paper.p95_ms, bound),
                at_least(paper.mean_ms, bound),
                f"per call p50 {per_call} ms{over}; owlready2 {paper.owlready2}",
            )
        )
    rows += [
        (
            "(b) reference engine (HermiT)",
            str(ref.plans),
            f"{ref.p50_ms:.0f}",
            f"{ref.p95_ms:.0f}",
            f"{ref.mean_ms:.0f}",
            "with minimal explanations",
        ),
        (
            "(c) fast engine",
            str(fig.plans),
            f"{fast.p50_ms:.1f}",
            f"{fast.p95_ms:.1f}",
            f"{fast.mean_ms:.1f}",
            f"{fast.reasoner_calls} calls, {fast.fallbacks} fallbacks",
        ),
    ]
    if terminal:
        return TextTable.of(
            ("method", "plans", "p50 ms", "p95 ms", "mean ms", "note"),
            rows,
            title=f"Per-plan verification latency ({fig.plans} SafeAgentBench plans)",
        )
    return TextTable.of(
        ("method", "plans timed", "p50 ms", "p95 ms", "mean ms"), [r[:-1] for r in rows]
    )


def scaling_table(
    fig: LatencyFigures, key: Literal["scene_scaling", "length_scaling"], *, terminal: bool
) -> TextTable:
    """``key`` is scene_scaling (per object) or length_scaling (per step)."""
    per = "objects" if key == "scene_scaling" else "steps"
    rows = []
    for row in fig.scene_scaling if key == "scene_scaling" else fig.length_scaling:
        size = row.size if per == "objects" else row.steps
        rows.append(
            (
                str(size),
                row.status,
                f"{row.fast_ms:.1f}",
                f"{row.fast_ms / size:.3f}",
                f"{row.reference_ms:.0f}",
                f"{row.reference_2_workers_ms:.0f}",
                "-" if row.paper_ms is None else at_least(row.paper_ms, row.paper_lower_bound),
                "yes" if row.identical else "NO",
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


def tbox_table(fig: LatencyFigures, *, terminal: bool) -> TextTable:
    rows = [
        (
            f"x{row.factor}",
            str(row.logical_axioms),
            f"{row.fast_ms:.1f}",
            f"{row.reference_ms:.0f}",
            "yes" if row.identical else "NO",
        )
        for row in fig.tbox_scaling
    ]
    same = "same" if terminal else "reports identical"
    return TextTable.of(
        ("TBox", "logical axioms", "fast ms", "reference ms", same),
        rows,
        title="Scaling with TBox size (50-object scene, 10-step plan)" if terminal else None,
    )


def chain_markdown(
    chains: Sequence[ChainRow], hazards: Sequence[HazardChainRow], deadlines: Sequence[DeadlineRow]
) -> list[str]:
    """The containment-chain and deadline sections of performance.md."""
    lines: list[str] = []
    if chains:
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
                    str(row.objects),
                    row.status,
                    f"{row.fast_ms:.1f}",
                    f"{row.fast_ms / row.objects:.3f}",
                )
                for row in chains
            ],
        )
        lines += to_markdown(chain)
    if hazards:
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
                    str(row.objects),
                    row.status,
                    str(row.explained_facts),
                    f"{row.fast_ms:.1f}",
                )
                for row in hazards
            ],
        )
        lines += to_markdown(hazard)
    if deadlines:
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
                    row.engine,
                    str(row.objects),
                    f"{row.timeout_s:g}",
                    row.status,
                    f"{row.elapsed_ms:.0f}",
                )
                for row in deadlines
            ],
        )
        lines += to_markdown(deadline)
    return lines


def render_markdown(fig: LatencyFigures, command: str) -> str:
    """docs/performance.md: the figures of one run, the machine, how to reproduce."""
    m = fig.machine
    fast = fig.fast
    paper = fig.paper
    same = fig.identical_reports
    limit = fig.paper_call_limit_s or PAPER_CALL_LIMIT_S
    lines = [
        "# Performance",
        "",
        "<!-- GENERATED by `virf bench latency --markdown`; edit bench/latency_report.py, not this file. -->",
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
        f"{fig.repeats} runs after one warm-up pass; the reference engine's and the",
        "paper method's are single runs. Before each timed phase the benchmark runs",
        "`gc.collect(); gc.freeze()`, so what earlier phases left on the heap does not tax it.",
        "Runs of the same plan follow one another, so each reuses the model of the",
        "scene's shared facts that the engine kept from the run before, and starts",
        "its first step from the run before's first step",
        "([fast-engine.md](fast-engine.md#work-done-once)), as a planner's repairs in",
        "one scene do; the first verification in a new scene also builds that model.",
        "Each plan's first timed run follows another plan's, so nothing of its own",
        "is kept: those runs are also reported alone, below the table by room.",
        "",
        "## Machine",
        "",
        f"* {m.cpus} CPUs, Python {m.python}, Java {m.java}",
        f"* {m.platform}",
        "",
        "## Per-plan latency on the SafeAgentBench dev split",
        "",
        f"{fig.plans} reference plans (every task in the given files that ships one),",
        "each verified with its room's rules.",
        "",
        *to_markdown(latency_table(fig, terminal=False)),
        "",
    ]
    if fig.rooms:
        by_room = TextTable.of(
            ("room", "plans", "fast p50 ms", "fast p95 ms"),
            [(r.room, str(r.plans), f"{r.p50_ms:.1f}", f"{r.p95_ms:.1f}") for r in fig.rooms],
        )
        lines += ["The fast engine by room:", "", *to_markdown(by_room), ""]
    lines += [
        f"* **ratio a/c** (median over the plans timed both ways): **{ratio_text(fig)}**"
        + (
            f"; ratio of the medians: {ratio_text(fig, 'ratio_of_medians')}"
            if fig.ratio_of_medians
            else ""
        ),
        first_run_line(fig),
        f"* reports of (b) and (c) identical: **{same.identical}/{same.compared}**",
        f"* fast engine: {fast.reasoner_calls} engine calls, **{fast.fallbacks}** handed to "
        "the reference engine",
    ]
    if paper:
        per_call = at_least(paper.per_call_p50_ms, paper.per_call_lower_bound)
        lines.append(
            f"* paper method: one reasoner call takes {per_call} ms (p50); "
            "each call starts a JVM and classifies the whole TBox again"
        )
        lines.append(
            f"* paper method: **{paper.calls_over_limit}** of its {paper.calls} "
            f"reasoner calls hit the {paper.call_limit_s:g} s limit and were stopped; "
            f"{paper.plans_lower_bound} of the {paper.plans} plans timed are "
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
    cold = fig.cold_start
    if cold:
        lines += [
            "## Cold start to first verdict",
            "",
            f"`virf verify` on `{cold.example}` as a fresh process, from start to exit:",
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
    mem = fig.memory
    lines += [
        f"* process RSS after loading the TBox (JVM included): {mem.process_rss_after_tbox_mb:.0f} MB",
        f"* peak RSS after the fast-engine runs: {mem.process_rss_peak_after_fast_mb:.0f} MB; "
        f"Python heap peak of the fast engine (tracemalloc): {mem.fast_python_heap_peak_mb:.1f} MB",
        f"* peak RSS after the reference-engine runs: "
        f"{mem.process_rss_peak_after_reference_mb:.0f} MB",
    ]
    if paper and paper.peak_rss_mb:
        lines.append(
            f"* paper method: peak RSS {paper.peak_rss_mb:.0f} MB (script plus its Pellet JVMs)"
        )
    scaling: tuple[tuple[Literal["scene_scaling", "length_scaling"], str], ...] = (
        ("scene_scaling", "Scaling with scene size (the same 10-step plan)"),
        ("length_scaling", "Scaling with plan length (50-object scene)"),
    )
    for key, title in scaling:
        lines += ["", f"## {title}", "", *to_markdown(scaling_table(fig, key, terminal=False))]
    lines += chain_markdown(fig.chain_scaling, fig.hazard_chains, fig.deadline)
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


def print_latency(fig: LatencyFigures) -> None:
    """The figures as ``virf bench latency`` prints them."""
    from rich.console import Console

    from virf.render.tables import to_rich

    console = Console(highlight=False, width=140)
    m = fig.machine
    console.print(f"machine: {m.cpus} CPUs, Python {m.python}, Java {m.java}, {m.platform}")
    console.print(to_rich(latency_table(fig, terminal=True)))
    if fig.cold_start:
        console.print(f"cold start to first verdict ({fig.cold_start.example}):")
        console.print(to_rich(cold_start_table(fig)))
    paper = fig.paper
    same = fig.identical_reports
    console.print(
        f"ratio a/c (median over plans): {ratio_text(fig)}; "
        f"reports identical (b vs c): {same.identical}/{same.compared}"
    )
    if paper and paper.calls_over_limit:
        console.print(
            f"paper method: {paper.calls_over_limit} of {paper.calls} calls hit the "
            f"{paper.call_limit_s:g} s limit; {paper.plans_lower_bound} of "
            f"{paper.plans} plans timed are lower bounds (≥)"
        )
    mem = fig.memory
    console.print(
        f"memory: process RSS {mem.process_rss_after_tbox_mb:.0f} MB after TBox load, "
        f"peak {mem.process_rss_peak_after_fast_mb:.0f} MB after (c), "
        f"{mem.process_rss_peak_after_reference_mb:.0f} MB after (b); "
        f"fast engine Python heap peak {mem.fast_python_heap_peak_mb:.1f} MB"
        + (f"; paper method peak {paper.peak_rss_mb} MB" if paper else "")
    )
    console.print(to_rich(scaling_table(fig, "scene_scaling", terminal=True)))
    console.print(to_rich(scaling_table(fig, "length_scaling", terminal=True)))
    console.print(to_rich(tbox_table(fig, terminal=True)))
    # The containment-chain and deadline figures, as the Markdown report has them.
    for line in chain_markdown(fig.chain_scaling, fig.hazard_chains, fig.deadline):
        console.print(line, markup=False)
