"""The SQLite run log: append-only migrations and what every apprentice logs."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest
from runlog_support import MESSAGES, log_one

from virf.errors import EnvironmentProblem, InputError
from virf.migrations import check_migrations
from virf.planner import (
    MIGRATIONS,
    Migration,
    Proposal,
    Purpose,
    ReplayApprentice,
    RunLog,
    ScriptedApprentice,
    export_replay,
)

# Shipped migrations are frozen: editing one changes its hash and breaks every
# database that already ran it.  Add a new migration instead of changing these.
FROZEN = {
    "0001_model_calls": "f445010d532d9ce411eb0f1f348c7573499c0e94707c60cea6b535a4b133b0e2",
    "0002_service_runs": "301e6977802e3441f6a2500798520fd24ea8d25d50447efbbf4a76419b43851b",
}

EXTRA = Migration(
    "0002_test_notes",
    """
    ALTER TABLE model_calls ADD COLUMN note TEXT;
    CREATE TABLE notes (id INTEGER PRIMARY KEY, body TEXT NOT NULL);
    CREATE TRIGGER note_body AFTER INSERT ON notes BEGIN
        UPDATE notes SET body = trim(NEW.body) WHERE id = NEW.id;
    END;
    """,
)


def tables(path: Path) -> set[str]:
    with sqlite3.connect(path) as conn:
        return {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}


def test_shipped_migrations_are_never_edited() -> None:
    check_migrations(MIGRATIONS)
    shipped = {m.id: m.sha256 for m in MIGRATIONS[: len(FROZEN)]}
    assert shipped == FROZEN


def test_new_database_gets_every_migration(tmp_path: Path) -> None:
    path = tmp_path / "runs.db"
    with RunLog(path, run_id="a") as log:
        assert log.applied_migrations() == [m.id for m in MIGRATIONS]
    assert {"_migrations", "model_calls"} <= tables(path)


def test_opening_twice_applies_nothing_new(tmp_path: Path) -> None:
    path = tmp_path / "runs.db"
    with RunLog(path, run_id="a") as log:
        log_one(log)
    with RunLog(path, run_id="b") as log:
        assert log.applied_migrations() == [m.id for m in MIGRATIONS]
        log_one(log, "t2")
        assert [c.task_id for c in log.calls()] == ["t1", "t2"]
        assert log.run_ids() == ["a", "b"]
        assert [c.run_id for c in log.calls(run_id="b")] == ["b"]


def test_old_database_gets_the_missing_migration(tmp_path: Path) -> None:
    path = tmp_path / "runs.db"
    with RunLog(path, run_id="old") as log:
        log_one(log)
    with RunLog(path, run_id="new", migrations=(*MIGRATIONS, EXTRA)) as log:
        assert log.applied_migrations() == [*(m.id for m in MIGRATIONS), EXTRA.id]
        # Rows written before the migration survive it.
        assert [c.run_id for c in log.calls()] == ["old"]
    assert "notes" in tables(path)
    with sqlite3.connect(path) as conn:
        conn.execute("INSERT INTO notes (body) VALUES ('  padded  ')")
        assert conn.execute("SELECT body FROM notes").fetchone() == ("padded",)
        assert "note" in {r[1] for r in conn.execute("PRAGMA table_info(model_calls)")}
    # Code that lacks a migration refuses the file rather than guess at its schema.
    with pytest.raises(EnvironmentProblem) as exc:
        RunLog(path, run_id="older")
    assert str(exc.value) == (
        f"run log {path} was written by a newer VIRF (migration {EXTRA.id}); "
        "upgrade VIRF or choose another file"
    )


def test_edited_migration_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "runs.db"
    RunLog(path, run_id="a", migrations=(*MIGRATIONS, EXTRA)).close()
    edited = Migration(EXTRA.id, EXTRA.sql.replace("note TEXT", "note BLOB"))
    with pytest.raises(EnvironmentProblem, match="migration 0002_test_notes differs"):
        RunLog(path, run_id="a", migrations=(*MIGRATIONS, edited))


def test_failed_migration_rolls_back(tmp_path: Path) -> None:
    path = tmp_path / "runs.db"
    RunLog(path, run_id="a").close()
    broken = Migration("0002_broken", "CREATE TABLE half (x); INSERT INTO nowhere VALUES (1);")
    with pytest.raises(EnvironmentProblem) as exc:
        RunLog(path, run_id="a", migrations=(*MIGRATIONS, broken))
    assert str(exc.value).startswith(f"cannot migrate run log {path}: no such table: nowhere")
    assert "half" not in tables(path)
    with RunLog(path, run_id="a") as log:
        assert log.applied_migrations() == [m.id for m in MIGRATIONS]


@pytest.mark.parametrize(
    "migrations",
    [
        (Migration("2_bad_id", "SELECT 1"),),
        (Migration("0001_a", "SELECT 1"), Migration("0001_a", "SELECT 2")),
        (Migration("0001_a", "SELECT 1; SELECT 'unterminated"),),
    ],
)
def test_malformed_migration_lists(migrations: tuple[Migration, ...]) -> None:
    with pytest.raises(ValueError):
        check_migrations(migrations)


def test_not_a_database(tmp_path: Path) -> None:
    path = tmp_path / "notes.txt"
    path.write_text("this is not sqlite, but it is long enough to have a header" * 20)
    with pytest.raises(InputError) as exc:
        RunLog(path, run_id="a")
    assert str(exc.value) == f"run log {path} is not a SQLite database; choose another file"


def test_bad_paths(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="is a directory"):
        RunLog(tmp_path, run_id="a")
    with pytest.raises(InputError, match="does not exist; create it first"):
        RunLog(tmp_path / "missing" / "runs.db", run_id="a")


def test_default_run_ids_are_distinct(tmp_path: Path) -> None:
    with RunLog(tmp_path / "a.db") as one, RunLog(tmp_path / "a.db") as two:
        assert one.run_id != two.run_id


def test_call_records_round_trip(tmp_path: Path) -> None:
    with RunLog(tmp_path / "runs.db", run_id="r") as log:
        row = log_one(log, reply=None)
        (call,) = log.calls()
    assert call.id == row and call.run_id == "r"
    assert call.messages == MESSAGES and call.reply is None and call.ok is False
    assert call.reason == "the reply was empty"
    assert (call.prompt_tokens, call.completion_tokens, call.latency_ms, call.attempts) == (
        3,
        2,
        1.5,
        1,
    )
    assert call.created_at.endswith("+00:00")


def test_offline_apprentices_log_like_online_ones(tmp_path: Path) -> None:
    with RunLog(tmp_path / "runs.db", run_id="scripted-run") as log:
        scripted = ScriptedApprentice(
            ["find Apple\nslice Apple", " ", Proposal.failed("planner crashed")], run_log=log
        )
        for iteration in (1, 2, 3):
            scripted.propose(
                MESSAGES,
                task_id="t1",
                iteration=iteration,
                method="impulsive",
                purpose=Purpose.PLAN,
            )
        calls = log.calls()
        assert [(c.iteration, c.ok, c.reply, c.reason) for c in calls] == [
            (1, True, "find Apple\nslice Apple", ""),
            (2, False, " ", "the reply was only whitespace"),
            (3, False, None, "planner crashed"),
        ]
        assert {(c.apprentice, c.method, c.ask) for c in calls} == {("scripted", "impulsive", 1)}

        path = tmp_path / "replay.jsonl"
        assert export_replay(log, "scripted-run", path) == 3
        first = json.loads(path.read_text().splitlines()[0])
        assert first["text"] == "find Apple\nslice Apple" and first["method"] == "impulsive"

    with RunLog(tmp_path / "runs.db", run_id="replayed") as log:
        replay = ReplayApprentice(path, run_log=log)
        for iteration in (1, 2, 3):
            replay.propose(
                MESSAGES,
                task_id="t1",
                iteration=iteration,
                method="impulsive",
                purpose=Purpose.PLAN,
            )
        replayed = log.calls(run_id="replayed")
        assert [(c.ok, c.reason) for c in replayed] == [(c.ok, c.reason) for c in calls]
        assert {c.apprentice for c in replayed} == {f"replay:{path}"}
        with pytest.raises(InputError, match="has no calls for run 'nope'"):
            export_replay(log, "nope", tmp_path / "x.jsonl")
