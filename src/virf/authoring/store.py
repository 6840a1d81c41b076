"""The workspace database: candidates, their checks and previews, decisions,
and the events the audit times.  SQLite with append-only migrations (see
:mod:`virf.migrations`); a decision, once written, cannot be changed or
removed (triggers refuse it), so the audit trail is the history.
"""

from __future__ import annotations

import json
import sqlite3
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from virf.errors import EnvironmentProblem, InputError
from virf.migrations import Migration, check_migrations, migrate, now, rollback

# Append only.  Never edit or reorder an entry once it has been committed.
MIGRATIONS: Final[tuple[Migration, ...]] = (
    Migration(
        "0001_candidates",
        """
        CREATE TABLE candidates (
            id           INTEGER PRIMARY KEY AUTOINCREMENT,
            created_at   TEXT    NOT NULL,
            query        TEXT,
            drafter      TEXT    NOT NULL,
            drafter_kind TEXT    NOT NULL CHECK (drafter_kind IN ('llm', 'person')),
            name         TEXT    NOT NULL,
            axiom        TEXT    NOT NULL,
            rule         TEXT    NOT NULL,
            draft        TEXT    NOT NULL,
            evidence     TEXT    NOT NULL,
            retrieved    TEXT    NOT NULL
        );
        CREATE TABLE checks (
            id           INTEGER PRIMARY KEY AUTOINCREMENT,
            candidate_id INTEGER NOT NULL REFERENCES candidates (id),
            created_at   TEXT    NOT NULL,
            axiom        TEXT    NOT NULL,
            passed       INTEGER NOT NULL CHECK (passed IN (0, 1)),
            report       TEXT    NOT NULL
        );
        CREATE INDEX checks_by_candidate ON checks (candidate_id, id);
        CREATE TABLE previews (
            id           INTEGER PRIMARY KEY AUTOINCREMENT,
            candidate_id INTEGER NOT NULL REFERENCES candidates (id),
            created_at   TEXT    NOT NULL,
            axiom        TEXT    NOT NULL,
            report       TEXT    NOT NULL
        );
        CREATE INDEX previews_by_candidate ON previews (candidate_id, id);
        CREATE TABLE decisions (
            id           INTEGER PRIMARY KEY AUTOINCREMENT,
            candidate_id INTEGER NOT NULL UNIQUE REFERENCES candidates (id),
            created_at   TEXT    NOT NULL,
            decision     TEXT    NOT NULL CHECK (decision IN ('accept', 'reject')),
            edit         TEXT    NOT NULL CHECK (edit IN ('none', 'minor', 'major')),
            axiom        TEXT,
            layer        TEXT,
            reason       TEXT,
            reviewer     TEXT    NOT NULL,
            seconds      REAL,
            block        TEXT
        );
        CREATE TRIGGER decisions_are_final_update BEFORE UPDATE ON decisions
        BEGIN SELECT RAISE(ABORT, 'decisions are final'); END;
        CREATE TRIGGER decisions_are_final_delete BEFORE DELETE ON decisions
        BEGIN SELECT RAISE(ABORT, 'decisions are final'); END;
        CREATE TABLE events (
            id           INTEGER PRIMARY KEY AUTOINCREMENT,
            candidate_id INTEGER REFERENCES candidates (id),
            created_at   TEXT    NOT NULL,
            kind         TEXT    NOT NULL,
            actor        TEXT,
            detail       TEXT
        );
        CREATE INDEX events_by_candidate ON events (candidate_id, kind, id);
        """,
    ),
    # Where a candidate came from: a drafted rule (an LLM's or a person's
    # draft), or a class learned from a user's answers about an open-world
    # object (virf verify --learn).  Every older candidate is a draft.
    Migration(
        "0002_candidate_origin",
        """
        ALTER TABLE candidates ADD COLUMN origin TEXT NOT NULL DEFAULT 'draft'
            CHECK (origin IN ('draft', 'answer'));
        """,
    ),
)
ORIGINS: Final = ("draft", "answer")


def status_of(decision: str | None) -> str:
    """A candidate's status from its decision (None: not decided yet)."""
    return {"accept": "accepted", "reject": "rejected"}.get(decision or "", "pending")


@dataclass(frozen=True)
class CandidateRow:
    id: int
    created_at: str
    query: str | None
    drafter: str
    drafter_kind: str
    name: str
    axiom: str
    rule: dict[str, Any]
    draft: dict[str, Any]
    evidence: tuple[str, ...]
    retrieved: tuple[str, ...]
    origin: str = "draft"  # "answer": a class learned from answers (see ORIGINS)


@dataclass(frozen=True)
class DecisionRow:
    candidate_id: int
    created_at: str
    decision: str
    edit: str
    axiom: str | None
    layer: str | None
    reason: str | None
    reviewer: str
    seconds: float | None
    block: str | None = None  # the Manchester block an acceptance wrote


class Store:
    """One workspace's database.  Writes are serialised by a lock, so the
    review server's threads may share it."""

    def __init__(self, path: Path, migrations: Sequence[Migration] = MIGRATIONS) -> None:
        check_migrations(migrations)
        self.path = path
        self._lock = threading.RLock()
        try:
            self._conn = sqlite3.connect(
                path, timeout=30.0, isolation_level=None, check_same_thread=False
            )
        except sqlite3.Error as exc:
            raise EnvironmentProblem(f"cannot open workspace database {path}: {exc}") from None
        try:
            migrate(self._conn, migrations, f"workspace database {path}")
        except BaseException:
            self._conn.close()
            raise

    def close(self) -> None:
        self._conn.close()

    @contextmanager
    def transaction(self) -> Iterator[sqlite3.Connection]:
        """One write transaction; an exception inside rolls it all back."""
        with self._lock:
            self._conn.execute("BEGIN IMMEDIATE")
            try:
                yield self._conn
                self._conn.execute("COMMIT")
            except BaseException:
                rollback(self._conn)
                raise

    # ------------------------------------------------------------ candidates
    def add_candidate(
        self,
        *,
        query: str | None,
        drafter: str,
        drafter_kind: str,
        name: str,
        axiom: str,
        rule: dict[str, Any],
        draft: dict[str, Any],
        evidence: Sequence[str],
        retrieved: Sequence[str],
        origin: str = "draft",
        conn: sqlite3.Connection | None = None,
    ) -> int:
        sql = (
            "INSERT INTO candidates (created_at, query, drafter, drafter_kind, name, axiom, "
            "rule, draft, evidence, retrieved, origin) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)"
        )
        args = (
            now(),
            query,
            drafter,
            drafter_kind,
            name,
            axiom,
            _dump(rule),
            _dump(draft),
            _dump(list(evidence)),
            _dump(list(retrieved)),
            origin,
        )
        with self._lock:
            cur = (conn or self._conn).execute(sql, args)
        assert cur.lastrowid is not None
        return int(cur.lastrowid)

    def candidate(self, cid: int) -> CandidateRow:
        if not 0 < cid < 2**63:  # SQLite's integers; beyond them sqlite3 overflows
            raise InputError(f"no candidate {cid}; candidate ids are positive whole numbers")
        with self._lock:
            row = self._conn.execute(
                "SELECT id, created_at, query, drafter, drafter_kind, name, axiom, rule, draft, "
                "evidence, retrieved, origin FROM candidates WHERE id = ?",
                (cid,),
            ).fetchone()
            if row is None:
                count = self._conn.execute("SELECT MAX(id) FROM candidates").fetchone()[0]
        if row is None:
            known = f"the workspace has candidates 1-{count}" if count else "there are none yet"
            raise InputError(f"no candidate {cid}; {known}")
        return CandidateRow(
            id=row[0],
            created_at=row[1],
            query=row[2],
            drafter=row[3],
            drafter_kind=row[4],
            name=row[5],
            axiom=row[6],
            rule=json.loads(row[7]),
            draft=json.loads(row[8]),
            evidence=tuple(json.loads(row[9])),
            retrieved=tuple(json.loads(row[10])),
            origin=row[11],
        )

    def candidate_ids(self) -> list[int]:
        with self._lock:
            return [r[0] for r in self._conn.execute("SELECT id FROM candidates ORDER BY id")]

    # ------------------------------------------------------------ checks, previews
    def add_check(self, cid: int, axiom: str, passed: bool, report: dict[str, Any]) -> None:
        with self._lock:
            self._conn.execute(
                "INSERT INTO checks (candidate_id, created_at, axiom, passed, report) "
                "VALUES (?, ?, ?, ?, ?)",
                (cid, now(), axiom, int(passed), _dump(report)),
            )

    def latest_check(self, cid: int) -> dict[str, Any] | None:
        return self._latest("checks", cid)

    def first_check(self, cid: int) -> dict[str, Any] | None:
        with self._lock:
            row = self._conn.execute(
                "SELECT report FROM checks WHERE candidate_id = ? ORDER BY id LIMIT 1", (cid,)
            ).fetchone()
        return None if row is None else dict(json.loads(row[0]))

    def add_preview(self, cid: int, axiom: str, report: dict[str, Any]) -> None:
        with self._lock:
            self._conn.execute(
                "INSERT INTO previews (candidate_id, created_at, axiom, report) VALUES (?, ?, ?, ?)",
                (cid, now(), axiom, _dump(report)),
            )

    def latest_preview(self, cid: int) -> dict[str, Any] | None:
        return self._latest("previews", cid)

    def _latest(self, table: str, cid: int) -> dict[str, Any] | None:
        with self._lock:
            row = self._conn.execute(
                f"SELECT report FROM {table} WHERE candidate_id = ? ORDER BY id DESC LIMIT 1",
                (cid,),
            ).fetchone()
        return None if row is None else dict(json.loads(row[0]))

    # ------------------------------------------------------------ decisions
    def add_decision(self, conn: sqlite3.Connection, d: DecisionRow) -> None:
        try:
            conn.execute(
                "INSERT INTO decisions (candidate_id, created_at, decision, edit, axiom, layer, "
                "reason, reviewer, seconds, block) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    d.candidate_id,
                    d.created_at,
                    d.decision,
                    d.edit,
                    d.axiom,
                    d.layer,
                    d.reason,
                    d.reviewer,
                    d.seconds,
                    d.block,
                ),
            )
        except sqlite3.IntegrityError:
            raise InputError(f"candidate {d.candidate_id} has already been decided") from None

    def decision(self, cid: int) -> DecisionRow | None:
        rows = self.decisions(cid)
        return rows[0] if rows else None

    def undecided(self, cid: int) -> None:
        """Refuse a candidate that has been decided: a decision is final, so
        it is neither checked, previewed nor decided again."""
        decided = self.decision(cid)
        if decided is not None:
            what = "accepted" if decided.decision == "accept" else "rejected"
            raise InputError(f"candidate {cid} has already been decided ({what})")

    def decisions(self, cid: int | None = None) -> list[DecisionRow]:
        sql = (
            "SELECT candidate_id, created_at, decision, edit, axiom, layer, reason, reviewer, "
            "seconds, block FROM decisions"
        )
        args: tuple[int, ...] = ()
        if cid is not None:
            sql += " WHERE candidate_id = ?"
            args = (cid,)
        with self._lock:
            rows = self._conn.execute(sql + " ORDER BY id", args).fetchall()
        return [DecisionRow(*r) for r in rows]

    def statuses(self) -> dict[int, str]:
        with self._lock:
            rows = self._conn.execute(
                "SELECT c.id, d.decision FROM candidates c "
                "LEFT JOIN decisions d ON d.candidate_id = c.id ORDER BY c.id"
            ).fetchall()
        return {cid: status_of(dec) for cid, dec in rows}

    # ------------------------------------------------------------ events
    def add_event(
        self, kind: str, cid: int | None = None, actor: str | None = None, detail: str | None = None
    ) -> None:
        with self._lock:
            self._conn.execute(
                "INSERT INTO events (candidate_id, created_at, kind, actor, detail) "
                "VALUES (?, ?, ?, ?, ?)",
                (cid, now(), kind, actor, detail),
            )

    def first_event(self, cid: int, kind: str) -> str | None:
        """When ``kind`` first happened to the candidate (ISO time)."""
        with self._lock:
            row = self._conn.execute(
                "SELECT created_at FROM events WHERE candidate_id = ? AND kind = ? "
                "ORDER BY id LIMIT 1",
                (cid, kind),
            ).fetchone()
        return None if row is None else str(row[0])

    def event_details(self, kind: str) -> list[str]:
        with self._lock:
            rows = self._conn.execute(
                "SELECT detail FROM events WHERE kind = ? ORDER BY id", (kind,)
            ).fetchall()
        return [str(r[0]) for r in rows]

    def count_events(self, kind: str) -> int:
        with self._lock:
            row = self._conn.execute(
                "SELECT COUNT(*) FROM events WHERE kind = ?", (kind,)
            ).fetchone()
        return int(row[0])


def _dump(value: object) -> str:
    return json.dumps(value, sort_keys=True, ensure_ascii=False)
