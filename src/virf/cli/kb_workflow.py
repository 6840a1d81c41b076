"""``virf kb init | draft | propose | candidates | show | check | preview |
decide | audit``: the knowledge-acquisition workflow from the terminal."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from virf.cli.app import (
    ApiKeyEnvOpt,
    BaseUrlOpt,
    MaxTokensOpt,
    ModelTimeoutOpt,
    PlainScenarioOpt,
    SeedOpt,
    TemperatureOpt,
    WorkspaceOpt,
    default_reviewer,
    write_output,
)
from virf.errors import InputError

if TYPE_CHECKING:
    from virf.authoring.models import CandidateView, CheckReport, Preview
    from virf.authoring.workspace import Workspace

JsonOpt = Annotated[bool, typer.Option("--json", help="Print JSON instead of text.")]
PreviewOpt = Annotated[
    Path | None,
    typer.Option(
        "--preview",
        help="Benchmark JSONL file: also list which of its tasks (and of the bundled examples) "
        "change verdict if the candidate is accepted.",
    ),
]
ExamplesOpt = Annotated[
    Path | None,
    typer.Option(
        help="Folder of bundled examples for the preview (default ./examples if present)."
    ),
]


def _reviewer(given: str | None) -> str:
    return given or default_reviewer()


def _open(workspace: Path) -> Workspace:
    from virf.authoring.workspace import Workspace

    return Workspace.open(workspace)


def examples_or_default(given: Path | None) -> Path | None:
    if given is not None:
        if not given.is_dir():
            raise InputError(f"examples folder {given} does not exist")
        return given
    default = Path("examples")
    return default if default.is_dir() else None


def _dump(model: Any) -> None:
    typer.echo(json.dumps(model.model_dump(mode="json"), indent=2, sort_keys=True))


def _print_check(report: CheckReport) -> None:
    typer.echo(f"  axiom:      {report.axiom}")
    if report.normalised and report.normalised != report.axiom:
        typer.echo(f"  normalised: {report.normalised}")
    typer.echo(f"  layer:      {report.layer}")
    for t in report.terms:
        if t.match == "exact":
            continue
        extra = f" (similarity {t.score:.2f}, threshold {report.threshold:.2f})" if t.score else ""
        if t.match == "new":
            extra = f" -> new class under {t.parent}" if t.role == "class" else " (unknown)"
            if t.alternatives:
                extra += "; nearest: " + ", ".join(f"{n} {s:.2f}" for n, s in t.alternatives)
        typer.echo(f"  term:       {t.term} -> {t.chosen} [{t.match}]{extra}")
    for item in report.items:
        mark = {"error": "FAIL", "warning": "warn", "info": " ok "}[item.severity]
        typer.echo(f"  [{mark}] {item.name}: {item.message}")
    typer.echo(f"  checks {'PASSED' if report.passed else 'FAILED'}")


def _print_preview(preview: Preview) -> None:
    where = f" and {preview.tasks} tasks of {preview.tasks_file}" if preview.tasks_file else ""
    scenes = f" and {preview.scenes} scene(s)" if preview.scenes else ""
    typer.echo(
        f"  preview over {preview.examples} examples{where}{scenes}: "
        f"{len(preview.changes)} change(s)"
    )
    for c in preview.changes:
        typer.echo(
            f"    {c.item}: {c.before} -> {c.after}"
            + (f"  {c.instruction}" if c.instruction else "")
        )
    if preview.kb_test:
        typer.echo(f"  {preview.kb_test}")
    for failure in preview.kb_test_failures:
        typer.echo(f"    new failure: {failure}")


def _print_learned(view: CandidateView) -> None:
    learned = view.learned
    assert learned is not None
    typer.echo(
        f"  a class learned from answers by {learned.who} at {learned.when} about "
        f"{', '.join(learned.instances)} in scene {learned.scene_name} "
        f"(sha256 {learned.scene_sha256})"
    )
    typer.echo(f"  written in the scene as {', '.join(learned.words)}; {learned.reading}")
    typer.echo("  axioms, as learned:")
    for axiom in learned.axioms:
        typer.echo(f"    {axiom}")
    typer.echo("  evidence (the answers):")
    for a in learned.answers:
        typer.echo(f"    '{a.question}' ({a.key}) -> {a.answer}: {a.effect}")
    for what in learned.unconfirmed:
        typer.echo(f"    not confirmed: {what}")


def _print_candidate(view: CandidateView) -> None:
    s, r = view.summary, view.rule
    typer.echo(f"Candidate {s.id}: {r.name}  [{s.status}]")
    if view.learned is not None:
        _print_learned(view)
        if view.check is not None:
            _print_check(view.check)
        if view.preview is not None:
            _print_preview(view.preview)
        _print_decision(view)
        return
    typer.echo(
        f"  drafted by {s.drafter} at {s.created_at}" + (f" for: {s.query}" if s.query else "")
    )
    typer.echo(f"  {r.category}; danger {r.danger_level}; {r.kind}; checked {r.check_at}")
    for label, text in (
        ("description", r.description),
        ("warning", r.safety_warning),
        ("trigger", r.trigger_reason),
        ("suggestion", r.suggestion),
    ):
        typer.echo(f"  {label + ':':12} {text}")
    typer.echo("  evidence:")
    for e in view.evidence:
        if not e.found:
            typer.echo(f"    [{e.passage_id}] NOT IN THE CORPUS")
            continue
        typer.echo(f"    [{e.passage_id}] {e.publisher}, {e.document_title} ({e.section})")
        typer.echo(textwrap.fill(e.text, 100, initial_indent="      ", subsequent_indent="      "))
    if view.check is not None:
        _print_check(view.check)
    if view.preview is not None:
        _print_preview(view.preview)
    _print_decision(view)


def _print_decision(view: CandidateView) -> None:
    if view.decision is not None:
        d = view.decision
        typer.echo(
            f"  decision: {d.decision} ({d.edit} edit) by {d.reviewer} at {d.decided_at}"
            + (f": {d.reason}" if d.reason else "")
        )


def kb_init(
    folder: Annotated[Path, typer.Argument(help="New folder for the workspace.")] = Path("virf-kb"),
    scenario: PlainScenarioOpt = None,
    starter: Annotated[
        bool,
        typer.Option(
            "--starter/--no-starter",
            help="Copy the starter corpus (the bundled safety documents) in.",
        ),
    ] = True,
) -> None:
    """Create a knowledge workspace: layered modules, a corpus folder and a database."""
    from virf.authoring.workspace import Workspace

    ws = Workspace.init(folder, scenario or "kitchen", starter=starter)
    docs = len(list(ws.corpus_dir.iterdir()))
    typer.echo(f"created workspace {folder} (scenario {ws.scenario}; {docs} documents in corpus/)")
    typer.echo(
        f'next: virf kb search "..." -w {folder}   or   virf kb draft --query "..." -w {folder}'
    )


def kb_draft(
    query: Annotated[str, typer.Option("--query", "-q", help="What the rules should be about.")],
    drafter: Annotated[
        str,
        typer.Option(
            help="openai:MODEL (any OpenAI-compatible server), replay:FILE (recorded drafts) "
            "or scripted."
        ),
    ],
    workspace: WorkspaceOpt = Path("virf-kb"),
    k: Annotated[
        int, typer.Option("--k", min=1, max=50, help="Evidence passages to retrieve.")
    ] = 5,
    base_url: BaseUrlOpt = None,
    api_key_env: ApiKeyEnvOpt = None,
    temperature: TemperatureOpt = None,
    max_tokens: MaxTokensOpt = None,
    timeout: ModelTimeoutOpt = None,
    seed: SeedOpt = None,
    preview: PreviewOpt = None,
    examples: ExamplesOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Retrieve evidence, ask the LLM for candidate rules, store and check them."""
    from virf.planner import RunLog, make_apprentice

    ws = _open(workspace)
    with RunLog(ws.run_log_path()) as log:
        apprentice = make_apprentice(
            drafter,
            run_log=log,
            base_url=base_url,
            api_key_env=api_key_env,
            temperature=temperature,
            max_tokens=max_tokens,
            timeout_s=timeout,
            seed=seed,
        )
        try:
            ids, problem = ws.draft(query, apprentice, k=k)
        finally:
            apprentice.close()
    previews = {}
    if preview is not None or examples is not None:
        for cid in ids:
            if ws.candidate(cid).check and ws.candidate(cid).check.passed:  # type: ignore[union-attr]
                previews[cid] = ws.preview(
                    cid, tasks=preview, examples=examples_or_default(examples)
                )
    if as_json:
        typer.echo(
            json.dumps(
                {
                    "candidates": [ws.candidate(cid).model_dump(mode="json") for cid in ids],
                    "problem": problem or None,
                },
                indent=2,
                sort_keys=True,
            )
        )
    else:
        if problem:
            typer.echo(f"the drafter's reply was not usable: {problem}")
        for cid in ids:
            _print_candidate(ws.candidate(cid))
            typer.echo("")
    if problem and not ids:
        raise typer.Exit(1)


def kb_propose(
    file: Annotated[
        Path, typer.Argument(help="Draft JSON written by a person (same shape as an LLM draft).")
    ],
    workspace: WorkspaceOpt = Path("virf-kb"),
    author: Annotated[str | None, typer.Option(help="Who wrote it (default $USER).")] = None,
    as_json: JsonOpt = False,
) -> None:
    """Add a person's candidate rules and check them."""
    ws = _open(workspace)
    ids = ws.propose(file, _reviewer(author))
    if as_json:
        typer.echo(
            json.dumps(
                [ws.candidate(c).model_dump(mode="json") for c in ids], indent=2, sort_keys=True
            )
        )
        return
    for cid in ids:
        _print_candidate(ws.candidate(cid))
        typer.echo("")


def kb_candidates(
    workspace: WorkspaceOpt = Path("virf-kb"),
    status: Annotated[str, typer.Option(help="pending, accepted, rejected or all.")] = "pending",
    as_json: JsonOpt = False,
) -> None:
    """List candidates (the review queue by default)."""
    from virf.errors import InputError
    from virf.render.tables import Column, TextTable, to_rich

    if status not in ("pending", "accepted", "rejected", "all"):
        raise InputError(f"unknown status '{status}'; choose pending, accepted, rejected or all")
    ws = _open(workspace)
    rows = ws.candidates(None if status == "all" else status)  # type: ignore[arg-type]
    if as_json:
        typer.echo(json.dumps([r.model_dump(mode="json") for r in rows], indent=2, sort_keys=True))
        return
    from rich.console import Console

    table = TextTable.of(
        (Column("id", "right"), "name", "category", "drafter", "status", "checks"),
        [
            (
                str(r.id),
                r.name,
                r.category,
                r.drafter,
                r.status,
                "-" if r.passed is None else "passed" if r.passed else "FAILED",
            )
            for r in rows
        ],
        title=f"Candidates ({status})",
    )
    Console(highlight=False, width=150).print(to_rich(table))


def kb_show(
    candidate: Annotated[int, typer.Argument(help="Candidate id.")],
    workspace: WorkspaceOpt = Path("virf-kb"),
    reviewer: Annotated[str | None, typer.Option(help="Who is reviewing (default $USER).")] = None,
    as_json: JsonOpt = False,
) -> None:
    """Show a candidate: rule, evidence, normalisation, checks, preview, decision.

    Showing it starts the reviewer's clock for the audit's time per decision."""
    ws = _open(workspace)
    view = ws.candidate(candidate)
    if view.decision is None:
        ws.opened(candidate, _reviewer(reviewer))
    if as_json:
        _dump(view)
    else:
        _print_candidate(view)


def kb_recheck(
    candidate: Annotated[int, typer.Argument(help="Candidate id.")],
    workspace: WorkspaceOpt = Path("virf-kb"),
    axiom: Annotated[
        str | None, typer.Option(help="An edited Manchester class expression to check instead.")
    ] = None,
    as_json: JsonOpt = False,
) -> None:
    """Normalise and check a candidate's axiom again (or an edited one)."""
    ws = _open(workspace)
    report = ws.check(candidate, axiom)
    if as_json:
        _dump(report)
    else:
        typer.echo(f"Candidate {candidate}:")
        _print_check(report)
    if not report.passed:
        raise typer.Exit(1)


def kb_preview(
    candidate: Annotated[int, typer.Argument(help="Candidate id.")],
    workspace: WorkspaceOpt = Path("virf-kb"),
    tasks: PreviewOpt = None,
    examples: ExamplesOpt = None,
    axiom: Annotated[str | None, typer.Option(help="Preview an edited axiom instead.")] = None,
    as_json: JsonOpt = False,
) -> None:
    """Which examples and benchmark tasks change verdict if the candidate is accepted."""
    ws = _open(workspace)
    result = ws.preview(candidate, axiom, tasks=tasks, examples=examples_or_default(examples))
    if as_json:
        _dump(result)
    else:
        typer.echo(f"Candidate {candidate}:")
        _print_preview(result)


def kb_decide(
    candidate: Annotated[int, typer.Argument(help="Candidate id.")],
    decision: Annotated[str, typer.Argument(help="accept or reject.")],
    workspace: WorkspaceOpt = Path("virf-kb"),
    reason: Annotated[str | None, typer.Option(help="Why (required to reject).")] = None,
    axiom: Annotated[
        str | None, typer.Option(help="Accept this edited Manchester class expression instead.")
    ] = None,
    reviewer: Annotated[str | None, typer.Option(help="Who decides (default $USER).")] = None,
    as_json: JsonOpt = False,
) -> None:
    """Accept (after re-checking) or reject a candidate; accepted axioms go into the workspace's modules."""
    from virf.authoring.decisions import EDIT_LABELS

    ws = _open(workspace)
    result = ws.decide(
        candidate, decision, reviewer=_reviewer(reviewer), reason=reason, axiom=axiom
    )
    if as_json:
        _dump(result)
        return
    if result.decision == "accept":
        layer = result.layer or "core"
        typer.echo(
            f"candidate {candidate} {EDIT_LABELS[result.edit]} into the {layer} layer "
            f"({ws.layout.module_path(layer)})"
        )
    else:
        typer.echo(f"candidate {candidate} rejected: {result.reason}")


def kb_audit(workspace: WorkspaceOpt = Path("virf-kb"), as_json: JsonOpt = False) -> None:
    """The funnel from drafts to accepted axioms, with reasons and time per decision."""
    from rich.console import Console

    from virf.authoring.audit import audit
    from virf.render.tables import Column, TextTable, to_rich

    ws = _open(workspace)
    result = audit(ws)
    if as_json:
        _dump(result)
        return
    table = TextTable.of(
        ("stage", Column("count", "right"), Column("share", "right"), "what it means"),
        [
            (
                s.stage,
                str(s.count),
                "-" if s.share is None else f"{100 * s.share:.1f}%",
                s.description,
            )
            for s in result.funnel
        ],
        title=f"Knowledge-acquisition audit: {ws.root}",
    )
    console = Console(highlight=False, width=150)
    console.print(to_rich(table))
    console.print(
        f"Draft requests: {result.draft_requests}; unusable replies: {len(result.unusable_drafts)}"
    )
    for detail in result.unusable_drafts:
        console.print(f"  unusable: {detail}")
    for cid, why in result.rejection_reasons:
        console.print(f"  rejected {cid}: {why}")
    if result.timed_decisions:
        console.print(
            f"Time per decision: median {result.decision_seconds_median} s, mean "
            f"{result.decision_seconds_mean} s over {result.timed_decisions} timed decisions"
        )
    else:
        console.print("Time per decision: no decision was timed (open a candidate before deciding)")


def kb_export(
    workspace: WorkspaceOpt = Path("virf-kb"),
    to: Annotated[
        Path | None,
        typer.Option(help="Write the module to this file (default: print it)."),
    ] = None,
    iri: Annotated[
        str,
        typer.Option(help="The exported ontology's IRI (the name other modules import it by)."),
    ] = "http://virf.dev/ontology/workspace/export",
    label: Annotated[str | None, typer.Option(help="The module's rdfs:label.")] = None,
) -> None:
    """Write every accepted axiom, with its evidence and decision, as one Manchester module."""
    if not iri.startswith(("http://", "https://")) or any(c in iri for c in ' <>"{}|\\^`'):
        raise typer.BadParameter(
            f"--iri {iri!r} is not an absolute http(s) IRI", param_hint="--iri"
        )
    ws = _open(workspace)
    text = ws.export(iri, label)
    if to is None:
        typer.echo(text, nl=False)
        return
    write_output(to, text)
    accepted = sum(1 for d in ws.store.decisions() if d.decision == "accept")
    typer.echo(f"wrote {to}: {accepted} accepted candidate(s)", err=True)
