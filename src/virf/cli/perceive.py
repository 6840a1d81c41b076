"""``virf perceive``: camera images to a scene graph and a scene (the paper's VLM cascade)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer

from virf.cli.app import (
    ApiKeyEnvOpt,
    BaseUrlOpt,
    KbOpt,
    MaxTokensOpt,
    ScenarioOpt,
    SeedOpt,
    TemperatureOpt,
    check_writable,
    write_output,
)

VlmOpt = Annotated[
    str,
    typer.Option(
        "--vlm",
        help="Vision model: openai:MODEL (any OpenAI-compatible server that takes images) "
        "or replay:FILE (recorded replies).",
    ),
]
DetectionsOpt = Annotated[
    Path | None,
    typer.Option(
        "--detections",
        help="Hybrid baseline: object boxes from a detector (COCO JSON); the vision model "
        "then gives only attributes and relations.",
    ),
]
ThresholdOpt = Annotated[
    float,
    typer.Option(
        "--threshold",
        min=0.0,
        max=1.0,
        help="Confidence below which a reading is uncertain: a material becomes unknown, "
        "a state or relation an assumption the tutor asks about.",
    ),
]
OpenContentsOpt = Annotated[
    bool,
    typer.Option(
        "--open-contents",
        help="Never take what a surface holds as complete (by default it is, for a surface "
        "seen with confidence; a container's contents never are).",
    ),
]
BboxUnitsOpt = Annotated[
    str,
    typer.Option(
        "--bbox-units",
        help="How the model's boxes are measured: pixels (default), normalized (0-1) or "
        "per-mille (0-1000, as Gemini gives them).",
    ),
]
VlmTimeoutOpt = Annotated[
    float | None, typer.Option("--timeout", help="Seconds one model reply may take (default 120).")
]
LogOpt = Annotated[
    str | None,
    typer.Option(help="Run log of every model call: a SQLite file or a postgresql:// URL."),
]


def run_perception(
    images: list[Path],
    vlm: str,
    vocab: Any,
    *,
    log: str | None = None,
    run_log: Any = None,
    detections: Path | None,
    threshold: float,
    open_contents: bool,
    bbox_units: str,
    deadline: Any = None,
    **settings: Any,
) -> Any:
    """The cascade on ``images``, with a spinner on a terminal; shared by
    ``virf perceive`` and ``virf plan --images``.  The calls go to ``run_log``
    (left open) or to the log at ``log``."""
    from rich.console import Console
    from rich.markup import escape

    from virf.perception import perceive
    from virf.planner import RunLog, make_apprentice

    console = Console(stderr=True)
    own_log = RunLog(log) if log is not None and run_log is None else None
    run_log = run_log or own_log
    try:
        model = make_apprentice(vlm, run_log=run_log, **settings)
        with (
            model,
            console.status("perceiving", spinner="dots")
            if console.is_terminal
            else _Quiet() as status,
        ):
            return perceive(
                images,
                model,
                vocab,
                detections=detections,
                threshold=threshold,
                open_contents=open_contents,
                bbox_units=bbox_units,
                deadline=deadline,
                progress=lambda what: status.update(f"perceiving: {escape(what)}"),
            )
    finally:
        if own_log is not None:
            own_log.close()


class _Quiet:
    def __enter__(self) -> _Quiet:
        return self

    def __exit__(self, *_: object) -> None:
        return None

    def update(self, _: str) -> None:
        return None


def perceive(
    images: Annotated[list[Path], typer.Argument(help="Camera images of one scene (views).")],
    vlm: VlmOpt,
    out: Annotated[
        Path | None, typer.Option("--out", "-o", help="Write the scene (for virf verify) here.")
    ] = None,
    graph: Annotated[
        Path | None,
        typer.Option(help="Write the scene graph (every reading, its view and confidence) here."),
    ] = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print one JSON object: the scene graph and the scene.")
    ] = False,
    detections: DetectionsOpt = None,
    threshold: ThresholdOpt = 0.5,
    open_contents: OpenContentsOpt = False,
    bbox_units: BboxUnitsOpt = "pixels",
    base_url: BaseUrlOpt = None,
    api_key_env: ApiKeyEnvOpt = None,
    temperature: TemperatureOpt = None,
    seed: SeedOpt = None,
    max_tokens: MaxTokensOpt = None,
    timeout: VlmTimeoutOpt = None,
    log: LogOpt = None,
    scenario: ScenarioOpt = None,
    kb: KbOpt = None,
) -> None:
    """Turn camera images into a scene the tutor verifies (VLM cascade: objects, then
    each object's states and material, then relations; several views are fused).

    Exit 0 when a scene was made, 2 on bad input or an unreadable reply, 4 when
    the model cannot be reached.
    """
    from virf.ontology.tbox import load_tbox

    for path, option in ((out, "--out"), (graph, "--graph")):
        if path is not None:
            check_writable(path, option)  # before any model call, so nothing is half-done
    vocab = load_tbox(scenario, kb=kb).vocabulary
    result = run_perception(
        images,
        vlm,
        vocab,
        log=log,
        detections=detections,
        threshold=threshold,
        open_contents=open_contents,
        bbox_units=bbox_units,
        base_url=base_url,
        api_key_env=api_key_env,
        temperature=temperature,
        seed=seed,
        max_tokens=max_tokens,
        timeout_s=timeout,
    )
    scene_text = json.dumps(result.scene, indent=2, ensure_ascii=False) + "\n"
    graph_text = result.graph.model_dump_json(indent=2) + "\n"
    if out is not None:
        write_output(out, scene_text)
    if graph is not None:
        write_output(graph, graph_text)
    if as_json:
        typer.echo(
            json.dumps(
                {"graph": result.graph.model_dump(mode="json"), "scene": result.scene},
                ensure_ascii=False,
            )
        )
        return
    print_graph(result.graph)
    if out is not None:
        typer.echo(f"Scene written to {out}; check a plan with: virf verify {out} PLAN")
    elif graph is None:
        typer.echo("(use --out scene.json to save the scene, --graph to save the scene graph)")


def print_graph(graph: Any) -> None:
    from rich.console import Console
    from rich.table import Table
    from rich.text import Text

    def cells(*values: str) -> list[Text]:
        # Plain text: a model's label such as "mug [/]" is not markup.
        return [Text(v) for v in values]

    console = Console(highlight=False, width=120)
    views = ", ".join(f"{v.name} ({v.width}x{v.height}, boxes: {v.boxes})" for v in graph.views)
    console.print(f"Views: {views}; confidence threshold {graph.threshold:g}", markup=False)

    def conf(c: float | None) -> str:
        return "-" if c is None else f"{c:.2f}"

    several = len(graph.views) > 1

    def readings(items: Any) -> str:
        """Each value once, with the confidence each view gave it."""
        by_value: dict[str, list[str]] = {}
        for r in items:
            by_value.setdefault(r.value, []).append(
                f"{r.view} {conf(r.confidence)}" if several else conf(r.confidence)
            )
        return "; ".join(f"{v} ({', '.join(c)})" for v, c in by_value.items()) or "-"

    objects = Table(
        "object", "type (from the label)", "material", "states", "seen", title="Objects"
    )
    for o in graph.objects:
        if o.match.how == "name":
            how = "by name"
        elif o.match.how == "embedding":
            how = f"by meaning, similarity {o.match.score or 0:.2f}"
        else:
            how = "no type fits"
        objects.add_row(
            *cells(
                o.name,
                f"{o.type} ('{o.label}', {how})",
                readings(o.materials),
                readings(o.states),
                "; ".join(f"{s.view} {conf(s.confidence)}" for s in o.seen),
            )
        )
    console.print(objects)
    relations = Table("subject", "relation", "object", "confidence", title="Relations")
    said: dict[tuple[str, str, str], list[str]] = {}
    for r in graph.relations:
        said.setdefault((r.subject, r.relation, r.object), []).append(
            f"{conf(r.confidence)} ({r.view})" if several else conf(r.confidence)
        )
    for (subject, relation, obj), confidences in said.items():
        relations.add_row(*cells(subject, relation, obj, ", ".join(confidences)))
    console.print(relations)
    for title, lines in (("Disagreements", graph.disagreements), ("Notes", graph.notes)):
        if lines:
            console.print(f"{title}:", markup=False)
            for line in lines:
                console.print(f"  - {line}", markup=False)
