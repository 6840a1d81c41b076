"""``virf kb review``: the knowledge engineer's review page, served locally."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virf.cli.app import default_reviewer
from virf.cli.kb_workflow import ExamplesOpt, PreviewOpt, examples_or_default
from virf.errors import InputError


def register(kb_app: typer.Typer) -> None:
    """Add the ``review`` command to the ``virf kb`` group."""
    kb_app.command("review")(kb_review)


def kb_review(
    workspace: Annotated[
        Path,
        typer.Option(
            "--workspace", "-w", help="The knowledge workspace (made by 'virf kb init DIR')."
        ),
    ] = Path("virf-kb"),
    port: Annotated[
        int, typer.Option(help="TCP port to listen on (0: any free port).", min=0, max=65535)
    ] = 8765,
    host: Annotated[
        str,
        typer.Option(
            help="Address to listen on. The default is reachable from this machine only; the"
            " page has no login, so think before choosing another."
        ),
    ] = "127.0.0.1",
    reviewer: Annotated[
        str | None,
        typer.Option(help="Name recorded with each decision (default: your login name)."),
    ] = None,
    preview: PreviewOpt = None,
    examples: ExamplesOpt = None,
) -> None:
    """Serve the review page: the queue of drafted rules, their evidence, checks and effect, and Accept / Reject.

    Open the printed address in a browser; Ctrl-C stops."""
    from virf.authoring.review import serve
    from virf.authoring.workspace import Workspace

    name = (reviewer if reviewer is not None else default_reviewer()).strip()
    if not name:
        raise InputError("--reviewer must not be empty")
    if preview is not None and not preview.is_file():
        raise InputError(f"--preview: benchmark file {preview} does not exist")
    ws = Workspace.open(workspace)
    serve(
        ws,
        host=host,
        port=port,
        reviewer=name,
        announce=typer.echo,
        preview_tasks=preview,
        examples=examples_or_default(examples),
    )
    typer.echo("Review server stopped.")
