"""Append-only schema migrations, shared by every database VIRF writes (the
planner's run log, a knowledge workspace's store).  They are written for
SQLite; a run log on PostgreSQL runs the same ones (:mod:`virf.database`).

A migration that has shipped is never edited: databases in the field already
ran it, and the hash stored in ``_migrations`` turns an edit into a loud error
instead of a silently diverging schema.  Opening a database applies the
migrations it lacks, in order, in one transaction.
"""

from __future__ import annotations

import contextlib
import hashlib
import re
import sqlite3
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Final

from virf.database import PostgresConnection, errors_of, first_line
from virf.errors import EnvironmentProblem, InputError


@dataclass(frozen=True)
class Migration:
    """One schema step: a stable id and the SQL it runs (several statements allowed)."""

    id: str
    sql: str

    @property
    def sha256(self) -> str:
        return hashlib.sha256(self.sql.encode("utf-8")).hexdigest()


_MIGRATION_ID: Final = re.compile(r"^[0-9]{4}_[a-z0-9_]+$")

# Any fixed number: the advisory lock that serialises migrations on a server.
_LOCK_KEY: Final = 0x56495246

_BOOKKEEPING: Final = """
CREATE TABLE IF NOT EXISTS _migrations (
    id         TEXT PRIMARY KEY,
    sha256     TEXT NOT NULL,
    applied_at TEXT NOT NULL
)
"""


def now() -> str:
    """The time stamps every VIRF database stores: UTC, ISO 8601, milliseconds."""
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def statements(sql: str) -> list[str]:
    """Split a migration into statements without breaking a trigger body.

    ``sqlite3.Connection.execute`` runs one statement, and ``executescript``
    commits on its own, which would let a half-applied migration escape its
    transaction.  ``sqlite3.complete_statement`` knows where a statement ends.
    """
    out: list[str] = []
    pending = ""
    for piece in sql.split(";"):
        pending += piece + ";"
        if sqlite3.complete_statement(pending):
            if pending.strip(" \t\r\n;"):
                out.append(pending.strip())
            pending = ""
    if pending.strip(" \t\r\n;"):
        raise ValueError("migration SQL ends with an incomplete statement")
    return out


def check_migrations(migrations: Sequence[Migration]) -> None:
    """Reject a malformed migration list: a programming error, caught by tests."""
    seen: set[str] = set()
    for m in migrations:
        if not _MIGRATION_ID.match(m.id):
            raise ValueError(f"migration id {m.id!r} must look like 0001_name")
        if m.id in seen:
            raise ValueError(f"migration id {m.id} appears twice")
        seen.add(m.id)
        statements(m.sql)


def migrate(
    conn: sqlite3.Connection | PostgresConnection, migrations: Sequence[Migration], what: str
) -> None:
    """Apply the migrations ``conn`` lacks (``conn`` in autocommit mode).

    ``what`` names the database in messages ("run log runs/log.sqlite")."""
    postgres = isinstance(conn, PostgresConnection)
    errors = errors_of(conn)
    try:
        if postgres:
            conn.execute("BEGIN")
            # Two service machines starting at once: one migrates, the other waits.
            conn.execute("SELECT pg_advisory_xact_lock(?)", (_LOCK_KEY,))
        else:
            conn.execute("BEGIN IMMEDIATE")
        conn.execute(_BOOKKEEPING)
        applied = {row[0]: row[1] for row in conn.execute("SELECT id, sha256 FROM _migrations")}
        known = {m.id for m in migrations}
        newer = sorted(set(applied) - known)
        if newer:
            raise EnvironmentProblem(
                f"{what} was written by a newer VIRF (migration {newer[0]}); "
                "upgrade VIRF or choose another file"
            )
        for m in migrations:
            if m.id in applied:
                if applied[m.id] != m.sha256:
                    raise EnvironmentProblem(
                        f"{what}: migration {m.id} differs from the one applied; "
                        "migrations are append-only, add a new one instead of editing"
                    )
                continue
            for statement in statements(m.sql):
                conn.execute(
                    conn.translate(statement) if isinstance(conn, PostgresConnection) else statement
                )
            conn.execute(
                "INSERT INTO _migrations (id, sha256, applied_at) VALUES (?, ?, ?)",
                (m.id, m.sha256, now()),
            )
        conn.execute("COMMIT")
    except errors as exc:
        rollback(conn)
        if "not a database" in str(exc):
            raise InputError(f"{what} is not a SQLite database; choose another file") from None
        raise EnvironmentProblem(f"cannot migrate {what}: {first_line(exc)}") from None
    except BaseException:
        rollback(conn)
        raise


def rollback(conn: sqlite3.Connection | PostgresConnection) -> None:
    # The failure may have ended the transaction already; the original error
    # is the one worth reporting.
    with contextlib.suppress(*errors_of(conn)):
        conn.execute("ROLLBACK")


def applied_migrations(conn: sqlite3.Connection | PostgresConnection) -> list[str]:
    """Ids of the migrations a database has run, oldest first."""
    return [r[0] for r in conn.execute("SELECT id FROM _migrations ORDER BY id").fetchall()]
