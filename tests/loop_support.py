"""Helpers shared by the tests of the refinement loop's questions."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import pytest
from conftest import inst, rel

from virf.api import LogicTutor
from virf.planner import ScriptedApprentice
from virf.planner.loop import LoopResult, Tutor, refine
from virf.planner.methods import get_method, run_method
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


# The apple-and-fridge task several test modules drive

FRIDGE_SCENE: dict[str, Any] = {
    "instances": [
        inst("Apple", "Apple_1"),
        inst("Fridge", "Fridge_1"),
        inst("CounterTop", "CounterTop_1"),
    ],
    "assertions": [
        rel("Apple_1", "isOn", "CounterTop_1"),
        rel("Fridge_1", "hasState", "ClosedState"),
    ],
}
LEAVES_OPEN = "find Apple_1\npick Apple_1\nfind Fridge_1\nopen Fridge_1\nput Fridge_1"
CLOSES = LEAVES_OPEN + "\nclose Fridge_1"
# The rule that names a fridge left open: the household's mechanism rule, and
# the paper's hand-written one.
FRIDGE_RULES = {"kitchen": "ColdStorageLeftOpenDanger", "paper": "FridgeLeftOpenDanger"}


@pytest.fixture(params=sorted(FRIDGE_RULES))
def fridge_tutor(
    request: pytest.FixtureRequest, tutor: LogicTutor, paper_tutor: LogicTutor
) -> tuple[LogicTutor, str]:
    """The tutor of one scenario and the rule it names for the open fridge."""
    return (paper_tutor if request.param == "paper" else tutor), FRIDGE_RULES[request.param]


def run_method_with(
    tutor: LogicTutor, name: str, replies: list[str], critic: list[str] | None = None, **kw: Any
) -> tuple[LoopResult, ScriptedApprentice]:
    apprentice = ScriptedApprentice(replies)
    result = run_method(
        get_method(name),
        "Put the apple in the fridge.",
        FRIDGE_SCENE,
        apprentice,
        kw.pop("verifier", tutor.verifier),
        lambda d: build_scene(d, tutor.tbox.vocabulary),
        tutor.tbox.vocabulary,
        critic=ScriptedApprentice(critic) if critic is not None else None,
        **kw,
    )
    return result, apprentice
