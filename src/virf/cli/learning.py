"""What ``virf verify`` and ``virf plan`` share to learn from answers
(``--learn``, ``--who``, ``--strict-vocabulary``); the learning itself is
:mod:`virf.authoring.learn`."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from virf.errors import VirfError

if TYPE_CHECKING:
    from virf.authoring.workspace import Workspace
    from virf.schema import Question

LearnOpt = Annotated[
    Path | None,
    typer.Option(
        "--learn",
        help="Knowledge workspace: what the answers confirm about objects of classes the "
        "knowledge base lacks becomes candidate classes there, checked, for a person to "
        "accept (virf kb decide / virf kb review); verifies with that workspace.",
    ),
]
WhoOpt = Annotated[
    str | None,
    typer.Option("--who", help="Who gave the answers, kept as evidence (default $USER)."),
]
StrictVocabularyOpt = Annotated[
    bool,
    typer.Option(
        "--strict-vocabulary",
        help="Refuse a class the knowledge base lacks instead of reading it as an "
        "open-world object.",
    ),
]


def learning_kb(kb: Path | None, learn: Path | None) -> Path | None:
    """The workspace to verify with: --learn's, unless --kb names another."""
    if learn is None:
        return kb
    if kb is not None and kb.resolve() != learn.resolve():
        raise VirfError(
            f"--kb {kb} and --learn {learn} name different workspaces; learning verifies with "
            "the workspace it learns into (drop --kb)"
        )
    return learn


def who_of(who: str | None) -> str | None:
    """``--who``, checked before any work (one visible line)."""
    if who is None:
        return None
    from virf.authoring.learn import check_who

    return check_who(who)


def open_workspace(path: Path) -> Workspace:
    from virf.authoring.workspace import Workspace

    return Workspace.open(path)


def default_who() -> str:
    """Who answered when nobody said: the login name."""
    return os.environ.get("USER") or "unknown"


def warn_unused(key: str, asked: frozenset[str]) -> None:
    """An answer no report asked for: one warning line on stderr."""
    from virf.errors import clip, closest, printable

    near = closest(key, sorted(asked))
    hint = f"; closest asked: {', '.join(near)}" if near else ""
    typer.echo(f"warning: no question '{printable(clip(key))}' was asked{hint}", err=True)


def learn_lines(
    workspace: Workspace,
    name: str,
    data: dict[str, Any],
    plan: Sequence[str],
    answered: Sequence[tuple[Question, str]],
    who: str | None,
    learn: Path | None,
) -> list[str]:
    """Learn from the settled answers; the summary for the terminal."""
    from virf.authoring import learn as learning
    from virf.cli.kb_workflow import examples_or_default

    outcomes, skipped = learning.learn(
        workspace,
        learning.Source(name, data, tuple(plan)),
        answered,
        who or default_who(),
        examples=examples_or_default(None),
    )
    return learning.summary(outcomes, skipped, str(learn))
