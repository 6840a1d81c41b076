"""Helpers shared by the tests of the refinement loop's questions."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

from virf.api import LogicTutor
from virf.planner import ScriptedApprentice
from virf.planner.loop import LoopResult, Tutor, refine
from virf.schema import Question
from virf.world.scene import Scene, build_scene


class Recorder:
    """An answer policy that records what it was asked."""

    def __init__(self, answers: Mapping[str, str]) -> None:
        self.answers = dict(answers)
        self.asked: list[list[str]] = []

    def __call__(self, questions: Sequence[Question]) -> dict[str, str]:
        self.asked.append([q.key for q in questions])
        return {q.key: self.answers[q.key] for q in questions if q.key in self.answers}


def run_loop(
    tutor: LogicTutor,
    scene: Mapping[str, Any],
    replies: list[str],
    answer: Callable[[Sequence[Question]], dict[str, str]],
    *,
    instruction: str = "Do the task.",
    verifier: Tutor | None = None,
    build: Callable[[Mapping[str, Any]], Scene] | None = None,
    max_iter: int = 2,
) -> tuple[LoopResult, ScriptedApprentice]:
    """The loop over ``scene`` with scripted ``replies``; ``verifier`` stands in
    for the tutor's own, ``build`` for the plain scene reader."""
    vocab = tutor.tbox.vocabulary
    apprentice = ScriptedApprentice(replies)
    result = refine(
        instruction,
        scene,
        apprentice,
        verifier or tutor.verifier,
        build or (lambda d: build_scene(d, vocab)),
        vocab,
        answer=answer,
        max_iter=max_iter,
    )
    return result, apprentice


def statuses(result: LoopResult) -> list[str | None]:
    return [t.status for t in result.transcript if t.kind == "report"]
