"""``virf kb corpus add | list`` and ``virf kb search``: a workspace's documents and hybrid retrieval."""

from __future__ import annotations

import json
import textwrap
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from virf.cli.app import WorkspaceOpt, progress_bar
from virf.errors import printable

if TYPE_CHECKING:
    from rich.progress import TaskID

    from virf.authoring.corpus import Corpus, Hit

JsonOpt = Annotated[bool, typer.Option("--json", help="Print JSON instead of text.")]

corpus_app = typer.Typer(
    help="The workspace's safety documents (Markdown, text, HTML, PDF).", no_args_is_help=True
)


def register(kb_app: typer.Typer) -> None:
    """Add ``corpus add``, ``corpus list`` and ``search`` to the ``virf kb`` group."""
    kb_app.add_typer(corpus_app, name="corpus")
    kb_app.command("search")(kb_search)


@contextmanager
def _corpus(workspace: Path) -> Iterator[Corpus]:
    from virf.authoring.workspace import Workspace

    ws = Workspace.open(workspace)
    try:
        yield ws.corpus()
    finally:
        ws.close()


@corpus_app.command("add")
def corpus_add(
    files: Annotated[
        list[Path], typer.Argument(help="Documents: .md, .markdown, .txt, .html, .htm, .pdf.")
    ],
    replace: Annotated[
        bool,
        typer.Option("--replace", help="Replace a document whose id is already in the corpus."),
    ] = False,
    workspace: WorkspaceOpt = Path("virf-kb"),
) -> None:
    """Copy documents into the corpus: every file is checked first, then all are added or none."""
    with _corpus(workspace) as corpus:
        added = corpus.add_with_status(files, replace=replace)
    for doc, status in added:
        typer.echo(f"{status:<9} {doc.id}  {len(doc.passages)} passages  {printable(doc.title)}")


@corpus_app.command("list")
def corpus_list(as_json: JsonOpt = False, workspace: WorkspaceOpt = Path("virf-kb")) -> None:
    """The documents in the corpus, by id."""
    with _corpus(workspace) as corpus:
        docs = corpus.documents()
    if as_json:
        rows = [
            {
                "id": d.id,
                "title": d.title,
                "publisher": d.publisher,
                "url": d.url,
                "kind": d.kind,
                "file": Path(d.path).name,
                "rooms": list(d.rooms),
                "topics": list(d.topics),
                "passages": len(d.passages),
            }
            for d in docs
        ]
        typer.echo(json.dumps(rows, indent=2))
        return
    from rich.console import Console

    from virf.render.tables import Column, TextTable, to_rich

    if not docs:
        typer.echo("the corpus is empty; add documents with 'virf kb corpus add FILE...'")
        return
    table = TextTable.of(
        ("id", Column("passages", "right"), "title", "publisher"),
        [
            (printable(d.id), str(len(d.passages)), printable(d.title), printable(d.publisher))
            for d in docs
        ],
        title=f"{len(docs)} documents, {sum(len(d.passages) for d in docs)} passages",
    )
    Console(highlight=False, width=160).print(to_rich(table))


def kb_search(
    query: Annotated[str, typer.Argument(help="What to look for, in words.")],
    k: Annotated[int, typer.Option("--k", "-k", help="How many passages to show.")] = 5,
    as_json: JsonOpt = False,
    workspace: WorkspaceOpt = Path("virf-kb"),
) -> None:
    """Find the corpus passages that best match a question (BM25 and sentence embeddings).

    The first search after the corpus changes embeds the new passages (a
    progress bar on stderr); later ones reuse the cached index."""
    from rich.console import Console

    err = Console(stderr=True)
    with _corpus(workspace) as corpus, progress_bar(err) as bar:
        tasks: list[TaskID] = []

        def advance(done: int, total: int) -> None:
            # The bar appears only when there is something to embed.
            if not tasks:
                tasks.append(bar.add_task("embedding passages", total=total))
            bar.update(tasks[0], completed=done, total=total)

        hits = corpus.search(query, k=k, progress=advance)
    if as_json:
        typer.echo(json.dumps([_hit_json(h) for h in hits], indent=2))
        return
    for hit in hits:
        _print_hit(hit)


def _hit_json(hit: Hit) -> dict[str, object]:
    return {
        "rank": hit.rank,
        "passage": hit.passage.id,
        "document": hit.document.id,
        "title": hit.document.title,
        "publisher": hit.document.publisher,
        "url": hit.document.url,
        "section": hit.passage.section,
        "score": round(hit.score, 4),
        "bm25": round(hit.bm25, 4),
        "dense": round(hit.dense, 4),
        "text": hit.passage.text,
    }


def _print_hit(hit: Hit) -> None:
    doc = hit.document
    source = printable(doc.title) + (f" ({printable(doc.publisher)})" if doc.publisher else "")
    typer.echo(
        f"{hit.rank}. {printable(hit.passage.id)}  score {hit.score:.3f} "
        f"(bm25 {hit.bm25:.2f}, dense {hit.dense:.3f})"
    )
    typer.echo(f"   {source} / {printable(hit.passage.section)}")
    for line in textwrap.wrap(printable(hit.passage.text), width=96):
        typer.echo(f"   {line}")
    typer.echo("")
