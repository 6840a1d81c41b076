"""Decisions on candidates: a person accepts (the final axiom checked once
more, its block written into its layer's module) or rejects (with a reason).

The database is the record; one decision is taken at a time, across threads
and processes (:func:`exclusive`).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Final

from virf.authoring.checks import check_row, current_axiom
from virf.authoring.layers import append_block
from virf.authoring.models import DecisionView, Layer
from virf.authoring.store import DecisionRow
from virf.errors import InputError, clip
from virf.files import write_atomically
from virf.migrations import now
from virf.ontology import manchester

if TYPE_CHECKING:
    from virf.authoring.workspace import Workspace

EDIT_LABELS: Final = {
    "none": "accepted unedited",
    "minor": "accepted after a minor edit",
    "major": "accepted after a major edit",
}


def opened(ws: Workspace, cid: int, reviewer: str) -> None:
    """A reviewer opened the candidate: the time to a decision counts from here."""
    ws.store.candidate(cid)  # an unknown id is an error here too
    ws.store.add_event("opened", cid, actor=reviewer)


def decide(
    ws: Workspace,
    cid: int,
    decision: str,
    *,
    reviewer: str,
    reason: str | None = None,
    axiom: str | None = None,
) -> DecisionView:
    """Record a decision.  Accepting checks the final axiom (``axiom``, or
    the one checked last) once more and writes its block into its layer's
    module; a candidate whose checks fail is refused.

    The database is the record: the decision is committed first and the
    module replaced after, so a crash in between leaves an accepted rule
    out of the TBox (restored when the workspace is next opened), never a
    rule nobody accepted in it."""
    if decision not in ("accept", "reject"):
        raise InputError(f"unknown decision '{clip(decision)}'; choose accept or reject")
    if not reviewer.strip():
        raise InputError("a decision needs a reviewer's name (--reviewer or $USER)")
    if decision == "reject" and not (reason and reason.strip()):
        raise InputError("a rejection needs a reason (--reason TEXT)")
    row = ws.store.candidate(cid)
    with exclusive(ws.root):
        ws.store.undecided(cid)
        opened_at = ws.store.first_event(cid, "opened")
        decided_at = now()
        seconds = _seconds_between(opened_at, decided_at) if opened_at else None
        if decision == "reject":
            assert reason is not None
            record = DecisionRow(
                cid, decided_at, "reject", "none", None, None, reason.strip(), reviewer, seconds
            )
            with ws.store.transaction() as conn:
                ws.store.add_decision(conn, record)
                ws.store.add_event("decided", cid, actor=reviewer, detail="reject")
            return decision_view(record)
        current = current_axiom(ws.store, cid, row.axiom)
        final = axiom if axiom is not None else current
        edit = edit_size(row.axiom, final)
        provenance = {
            "reviewer": reviewer,
            "decision": EDIT_LABELS[edit]
            + (f": {' '.join(reason.split())}" if reason and reason.strip() else ""),
            "decidedOn": decided_at[:10],
        }
        report = check_row(ws, row, final, provenance)
        if not report.passed:
            failed = next(i for i in report.items if i.severity == "error")
            if final == current:
                # The candidate's own axiom, checked again: its latest check.
                ws.store.add_check(cid, final, False, report.model_dump(mode="json"))
            else:
                # An edit refused at acceptance does not become the
                # candidate's axiom: a later plain accept (or preview)
                # still takes the version checked last.  The attempt is
                # kept as an event.
                ws.store.add_event(
                    "accept_refused",
                    cid,
                    actor=reviewer,
                    detail=f"{' '.join(final.split())}: {failed.message}",
                )
            raise InputError(f"candidate {cid} cannot be accepted: {failed.message}")
        layer: Layer = report.layer
        record = DecisionRow(
            cid,
            decided_at,
            "accept",
            edit,
            final,
            layer,
            reason,
            reviewer,
            seconds,
            report.module_text,
        )
        path = ws.layout.module_path(layer)
        staged = path.with_name(f".{path.name}.staged")
        try:
            write_atomically(staged, append_block(path.read_text("utf-8"), report.module_text))
            # The modules as they will be must load: a block that parses
            # on top of the workspace but not in its layer stays out.
            from virf.ontology.axiom_check import parses_with

            parses_with(
                ws.scenario,
                tuple(str(staged if p == path else p) for p in ws.layout.modules()),
            )
            with ws.store.transaction() as conn:
                ws.store.add_check(cid, final, True, report.model_dump(mode="json"))
                ws.store.add_decision(conn, record)
                ws.store.add_event("decided", cid, actor=reviewer, detail=f"accept ({edit})")
            os.replace(staged, path)
        finally:
            staged.unlink(missing_ok=True)
    return decision_view(record)


@contextmanager
def exclusive(root: Path) -> Iterator[None]:
    """One decision at a time, across the review server's threads and
    every process using the workspace ``root``."""
    import fcntl

    with open(root / ".lock", "a+") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def edit_size(drafted: str, final: str) -> str:
    """none: the same expression; minor: only names changed (URI alignment,
    a fixed spelling); major: the structure changed (scope, restrictions)."""
    try:
        a, b = manchester.tokens(drafted), manchester.tokens(final)
    except InputError:
        return "major"
    if [t.text for t in a] == [t.text for t in b]:
        return "none"
    return "minor" if manchester.shape(drafted) == manchester.shape(final) else "major"


def _seconds_between(start: str, end: str) -> float:
    delta = datetime.fromisoformat(end) - datetime.fromisoformat(start)
    return round(max(0.0, delta.total_seconds()), 3)


def decision_view(d: DecisionRow) -> DecisionView:
    return DecisionView(
        decision=d.decision,  # type: ignore[arg-type]
        edit=d.edit,  # type: ignore[arg-type]
        axiom=d.axiom,
        reason=d.reason,
        reviewer=d.reviewer,
        decided_at=d.created_at,
        seconds=d.seconds,
        layer=d.layer,  # type: ignore[arg-type]
    )
