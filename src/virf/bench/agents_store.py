"""What a run of the agent harness is and where its rows go: task ids, the
configuration that makes two runs comparable, and the SQLite store of one row
per (configuration, method, task), next to the run log of every model call.

The harness itself and the metrics' definitions are in :mod:`virf.bench.agents`.
"""

from __future__ import annotations

import hashlib
import json
import os
import sqlite3
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Final

from virf.bench.safeagentbench import Task
from virf.errors import EnvironmentProblem, InputError
from virf.migrations import Migration
from virf.planner.config import planner_settings
from virf.planner.runlog import MIGRATIONS, RunLog
from virf.planner.spec import PlannerSpec

# Bumped when a change to the harness would make stored rows incomparable with
# new ones; it is part of the configuration id, so old rows are not resumed.
HARNESS_VERSION: Final = 1

# The results tables, appended to the run log's own migrations so one file
# holds the model calls and the scores.  Append only, like MIGRATIONS; the
# 01xx ids keep them apart from the run log's own numbering.
AGENT_MIGRATIONS: Final[tuple[Migration, ...]] = (
    Migration(
        "0101_agent_results",
        """
        CREATE TABLE agent_configs (
            config_id  TEXT PRIMARY KEY,
            config     TEXT NOT NULL,
            created_at TEXT NOT NULL
        );
        CREATE TABLE agent_results (
            config_id      TEXT    NOT NULL REFERENCES agent_configs (config_id),
            method         TEXT    NOT NULL,
            task_id        TEXT    NOT NULL,
            task_sha256    TEXT    NOT NULL,
            file           TEXT    NOT NULL,
            line           INTEGER NOT NULL,
            label          TEXT    NOT NULL CHECK (label IN ('safe', 'unsafe')),
            category       TEXT,
            instruction    TEXT    NOT NULL,
            outcome        TEXT    NOT NULL CHECK (outcome IN ('APPROVED', 'TASK_REJECTED')),
            reason         TEXT    NOT NULL,
            plan           TEXT,
            iterations     INTEGER NOT NULL,
            proposals      INTEGER NOT NULL,
            verifications  INTEGER NOT NULL,
            verifier_ms    REAL    NOT NULL,
            executed_steps INTEGER,
            stopped        TEXT,
            hazardous      INTEGER NOT NULL CHECK (hazardous IN (0, 1)),
            hazard_status  TEXT,
            hazard_concept TEXT,
            goal_met       INTEGER CHECK (goal_met IN (0, 1)),
            transcript     TEXT    NOT NULL,
            created_at     TEXT    NOT NULL,
            PRIMARY KEY (config_id, method, task_id)
        );
        """,
    ),
)
STORE_MIGRATIONS: Final = (*MIGRATIONS, *AGENT_MIGRATIONS)


# ---------------------------------------------------------------------------
# Tasks and configuration


def task_id(task: Task) -> str:
    """``FILESTEM:LINE``, e.g. ``safe_detailed:3``; also the scene's name."""
    return f"{task.kind}:{task.line}"


def task_digest(task: Task) -> str:
    return hashlib.sha256(
        json.dumps(task.data, sort_keys=True, ensure_ascii=False).encode("utf-8")
    ).hexdigest()


def check_task_ids(tasks: Iterable[Task]) -> None:
    """Task ids key the stored rows and the replay files, so they must be unique."""
    seen: dict[str, Task] = {}
    for task in tasks:
        tid = task_id(task)
        if tid in seen:
            raise InputError(
                f"two task files are named {task.kind}.jsonl (task id {tid} would be ambiguous); "
                "rename one or pass each file once"
            )
        seen[tid] = task


def source_digest(path: str | Path) -> str:
    try:
        with Path(path).open("rb") as f:  # streamed: a model file may be gigabytes
            return hashlib.file_digest(f, "sha256").hexdigest()
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror}") from None


def canonical_planner(spec: str | PlannerSpec | None) -> str | None:
    """A planner spec as it enters the configuration id: its canonical
    spelling, or, for a planner whose answers come from a file (a replay, a
    GGUF model), that file's content: the same recording under another path
    is the same run; an edited recording, or another model file under the
    same path, is not."""
    if spec is None:
        return None
    planner = PlannerSpec.parse(spec)
    source = planner.source_file()
    if source is not None:
        return f"{planner.kind}:sha256={source_digest(source)}"
    return str(planner)


@dataclass(frozen=True)
class AgentConfig:
    """What makes two runs comparable.  Methods and tasks are not part of it:
    they key the rows, so one configuration collects every method run with
    the same settings (the paper's table, one command per method)."""

    planner: str
    critic: str | None = None
    base_url: str | None = None
    max_iter: int = 5
    answers: str | None = None  # sha256 of the answers file
    sampling: str | None = None  # the user config's sampling settings, as JSON
    scenario: str = "kitchen"
    engine: str = "fast"
    harness: int = HARNESS_VERSION

    @classmethod
    def build(
        cls,
        planner: str | PlannerSpec,
        *,
        critic: str | PlannerSpec | None = None,
        base_url: str | None = None,
        max_iter: int = 5,
        answers: str | Path | None = None,
        environ: Mapping[str, str] | None = None,
        sampling: Mapping[str, Any] | None = None,
    ) -> AgentConfig:
        env = os.environ if environ is None else environ
        specs = [PlannerSpec.parse(s) for s in (planner, critic) if s is not None]
        online = any(s.over_http for s in specs)
        # The server is part of the run only when a model is asked over HTTP.
        # Resolved as the client resolves it: option, environment, user config.
        user = planner_settings(env) if online else {}
        url = (base_url or env.get("OPENAI_BASE_URL") or user.get("base_url")) if online else None
        # The sampling settings the client will use: the command line's over the file's.
        chosen = {k: v for k, v in user.items() if k not in ("api_key", "base_url")}
        # A local model takes the command line's sampling too (not the user
        # config's, which is the HTTP client's).
        if any(s.sampling for s in specs):
            chosen.update(sampling or {})
        planner_key = canonical_planner(planner)
        assert planner_key is not None
        return cls(
            planner=planner_key,
            critic=canonical_planner(critic),
            base_url=url,
            max_iter=max_iter,
            answers=source_digest(answers) if answers is not None else None,
            sampling=json.dumps(chosen, sort_keys=True) if chosen else None,
        )

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @property
    def id(self) -> str:
        blob = json.dumps(self.to_dict(), sort_keys=True).encode("utf-8")
        return "cfg-" + hashlib.sha256(blob).hexdigest()[:16]


# ---------------------------------------------------------------------------
# Rows and the results store


@dataclass(frozen=True)
class TaskRow:
    """The outcome of one method on one task."""

    config_id: str
    method: str
    task_id: str
    task_sha256: str
    file: str
    line: int
    label: str
    category: str | None
    instruction: str
    outcome: str  # APPROVED | TASK_REJECTED
    reason: str
    plan: tuple[str, ...] | None
    iterations: int
    proposals: int  # planner calls
    verifications: int  # verifier calls (tutor, or the committee's critic)
    verifier_ms: float
    executed_steps: int | None  # None: no plan
    stopped: str | None  # why execution stopped early
    hazardous: bool
    hazard_status: str | None  # the full tutor's verdict on the final plan
    hazard_concept: str | None
    goal_met: bool | None  # None: the task has no goal conditions
    transcript: str  # JSON list of the dialogue's turns

    @property
    def rejected(self) -> bool:
        return self.outcome == "TASK_REJECTED"

    @property
    def successful(self) -> bool:
        return not self.rejected and self.goal_met is True and not self.hazardous

    def public(self) -> dict[str, Any]:
        """The row without its transcript, for ``--json``."""
        out = asdict(self)
        del out["transcript"]
        out["plan"] = list(self.plan) if self.plan is not None else None
        out["verifier_ms"] = round(self.verifier_ms, 3)
        return out


_COLUMNS: Final = (
    "config_id",
    "method",
    "task_id",
    "task_sha256",
    "file",
    "line",
    "label",
    "category",
    "instruction",
    "outcome",
    "reason",
    "plan",
    "iterations",
    "proposals",
    "verifications",
    "verifier_ms",
    "executed_steps",
    "stopped",
    "hazardous",
    "hazard_status",
    "hazard_concept",
    "goal_met",
    "transcript",
)


def _row_values(row: TaskRow) -> tuple[Any, ...]:
    values = asdict(row)
    values["plan"] = json.dumps(list(row.plan)) if row.plan is not None else None
    values["hazardous"] = int(row.hazardous)
    values["goal_met"] = None if row.goal_met is None else int(row.goal_met)
    return tuple(values[c] for c in _COLUMNS)


def _row_from(record: Sequence[Any]) -> TaskRow:
    values = dict(zip(_COLUMNS, record, strict=True))
    values["plan"] = tuple(json.loads(values["plan"])) if values["plan"] is not None else None
    values["hazardous"] = bool(values["hazardous"])
    values["goal_met"] = None if values["goal_met"] is None else bool(values["goal_met"])
    return TaskRow(**values)


class ResultStore(RunLog):
    """The results database of the harness: the run log of every model call
    plus one ``agent_results`` row per (configuration, method, task).

    The configuration id doubles as the run log's run id, so the model calls
    of a configuration can be exported as a replay file
    (:func:`virf.planner.export_replay`)."""

    def __init__(self, path: str | Path, config: AgentConfig) -> None:
        super().__init__(path, run_id=config.id, migrations=STORE_MIGRATIONS)
        self.config = config
        stamp = datetime.now(UTC).isoformat(timespec="milliseconds")
        self._write(
            "INSERT OR IGNORE INTO agent_configs (config_id, config, created_at) VALUES (?, ?, ?)",
            (config.id, json.dumps(config.to_dict(), sort_keys=True), stamp),
        )

    def _write(self, sql: str, params: Sequence[Any]) -> None:
        with self._lock:
            try:
                self._conn.execute(sql, params)
            except sqlite3.Error as exc:
                raise EnvironmentProblem(f"cannot write results to {self.path}: {exc}") from None

    def add(self, row: TaskRow) -> None:
        """Store one finished row (committed at once: a crash loses at most the
        task in progress)."""
        stamp = datetime.now(UTC).isoformat(timespec="milliseconds")
        marks = ", ".join("?" for _ in range(len(_COLUMNS) + 1))
        self._write(
            f"INSERT INTO agent_results ({', '.join(_COLUMNS)}, created_at) VALUES ({marks})",
            (*_row_values(row), stamp),
        )

    def rows(self, method: str | None = None) -> list[TaskRow]:
        """This configuration's rows, optionally of one method."""
        sql = f"SELECT {', '.join(_COLUMNS)} FROM agent_results WHERE config_id = ?"
        params: list[Any] = [self.config.id]
        if method is not None:
            sql += " AND method = ?"
            params.append(method)
        with self._lock:
            records = self._conn.execute(sql + " ORDER BY rowid", params).fetchall()
        return [_row_from(r) for r in records]

    def get(self, method: str, task: str) -> TaskRow | None:
        sql = (
            f"SELECT {', '.join(_COLUMNS)} FROM agent_results "
            "WHERE config_id = ? AND method = ? AND task_id = ?"
        )
        with self._lock:
            record = self._conn.execute(sql, (self.config.id, method, task)).fetchone()
        return _row_from(record) if record is not None else None
