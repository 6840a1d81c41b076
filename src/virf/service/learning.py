"""``POST /v1/learn``: answers about open-world objects, kept for later scenes.

The body is what ``/v1/apply-answers`` takes, plus who answered:
``{scene, plan, answers, who, scenario?, engine?}``.  The scene is the one
the questions were asked about, before any answer.  The service settles the
questions with the answers as ``virf verify --answers`` does, then stores
what they confirm about each class of the scene's open-world objects as a
candidate in its knowledge workspace (``virf serve --workspace DIR``), with
the answers as evidence, and checks and previews it
(:mod:`virf.authoring.learn`).  Nothing changes a verdict until a person
accepts the candidate on the review page (``/review/``).

A service without a workspace answers 409.  The service verifies with what
was accepted when its ``--kb`` is the same workspace (``applies_here``).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Final

from fastapi import FastAPI
from fastapi.responses import JSONResponse
from pydantic import Field

from virf.bundled import bundled_examples
from virf.errors import InputError, clip, closest
from virf.service.app import Tutors
from virf.service.pages import _Body
from virf.web import problem

if TYPE_CHECKING:
    from virf.authoring.learn import Outcome
    from virf.authoring.workspace import Workspace

MAX_WHO: Final = 100
NO_WORKSPACE: Final = (
    "this service keeps no knowledge workspace, so it cannot learn; start it with "
    "'virf serve --workspace DIR' (and '--kb DIR' to verify with what is accepted)"
)


class LearnRequest(_Body):
    scene: dict[str, Any]
    plan: list[str] | str
    answers: dict[str, str]
    who: Annotated[str, Field(max_length=MAX_WHO)]
    scenario: str | None = None
    engine: str | None = None


def _candidate(o: Outcome) -> dict[str, Any]:
    items = o.check.items if o.check is not None else ()
    preview = o.preview
    return {
        "id": o.id,
        "class_name": o.lesson.name,
        "axiom": o.lesson.axiom,
        "axioms": list(o.lesson.axioms),
        "answers": [a.model_dump(mode="json") for a in o.lesson.answers],
        "passed": o.check.passed if o.check is not None else None,
        "problems": [i.message for i in items if i.severity == "error"],
        "warnings": [i.message for i in items if i.severity == "warning" and not i.ok],
        "changes": (
            [c.model_dump(mode="json") for c in preview.changes] if preview is not None else []
        ),
        "kb_test": preview.kb_test if preview is not None else None,
    }


def add_learning(app: FastAPI, tutors: Tutors, workspace: Workspace | None) -> None:
    """``POST /v1/learn`` over ``workspace`` (409 without one)."""

    @app.post("/v1/learn", response_model=None)
    def learn(body: LearnRequest) -> dict[str, Any] | JSONResponse:
        """Keep what answers confirm about open-world objects as candidate
        classes in the service's workspace, for a person to accept."""
        from virf.authoring import learn as learning
        from virf.planner.questions import settle

        if workspace is None:
            return problem(409, NO_WORKSPACE)
        who = " ".join(body.who.split())
        if not who:
            raise InputError("'who' must name who answered (it is kept as evidence)")
        tutor, lock, _, steps = tutors.prepare(body.scene, body.plan, body.scenario, body.engine)
        vocab = tutor.tbox.vocabulary

        def verify(data: Any) -> Any:
            scene = tutor.scene(dict(data))
            with lock:
                return tutor.verifier.verify(scene, steps)

        settled = settle(body.scene, verify, body.answers, vocab)
        for key in settled.unused(body.answers):
            near = closest(key, sorted(settled.asked))
            listed = f"; closest asked: {', '.join(near)}" if near else ""
            raise InputError(f"no question '{clip(key)}' for this scene and plan{listed}")
        name = body.scene.get("name")
        source = learning.Source(
            name if isinstance(name, str) and name.strip() else "posted-scene",
            body.scene,
            tuple(s.text for s in steps),
        )
        outcomes, skipped = learning.learn(
            workspace, source, settled.answered, who, examples=bundled_examples()
        )
        here = tutors.kb is not None and Path(tutors.kb).resolve() == workspace.root.resolve()
        return {
            "status": settled.report.status,
            "candidates": [_candidate(o) for o in outcomes],
            "skipped": skipped,
            "review": "/review/",
            "applies_here": here,
        }
