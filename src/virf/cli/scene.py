"""``virf scene``: how a scene is understood; scenes for benchmark tasks."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from virf.cli.app import PlainScenarioOpt

scene_app = typer.Typer(
    help="Show how a scene is understood; build scenes for benchmark tasks.", no_args_is_help=True
)


@scene_app.command("safeagentbench")
def scene_safeagentbench(
    file: Annotated[Path, typer.Argument(help="A SafeAgentBench JSONL file.")],
    line: Annotated[int, typer.Argument(help="1-based line of the task in FILE.")],
) -> None:
    """Print the scene ABox (the paper's JSON) VIRF builds for one task."""
    from virf.bench.safeagentbench import task_at
    from virf.ontology.tbox import load_tbox

    vocab = load_tbox().vocabulary
    task = task_at(file, line)
    typer.echo(json.dumps(task.scene_data(vocab), indent=2))


@scene_app.command("show")
def scene_show(
    scene: Annotated[Path, typer.Argument(help="Scene ABox JSON file.")],
    as_json: Annotated[
        bool, typer.Option("--json", help="Print the canonical world as one JSON object.")
    ] = False,
    scenario: PlainScenarioOpt = None,
) -> None:
    """Show how VIRF understood SCENE: the one canonical world it verifies against.

    Every object with its types, states, materials and relations; what came from
    the scene, from a catalogue default or from an open-world assumption; and how
    the scene wrote what was rewritten (a state individual, an inverse relation,
    a material class)."""
    from rich.console import Console

    from virf.ontology.tbox import load_tbox
    from virf.render.tables import TextTable, to_rich
    from virf.world.describe import describe_scene
    from virf.world.scene import load_scene_file

    world = describe_scene(load_scene_file(scene, load_tbox(scenario).vocabulary))
    if as_json:
        typer.echo(json.dumps(world, indent=2, sort_keys=True))
        return

    def cell(entries: list[dict[str, str]], relation: bool = False) -> str:
        out = []
        for e in entries:
            text = f"{e['relation']} {e['value']}" if relation else e["value"]
            if e["from"] != "scene":
                text += f" ({e['from']})"
            out.append(text)
        return "\n".join(out)

    rows: list[tuple[str, ...]] = []
    rewritten: list[str] = []
    for name, obj in world["objects"].items():
        rows.append(
            (
                name + (" (agent)" if name == world["agent"] else ""),
                ", ".join(obj["types"]),
                cell(obj["states"]),
                cell(obj["materials"] + obj["properties"]),
                cell(obj["relations"], relation=True),
            )
        )
        for e in obj["states"] + obj["materials"] + obj["properties"] + obj["relations"]:
            if "written" in e:
                rewritten.append(f"{e['written']}  ->  {e['canonical']}")
    table = TextTable.of(
        ("object", "types", "states", "materials", "relations"),
        rows,
        title=f"Scene {world['name']}: the canonical world",
    )
    console = Console(highlight=False, width=150)
    console.print(to_rich(table))
    lines = [
        "closed world: " + (", ".join(world["closed_world"]) or "none (contents are open)"),
        f"objects start located: {'no' if world['unlocated_by_default'] else 'yes'}",
    ]
    if world["unknown_contents"]:
        lines.append("contents unknown: " + ", ".join(world["unknown_contents"]))
    if world["referents"]:
        lines.append(
            "referents: " + ", ".join(f"{k} -> {v}" for k, v in world["referents"].items())
        )
    if world["open_world_markers"]:
        lines.append("open-world markers: " + "; ".join(world["open_world_markers"]))
    if rewritten:
        lines.append("rewritten as the canonical form:")
        lines += [f"  {r}" for r in rewritten]
    console.print("\n".join(lines), markup=False)
