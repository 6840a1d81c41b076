"""The service's web page at ``/`` and the small JSON endpoints only it needs.

The page (``static/``: vanilla JS, no build step, nothing from the internet)
verifies a scene and plan through ``POST /v1/verify`` and reads the rules from
``GET /v1/rules``; what the report alone cannot show comes from these:

* ``GET /v1/examples``: the bundled examples, ``[{"name", "description"}]``
  (a checkout's ``examples/``, or the copy an installed wheel carries);
* ``GET /v1/examples/{name}``: one of them, ``{"name", "description",
  "scene", "plan"}`` (the scene as JSON, the plan file's text);
* ``POST /v1/state`` ``{scene, plan, step, scenario?, engine?}``: the facts
  the reasoner sees at state ``step`` of the simulation (0 is the scene
  before the plan, k the state after action k, with action k+1's
  individual), each ``{subject, predicate, object, kind, provenance}`` in the
  report's triple notation, so triggering facts match them by equality;
* ``POST /v1/apply-answers`` ``{scene, plan, answers, scenario?, engine?}``: the
  scene with the answers to the report's questions written into it (the
  same code ``virf plan`` applies answers with), which questions they
  settled, and the scene's open-world objects (``open_world``: instance ->
  the class as written), whose answers ``POST /v1/learn`` can keep; the page
  then verifies the new scene.

All are under ``/v1/``, so the service's API key guards them as it guards
verification.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Final

from fastapi import FastAPI
from fastapi.responses import FileResponse, JSONResponse
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, ConfigDict, model_validator
from pydantic_core import PydanticCustomError

from virf.bundled import bundled_examples
from virf.errors import InputError, clip, closest, read_input_file, read_json_file
from virf.planner.questions import apply_answers
from virf.service.app import Tutors
from virf.web import problem

STATIC_DIR: Final = Path(__file__).resolve().parent / "static"


class _Body(BaseModel):
    """A request body with a one-line error naming an unknown key and the
    keys this endpoint takes (the app's own message lists /v1/verify's)."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data: Any) -> Any:
        if isinstance(data, dict):
            unknown = sorted(set(data) - set(cls.model_fields))
            if unknown:
                raise PydanticCustomError(
                    "unknown_key",
                    "unknown key '{key}'; expected {expected}",
                    {"key": clip(str(unknown[0])), "expected": ", ".join(cls.model_fields)},
                )
        return data


class StateRequest(_Body):
    scene: dict[str, Any]
    plan: list[str] | str
    step: int
    scenario: str | None = None
    engine: str | None = None


class AnswersRequest(_Body):
    scene: dict[str, Any]
    plan: list[str] | str
    answers: dict[str, str]
    scenario: str | None = None
    engine: str | None = None


def _example_names(folder: Path | None) -> list[str]:
    if folder is None or not folder.is_dir():
        return []
    return sorted(
        p.name
        for p in folder.iterdir()
        if (p / "scene.json").is_file() and (p / "plan.txt").is_file()
    )


def _description(scene: object) -> str:
    text = scene.get("description") if isinstance(scene, dict) else None
    return text if isinstance(text, str) else ""


def add_pages(app: FastAPI, tutors: Tutors, *, examples: Path | None = None) -> None:
    """Serve the page at ``/`` and its endpoints; ``examples`` defaults to the
    bundled examples (:func:`virf.bundled.bundled_examples`)."""
    folder = examples if examples is not None else bundled_examples()

    def read_example(name: str) -> dict[str, Any] | JSONResponse:
        names = _example_names(folder)
        if name not in names or folder is None:
            near = closest(name, names) or names[:8]
            listed = f"; choose from {', '.join(near)}" if near else "; this server has none"
            return problem(404, f"no example '{clip(name)}'{listed}")
        case = folder / name
        # Read as the CLI reads them: strict JSON, the same limits.
        scene = read_json_file(case / "scene.json", f"example '{name}' scene")
        plan = read_input_file(case / "plan.txt", f"example '{name}' plan")
        return {"name": name, "description": _description(scene), "scene": scene, "plan": plan}

    @app.get("/", include_in_schema=False)
    def page() -> FileResponse:
        return FileResponse(STATIC_DIR / "index.html", media_type="text/html")

    @app.get("/v1/examples")
    def examples_list() -> list[dict[str, str]]:
        """The bundled examples (``examples/`` of a checkout, or the installed copy)."""
        out = []
        for name in _example_names(folder):
            assert folder is not None
            try:
                scene = read_json_file(folder / name / "scene.json", "example scene")
            except InputError:
                scene = None  # listed anyway: opening it names the problem
            out.append({"name": name, "description": _description(scene)})
        return out

    @app.get("/v1/examples/{name}", response_model=None)
    def example(name: str) -> dict[str, Any] | JSONResponse:
        """One example: its scene (JSON) and its plan file's text."""
        return read_example(name)

    @app.post("/v1/state")
    def state(body: StateRequest) -> dict[str, Any]:
        """The facts of the simulated state ``step`` (0: the scene before the plan)."""
        tutor, lock, scene, steps = tutors.prepare(
            body.scene, body.plan, body.scenario, body.engine
        )
        with lock:
            snapshots = tutor.verifier.snapshots(scene, steps)
        last = len(snapshots) - 1
        if not 0 <= body.step <= last:
            raise InputError(
                f"step {body.step}: the simulation has states 0 to {last} "
                "(0 is the scene before the plan)"
            )
        facts = []
        for fact, provenance in sorted(snapshots[body.step].items()):
            t = fact.triple()
            facts.append(
                {
                    "subject": t.subject,
                    "predicate": t.predicate,
                    "object": t.object,
                    "kind": str(fact.kind),
                    "provenance": str(provenance),
                }
            )
        return {
            "step": body.step,
            "states": len(snapshots),
            "action": steps[body.step].text if body.step < len(steps) else None,
            "facts": facts,
        }

    @app.post("/v1/apply-answers")
    def answers(body: AnswersRequest) -> dict[str, Any]:
        """The scene with answers to the report's questions applied, as ``virf plan`` does."""
        tutor, lock, scene, steps = tutors.prepare(
            body.scene, body.plan, body.scenario, body.engine
        )
        with lock:
            report = tutor.verifier.verify(scene, steps)
        keys = [q.key for q in report.questions]
        for key in body.answers:
            if key not in keys:
                near = closest(key, keys)
                if near:
                    listed = f"; closest open questions: {', '.join(near)}"
                elif keys:
                    listed = f"; open questions: {', '.join(keys[:8])}"
                else:
                    listed = "; none is open"
                raise InputError(f"no question '{clip(key)}' for this scene and plan{listed}")
        update = apply_answers(body.scene, report.questions, body.answers, tutor.tbox.vocabulary)
        return {
            "scene": update.scene,
            "applied": list(update.applied),
            "unsettled": list(update.unsettled),
            # The scene's objects of classes the knowledge base lacks (instance
            # -> the class as written): answers about them can be learned.
            "open_world": dict(scene.open_world),
        }

    app.mount("/assets", StaticFiles(directory=STATIC_DIR), name="assets")
