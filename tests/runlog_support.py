"""One logged model call, for the run-log tests of both databases."""

from __future__ import annotations

from virf.planner import (
    RunLog,
)

MESSAGES = [{"role": "user", "content": "Slice the apple."}]


def log_one(log: RunLog, task_id: str = "t1", reply: str | None = "slice Apple") -> int:
    return log.log_call(
        method="virf",
        task_id=task_id,
        iteration=1,
        ask=1,
        apprentice="scripted",
        model=None,
        messages=MESSAGES,
        reply=reply,
        ok=reply is not None,
        reason="" if reply is not None else "the reply was empty",
        prompt_tokens=3,
        completion_tokens=2,
        latency_ms=1.5,
        attempts=1,
    )
