"""``virf kb``: inspect the safety knowledge base (TBox)."""

from __future__ import annotations

import json
from typing import Annotated

import typer

from virf.cli.app import EngineOpt, KbOpt, ScenarioOpt, progress_bar

kb_app = typer.Typer(
    help="Inspect the safety knowledge base (TBox) and grow it from safety documents "
    "(knowledge acquisition: init, corpus, search, draft, review, decide, audit, coverage).",
    no_args_is_help=True,
)


@kb_app.command("check")
def kb_check(
    scenario: ScenarioOpt = None,
    kb: KbOpt = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print the figures as one JSON object.")
    ] = False,
) -> None:
    """Check the TBox: consistency, satisfiability of every USC, and counts per module and category."""
    from rich.console import Console

    from virf.api import check_knowledge_base
    from virf.render.tables import Column, TextTable, to_rich

    result = check_knowledge_base(scenario, kb)
    if as_json:
        typer.echo(json.dumps(result, indent=2, sort_keys=True))
    else:
        console = Console(highlight=False, width=150)
        console.print(f"Scenario: {result['scenario']}  (reasoner: {result['reasoner']})")
        console.print(f"TBox consistent: {'yes' if result['consistent'] else 'NO'}")
        unsat = result["unsatisfiable_uscs"]
        console.print(
            f"Unsafe State Concepts satisfiable: {result['uscs'] - len(unsat)}/{result['uscs']}"
            + (f"  UNSATISFIABLE: {', '.join(unsat)}" if unsat else "")
        )
        bad = result["unsatisfiable_classes"]
        console.print(
            f"Named classes satisfiable: {result['classes'] - len(bad)}/{result['classes']}"
            + (f"  UNSATISFIABLE: {', '.join(bad)}" if bad else "")
        )
        counts = ("classes", "obj props", "data props", "individuals", "logical axioms", "USCs")
        modules = TextTable.of(
            ("module", "imports", *(Column(c, "right") for c in counts)),
            [
                (
                    m["name"],
                    ", ".join(m["imports"]),
                    *(
                        str(m[k])
                        for k in (
                            "classes",
                            "object_properties",
                            "data_properties",
                            "individuals",
                            "logical_axioms",
                            "uscs",
                        )
                    ),
                )
                for m in result["modules"]
            ],
            title="Modules",
        )
        console.print(to_rich(modules))
        kinds = sorted({k for row in result["usc_by_category"].values() for k in row})
        cats = TextTable.of(
            ("category", *(Column(k, "right") for k in kinds), Column("total", "right")),
            [
                (cat, *(str(row.get(k, 0)) for k in kinds), str(sum(row.values())))
                for cat, row in sorted(result["usc_by_category"].items())
            ],
            title="Unsafe State Concepts per category and kind",
        )
        console.print(to_rich(cats))
        ev = result["evidence"]
        console.print(
            f"Evidence: {ev['documents']} USCs ({100 * ev['share_documents']:.1f}%) cite corpus "
            f"passages; {ev['modelling_decisions']} ({100 * ev['share_modelling_decisions']:.1f}%) "
            f"state a common-sense modelling decision; {ev['neither']} cite neither"
            + (f": {', '.join(ev['without_evidence'][:8])}" if ev["neither"] else "")
            + ("…" if ev["neither"] > 8 else "")
        )
        console.print(
            "Compiled artifact: "
            + (
                "what the modules compile to"
                if result["artifact_matches_modules"]
                else "DIFFERS from what the modules compile to, in "
                + ", ".join(result["artifact_differs_in"])
                + " (rebuild it: 'make kb' for the built-in artifacts, delete the workspace's "
                "cache folder for a workspace's)"
            )
        )
        console.print(f"Precondition definitions (simulator): {result['preconditions']}")
        console.print(f"Annotated background axioms: {result['background_axioms']}")
        fe = result["fast_engine"]
        if fe["exact_fragment"]:
            console.print(
                f"Fast engine: inside its fragment ({fe['query_classes']} query classes, "
                f"{fe['sink_classes']} sink classes, {fe['kb_axioms']} knowledge-base axioms, "
                f"{fe['compiled_axioms']} compiled to rules, {fe['model_checked_axioms']} "
                "checked on candidate models)"
            )
        else:
            console.print(
                "Fast engine: OUTSIDE its fragment, every question goes to the reference "
                f"engine: {'; '.join(fe['problems'][:3])}"
            )
    if (
        not result["consistent"]
        or result["unsatisfiable_uscs"]
        or result["unsatisfiable_classes"]
        or not result["artifact_matches_modules"]
    ):
        raise typer.Exit(1)


@kb_app.command("rules")
def kb_rules(
    scenario: ScenarioOpt = None,
    kb: KbOpt = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the rules as JSON.")] = False,
) -> None:
    """List the Unsafe State Concepts with their definitions and annotations."""
    from virf.ontology.tbox import load_tbox

    vocab = load_tbox(scenario, kb=kb).vocabulary
    if as_json:
        typer.echo(json.dumps(vocab.rule_listing(), indent=2))
        return
    rules = sorted(vocab.uscs.values(), key=lambda u: (u.module, u.id))
    for u in rules:
        typer.echo(f"{u.id}  [{u.kind}; {u.category}; {u.danger_level}; checked: {u.check_at}]")
        typer.echo(f"    {u.definition}")
        typer.echo(f"    {u.description}")
        for mechanism in vocab.annotation(u.name, "mechanism"):
            typer.echo(f"    mechanism: {mechanism}")
        typer.echo(f"    source: {u.source}")


@kb_app.command("classes")
def kb_classes(
    scenario: ScenarioOpt = None,
    kb: KbOpt = None,
    search: Annotated[
        str | None,
        typer.Option(
            "--search",
            "-q",
            help="Rank the classes by how near they are to these words, by spelling and by "
            "meaning (sentence embeddings): --search 'hair dryer'.",
        ),
    ] = None,
    kind: Annotated[
        str | None,
        typer.Option(
            "--kind", help="Only classes of this kind: object, agent, state, material, property."
        ),
    ] = None,
    limit: Annotated[
        int | None,
        typer.Option(
            "--limit",
            "-n",
            min=1,
            help="At most this many classes (default: 10 with --search, else all).",
            show_default=False,
        ),
    ] = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print the classes as one JSON object.")
    ] = False,
) -> None:
    """List the classes a scene can use (object types, people, states, materials and
    properties) with their parents, materials, affordances and properties; --search
    finds the ones nearest some words."""
    from rich.console import Console

    from virf.errors import clip
    from virf.ontology.classes import classes_document, find_classes
    from virf.ontology.tbox import load_tbox
    from virf.render.classes import class_table
    from virf.render.tables import to_rich

    tbox = load_tbox(scenario, kb=kb)
    if limit is None and search is not None:
        limit = 10
    rows = find_classes(tbox, kind, search, limit)
    if as_json:
        typer.echo(json.dumps(classes_document(tbox, kind, search, rows), indent=2))
        return
    what = f"Classes of kind {kind}" if kind else "Classes"
    title = (
        f"{what} in scenario {tbox.scenario} nearest '{clip(search)}'"
        if search is not None
        else f"{what} in scenario {tbox.scenario} ({len(rows)})"
    )
    Console(highlight=False, width=160).print(to_rich(class_table(rows, title)))


@kb_app.command("test")
def kb_test(
    scenario: ScenarioOpt = None,
    kb: KbOpt = None,
    engine: EngineOpt = "fast",
    sweeps: Annotated[
        bool | None,
        typer.Option(
            "--sweeps/--no-sweeps",
            help="Also run the catalogue sweeps (throw, microwave, pour every type).",
            show_default="when the knowledge base holds the household rules, whose "
            "mechanisms the sweeps state",
        ),
    ] = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print the results as one JSON object.")
    ] = False,
) -> None:
    """Test the rules like code: every rule's minimal pairs (a world where it holds and a
    twin, differing in the property that matters, where it does not), and sweeps over the
    catalogue whose verdicts must follow each type's properties.  Exit 1 on any failure."""
    from dataclasses import asdict

    from rich.console import Console

    from virf.ontology.tbox import load_tbox
    from virf.reasoning import make_engine
    from virf.render.tables import TextTable, to_rich
    from virf.verify.kbtest import run_kb_test
    from virf.verify.sweeps import HOUSEHOLD_MODULE

    tbox = load_tbox(scenario, kb=kb)
    reasoner = make_engine(engine, tbox)
    if sweeps is None:
        sweeps = any(u.module == HOUSEHOLD_MODULE for u in tbox.vocabulary.uscs.values())
    err = Console(stderr=True)
    with progress_bar(err) as progress:
        bars: dict[str, object] = {}

        def tick(what: str, done: int, total: int) -> None:
            if what not in bars:
                bars[what] = progress.add_task(what, total=total)
            progress.update(bars[what], completed=done)

        result = run_kb_test(tbox, reasoner, sweeps=sweeps, progress=tick)
    failures = result.failures
    if as_json:
        typer.echo(
            json.dumps(
                {
                    "scenario": result.scenario,
                    "rules": result.rules,
                    "pairs": len(result.pairs),
                    "pair_failures": [asdict(p) for p in failures],
                    "sweep_cases": result.sweep_cases,
                    "sweep_failures": [asdict(f) for f in result.sweeps],
                    "passed": result.passed,
                },
                indent=2,
                sort_keys=True,
            )
        )
    else:
        console = Console(highlight=False, width=160)
        checked = sum(1 for p in result.pairs if p.index)
        console.print(
            f"Scenario {result.scenario}: {result.rules} rules, {checked} minimal pairs, "
            f"{len(failures)} failing"
            + (
                f"; sweeps: {result.sweep_cases} cases, {len(result.sweeps)} failing"
                if sweeps
                else "; sweeps skipped (they state the household rules' mechanisms; "
                "--sweeps runs them)"
            )
        )
        if failures:
            console.print(
                to_rich(
                    TextTable.of(
                        ("rule", "pair", "problem", "twin's change"),
                        [(p.rule, str(p.index or "-"), p.problem, p.change) for p in failures],
                        title="Minimal pairs that fail",
                    )
                )
            )
        if result.sweeps:
            console.print(
                to_rich(
                    TextTable.of(
                        ("sweep", "case", "expected", "got", "why it is expected"),
                        [(f.sweep, f.case, f.expected, f.got, f.why) for f in result.sweeps],
                        title="Sweep cases whose verdict does not follow the type's properties",
                    )
                )
            )
        if result.passed:
            console.print(
                "All rules pass their minimal pairs" + (" and the sweeps." if sweeps else ".")
            )
    if not result.passed:
        raise typer.Exit(1)


def _register_workflow() -> None:
    # The authoring commands live in their own modules; they join this group
    # here, in the order of the workflow.
    from virf.cli import kb_corpus, kb_coverage, kb_review, kb_workflow

    kb_app.command("init")(kb_workflow.kb_init)
    kb_corpus.register(kb_app)
    for name in ("draft", "propose", "candidates", "show", "recheck", "preview"):
        kb_app.command(name)(getattr(kb_workflow, f"kb_{name}"))
    kb_review.register(kb_app)
    kb_app.command("decide")(kb_workflow.kb_decide)
    kb_app.command("audit")(kb_workflow.kb_audit)
    kb_app.command("export")(kb_workflow.kb_export)
    kb_coverage.register(kb_app)


_register_workflow()
