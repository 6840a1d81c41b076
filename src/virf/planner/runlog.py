"""The run log: every model call an apprentice makes, for audit and replay.

A SQLite file, or a PostgreSQL database given by URL where several service
machines share one log (:mod:`virf.database`).  The schema evolves only by
appending to ``MIGRATIONS`` (see :mod:`virf.migrations`).
"""

from __future__ import annotations

import json
import threading
import uuid
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from types import TracebackType
from typing import Any, Final, Self

from virf.database import PostgresConnection, connect, errors_of, first_line, is_url, shown
from virf.errors import EnvironmentProblem, InputError
from virf.migrations import Migration, applied_migrations, check_migrations, migrate
from virf.migrations import now as _now

# Append only.  Never edit or reorder an entry once it has been committed.
MIGRATIONS: Final[tuple[Migration, ...]] = (
    Migration(
        "0001_model_calls",
        """
        CREATE TABLE model_calls (
            id                INTEGER PRIMARY KEY AUTOINCREMENT,
            run_id            TEXT    NOT NULL,
            method            TEXT    NOT NULL,
            task_id           TEXT    NOT NULL,
            iteration         INTEGER NOT NULL,
            ask               INTEGER NOT NULL,
            apprentice        TEXT    NOT NULL,
            model             TEXT,
            prompt            TEXT    NOT NULL,
            reply             TEXT,
            ok                INTEGER NOT NULL CHECK (ok IN (0, 1)),
            reason            TEXT    NOT NULL,
            prompt_tokens     INTEGER,
            completion_tokens INTEGER,
            latency_ms        REAL    NOT NULL,
            attempts          INTEGER NOT NULL,
            created_at        TEXT    NOT NULL
        );
        CREATE INDEX model_calls_by_task ON model_calls (run_id, task_id, iteration, method);
        """,
    ),
    # The service's runs, so that any of its workers (or machines, on a
    # shared PostgreSQL log) can show a run, stream it and take its answers.
    Migration(
        "0002_service_runs",
        """
        CREATE TABLE service_runs (
            id         TEXT    PRIMARY KEY,
            state      TEXT    NOT NULL,
            asks       INTEGER NOT NULL,
            body       TEXT    NOT NULL,
            updated_at TEXT    NOT NULL
        );
        CREATE TABLE service_answers (
            id         INTEGER PRIMARY KEY AUTOINCREMENT,
            run_id     TEXT    NOT NULL,
            asks       INTEGER NOT NULL,
            answers    TEXT    NOT NULL,
            created_at TEXT    NOT NULL
        );
        CREATE INDEX service_answers_by_run ON service_answers (run_id, asks);
        """,
    ),
)


@dataclass(frozen=True)
class CallRecord:
    """One logged model call, as stored."""

    id: int
    run_id: str
    method: str
    task_id: str
    iteration: int
    ask: int
    apprentice: str
    model: str | None
    messages: list[dict[str, Any]]
    reply: str | None
    ok: bool
    reason: str
    prompt_tokens: int | None
    completion_tokens: int | None
    latency_ms: float
    attempts: int
    created_at: str


def last_attempts(calls: Iterable[CallRecord]) -> list[CallRecord]:
    """The calls of each (task, method)'s last attempt, in log order.

    A task run again (after an interruption, say) asks iteration 0 anew, and
    only that attempt's outcome is kept by whoever ran it; the calls of the
    attempts before it would count twice in a replay file or a time table."""
    calls = list(calls)
    start: dict[tuple[str, str], int] = {}
    for call in calls:
        if call.iteration == 0 and call.ask == 1:
            start[(call.task_id, call.method)] = call.id
    return [c for c in calls if c.id >= start.get((c.task_id, c.method), c.id)]


class RunLog:
    """An append-only log of model calls for one run (``run_id``).

    Several runs may share one log; each row carries its run id.  Safe to
    share between threads of one process: writes are serialised by a lock.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        run_id: str | None = None,
        migrations: Sequence[Migration] = MIGRATIONS,
    ) -> None:
        check_migrations(migrations)
        # A URL stays a string: Path would fold its '//'.
        self.path: str | Path = path if is_url(path) else Path(path)
        # A fresh id per run keeps two runs in one file apart; callers that
        # resume a run pass its id explicitly.
        self.run_id = run_id if run_id is not None else _new_run_id()
        if not self.run_id:
            raise InputError("run id must be a non-empty string")
        self._lock = threading.Lock()
        self._conn = connect(self.path, "run log")
        self._errors = errors_of(self._conn)
        self._postgres = isinstance(self._conn, PostgresConnection)
        try:
            self._migrate(migrations)
        except BaseException:
            self._conn.close()
            raise

    @property
    def where(self) -> str:
        """The log for messages (a URL without its password)."""
        return shown(self.path)

    # -- schema ------------------------------------------------------------

    def _migrate(self, migrations: Sequence[Migration]) -> None:
        migrate(self._conn, migrations, f"run log {self.where}")

    def applied_migrations(self) -> list[str]:
        """Ids of the migrations this database has run, oldest first."""
        with self._lock:
            return applied_migrations(self._conn)

    # -- writing and reading ---------------------------------------------------

    def log_call(
        self,
        *,
        method: str,
        task_id: str,
        iteration: int,
        ask: int,
        apprentice: str,
        model: str | None,
        messages: Sequence[dict[str, Any]],
        reply: str | None,
        ok: bool,
        reason: str,
        prompt_tokens: int | None,
        completion_tokens: int | None,
        latency_ms: float,
        attempts: int,
    ) -> int:
        """Append one call and return its row id."""
        prompt = json.dumps(list(messages), ensure_ascii=False)
        with self._lock:
            try:
                cur = self._conn.execute(
                    """
                    INSERT INTO model_calls (
                        run_id, method, task_id, iteration, ask, apprentice, model, prompt,
                        reply, ok, reason, prompt_tokens, completion_tokens, latency_ms,
                        attempts, created_at
                    ) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)
                    """
                    # PostgreSQL has no last row id; SQLite before 3.35 has no RETURNING.
                    + (" RETURNING id" if self._postgres else ""),
                    (
                        self.run_id,
                        method,
                        task_id,
                        iteration,
                        ask,
                        apprentice,
                        model,
                        prompt,
                        reply,
                        int(ok),
                        reason,
                        prompt_tokens,
                        completion_tokens,
                        float(latency_ms),
                        attempts,
                        _now(),
                    ),
                )
                found = cur.fetchone()[0] if self._postgres else cur.lastrowid
                assert found is not None  # every INSERT makes a row with an id
                row_id = int(found)
            except self._errors as exc:
                raise EnvironmentProblem(
                    f"cannot write run log {self.where}: {first_line(exc)}"
                ) from None
        return row_id

    def calls(self, *, run_id: str | None = None, task_id: str | None = None) -> list[CallRecord]:
        """Logged calls in the order they were made, optionally filtered."""
        where, params = [], []
        if run_id is not None:
            where.append("run_id = ?")
            params.append(run_id)
        if task_id is not None:
            where.append("task_id = ?")
            params.append(task_id)
        sql = (
            "SELECT id, run_id, method, task_id, iteration, ask, apprentice, model, prompt, "
            "reply, ok, reason, prompt_tokens, completion_tokens, latency_ms, attempts, "
            "created_at FROM model_calls"
        )
        if where:
            sql += " WHERE " + " AND ".join(where)
        sql += " ORDER BY id"
        with self._lock:
            rows = self._conn.execute(sql, params).fetchall()
        return [
            CallRecord(
                id=r[0],
                run_id=r[1],
                method=r[2],
                task_id=r[3],
                iteration=r[4],
                ask=r[5],
                apprentice=r[6],
                model=r[7],
                messages=json.loads(r[8]),
                reply=r[9],
                ok=bool(r[10]),
                reason=r[11],
                prompt_tokens=r[12],
                completion_tokens=r[13],
                latency_ms=r[14],
                attempts=r[15],
                created_at=r[16],
            )
            for r in rows
        ]

    def run_ids(self) -> list[str]:
        """Every run in this file, in the order each first logged a call."""
        with self._lock:
            rows = self._conn.execute(
                "SELECT run_id FROM model_calls GROUP BY run_id ORDER BY MIN(id)"
            ).fetchall()
        return [r[0] for r in rows]

    # -- the service's runs -----------------------------------------------------

    def save_run(self, run_id: str, state: str, asks: int, body: dict[str, object]) -> None:
        """Record a service run as it stands now (replacing what was there)."""
        with self._lock:
            try:
                self._conn.execute(
                    """
                    INSERT INTO service_runs (id, state, asks, body, updated_at)
                    VALUES (?, ?, ?, ?, ?)
                    ON CONFLICT (id) DO UPDATE SET state = excluded.state,
                        asks = excluded.asks, body = excluded.body,
                        updated_at = excluded.updated_at
                    """,
                    (run_id, state, asks, json.dumps(body, sort_keys=True), _now()),
                )
            except self._errors as exc:
                raise EnvironmentProblem(
                    f"cannot write run log {self.where}: {first_line(exc)}"
                ) from None

    def load_run(self, run_id: str) -> dict[str, object] | None:
        """A service run as last recorded, or None."""
        row = self._read_one("SELECT body FROM service_runs WHERE id = ?", (run_id,))
        return None if row is None else dict(json.loads(row[0]))

    def post_answers(self, run_id: str, asks: int, answers: dict[str, str]) -> None:
        """Answers for the ``asks``-th time the run waits (any worker may take them)."""
        with self._lock:
            try:
                self._conn.execute(
                    "INSERT INTO service_answers (run_id, asks, answers, created_at) "
                    "VALUES (?, ?, ?, ?)",
                    (run_id, asks, json.dumps(answers, sort_keys=True), _now()),
                )
            except self._errors as exc:
                raise EnvironmentProblem(
                    f"cannot write run log {self.where}: {first_line(exc)}"
                ) from None

    def posted_answers(self, run_id: str, asks: int) -> dict[str, str] | None:
        """The first answers posted for that wait of the run, or None yet."""
        row = self._read_one(
            "SELECT answers FROM service_answers WHERE run_id = ? AND asks = ? ORDER BY id LIMIT 1",
            (run_id, asks),
        )
        return None if row is None else {str(k): str(v) for k, v in json.loads(row[0]).items()}

    def _read_one(self, sql: str, params: tuple[object, ...]) -> tuple[str, ...] | None:
        with self._lock:
            try:
                row: tuple[str, ...] | None = self._conn.execute(sql, params).fetchone()
            except self._errors as exc:
                raise EnvironmentProblem(
                    f"cannot read run log {self.where}: {first_line(exc)}"
                ) from None
        return row

    # -- lifetime ------------------------------------------------------------

    def close(self) -> None:
        with self._lock:
            self._conn.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def _new_run_id() -> str:
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    return f"{stamp}-{uuid.uuid4().hex[:8]}"
