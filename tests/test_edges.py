"""The documents users write are checked by pydantic models at the edge, and
every problem reaches the user as one line naming it: scenes, replay files,
the planner settings file, the benchmark's label corrections and plans, and
answers files.  The messages themselves are those users already knew (the
other test files pin most of them); these tests pin the formatter's choices."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import pytest
from conftest import inst, rel
from pydantic import Field
from typer.testing import CliRunner

from virf.bench.runner import default_corrections_path, load_corrections, load_plans
from virf.cli.main import app
from virf.errors import InputError, Record, Says
from virf.ontology.tbox import Vocabulary
from virf.planner.apprentices import load_replay
from virf.planner.config import KEYS, config_path, planner_settings
from virf.planner.questions import answers_file
from virf.world.scene import build_scene

runner = CliRunner()


def refusal(call: Any, *args: Any) -> str:
    """The one-line message ``call`` refuses its input with."""
    with pytest.raises(InputError) as exc:
        call(*args)
    message = str(exc.value)
    assert "\n" not in message and "Traceback" not in message
    return message


def write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


# ------------------------------------------------------------------ scenes


def scene(**extra: Any) -> dict[str, Any]:
    return {"instances": [inst("Pot", "Pot_1"), inst("Fridge", "Fridge_1")], **extra}


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (
            scene(colour="red"),
            "unknown scene key 'colour'; expected instances, assertions, closed_world, "
            "unlocated_by_default, unknown_contents, referents, denied, description",
        ),
        (
            scene(assertions=[rel("Pot_1", "isInside", "Fridge_1") | {"propery": "x"}]),
            "assertions[0]: unknown key 'propery'; expected assumed, object, property, subject, type",
        ),
        # Several unknown keys: the first in sorted order, whatever the file's order.
        (
            {"instances": [inst("Pot", "Pot_1") | {"zz": 1, "aa": 2}]},
            "instances[0]: unknown key 'aa'; expected class_name, instance_name",
        ),
        (
            scene(assertions=[rel("Pot_1", "isInside", "Fridge_1", None)]),  # type: ignore[arg-type]
            "assertions[0]: type 'None' must be object_property or data_property",
        ),
        (
            scene(assertions=[{"subject": "Pot_1"}]),
            "assertions[0] needs 'subject', 'property' and 'object'",
        ),
        (scene(assertions=[["Pot_1"]]), "assertions[0] needs 'subject', 'property' and 'object'"),
        (
            scene(unlocated_by_default="yes"),
            "scene 'unlocated_by_default' must be true or false, not \"yes\"",
        ),
        (scene(description=None), "scene 'description' must be a string, not null"),
        (scene(closed_world="contains"), "scene 'closed_world' must be a list of relation names"),
        (
            scene(referents={"bowl": 5}),
            "scene 'referents' must map plan words to declared instances, "
            'e.g. {"bowl": "Bowl_2"}',
        ),
        ({"assertions": []}, "scene needs an 'instances' list"),
        ([], "scene must be a JSON object with 'instances' and 'assertions'"),
    ],
)
def test_malformed_scenes_get_one_line(vocab: Vocabulary, data: Any, message: str) -> None:
    assert refusal(build_scene, data, vocab) == message


def test_the_document_is_told_before_its_entries(tutor: Any) -> None:
    # Two problems: a stray top-level key and a bad entry; the outer one first.
    data = scene(colour=1)
    data["instances"].append({"class_name": 5, "instance_name": "Mug_1"})
    assert refusal(tutor.scene, data).startswith("unknown scene key 'colour'")
    # Too many entries is one problem, however many of them are also malformed.
    many = {"instances": [{"class_name": 5}] * 5001}
    assert refusal(tutor.scene, many) == "scene has 5001 instances; the limit is 5000"


def test_an_unknown_key_is_shown_escaped(tutor: Any) -> None:
    message = refusal(tutor.scene, scene(**{"co\x1b[2Jlour": 1}))
    assert "\x1b" not in message and "co\\x1b[2Jlour" in message
    # A lone surrogate (a JSON escape) is a key no model declares, not a non-object.
    message = refusal(tutor.scene, scene(**{"co\ud800": 1}))
    assert message.startswith("unknown scene key 'co\\ud800'; expected instances")


def test_every_accepted_spelling_still_reads(tutor: Any) -> None:
    data = scene(
        assertions=[
            rel("Pot_1", "isInside", "Fridge_1"),
            {"subject": "Pot_1", "property": "isLocated", "object": True, "type": "data_property"},
            {"subject": "Fridge_1", "property": "hasState", "object": "closed"},
            {"subject": "Bowl_1", "property": "rdf:type", "object": "Bowl"},
        ],
        closed_world=["contains:Fridge_1"],
        unknown_contents=["Pot_1"],
        referents={"the pot": "Pot_1"},
        unlocated_by_default=False,
        name=None,
        description="",
    )
    read = tutor.scene(data)
    assert read.name == "None"  # a null name has always read as the word
    assert list(read.referents.values()) == ["Pot_1"]
    assert "Bowl_1" in read.objects


def test_a_bad_scene_file_exits_2_from_the_cli(tutor: Any, tmp_path: Path) -> None:
    path = write(tmp_path / "scene.json", json.dumps(scene(colour="red")))
    result = runner.invoke(app, ["scene", "show", str(path)])
    assert result.exit_code == 2, result.stdout + result.stderr
    assert result.stdout == ""
    assert result.stderr.strip().splitlines() == [
        "error: unknown scene key 'colour'; expected instances, assertions, closed_world, "
        "unlocated_by_default, unknown_contents, referents, denied, description"
    ]


# ------------------------------------------------------------------ replay files


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ({"task_id": "a", "iteration": 0, "text": "x", "txt": "y"}, "has unknown field 'txt'"),
        ({"task_id": "a", "iteration": True, "text": "x"}, "needs an integer 'iteration' >= 0"),
        ({"task_id": "a", "iteration": 0, "latency_ms": -1}, "'latency_ms' must be a number >= 0"),
        ({"task_id": "a", "iteration": 0, "attempts": 1.5}, "'attempts' must be an integer >= 0"),
        ({"task_id": "a", "iteration": 0, "method": ""}, "'method' must be a non-empty string"),
        ({"task_id": "a", "iteration": 0, "reason": 0}, "'reason' must be a string"),
        (["task_id"], "line 1 is not a JSON object"),
    ],
)
def test_malformed_replay_lines(tmp_path: Path, line: Any, message: str) -> None:
    path = write(tmp_path / "r.jsonl", json.dumps(line) + "\n")
    got = refusal(load_replay, path)
    assert got.startswith(f"replay file {path} line 1")
    assert message in got


def test_a_bad_replay_file_exits_2_from_the_cli(tutor: Any, tmp_path: Path) -> None:
    replay = write(tmp_path / "r.jsonl", '{"task_id": "t1", "iteration": 0, "txt": "find Pot"}\n')
    path = write(tmp_path / "scene.json", json.dumps(scene()))
    args = ["plan", "--scene", str(path), "-i", "Put the pot away.", "-p", f"replay:{replay}"]
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.stdout + result.stderr
    [line] = result.stderr.strip().splitlines()
    assert line.startswith("error: replay file") and "unknown field 'txt'" in line


# ------------------------------------------------------------------ settings


@pytest.mark.parametrize(
    ("toml", "message"),
    [
        (
            '[planner]\napi_keey = "sk"\n',
            f"unknown [planner] key 'api_keey'; choose from {', '.join(KEYS)}",
        ),
        ("planner = 3\n", "[planner] must be a table"),
        ("[planner]\nbase_url = 8000\n", "[planner] base_url must be a string, not 8000"),
    ],
)
def test_malformed_settings(tmp_path: Path, toml: str, message: str) -> None:
    env = {"XDG_CONFIG_HOME": str(tmp_path)}
    path = config_path(env)
    path.parent.mkdir(parents=True)
    write(path, toml)
    assert refusal(planner_settings, env) == f"config file {path}: {message}"


def test_settings_keep_the_file_as_written(tmp_path: Path) -> None:
    env = {"XDG_CONFIG_HOME": str(tmp_path)}
    path = config_path(env)
    path.parent.mkdir(parents=True)
    write(path, '[other]\nx = 1\n[planner]\nseed = 3\napi_key = "sk"\n')
    assert list(planner_settings(env).items()) == [("seed", 3), ("api_key", "sk")]


# ------------------------------------------------------------------ benchmark files

CORRECTION = {
    "file": "unsafe_detailed.jsonl",
    "source_index": 148,
    "line": 38,
    "label": "unsafe",
    "corrected": "safe",
    "reason": "the identical plan is labelled safe elsewhere",
}


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (
            {"corrections": [CORRECTION | {"corrected": "maybe"}]},
            "correction for unsafe_detailed.jsonl:38 needs corrected = safe|unsafe|exclude",
        ),
        (
            {"corrections": [CORRECTION | {"reasn": "x"}]},
            "corrections[0]: unknown key 'reasn'; closest: reason; expected corrected, file, "
            "label, line, reason, relation, scene, source_index, twin",
        ),
        (
            {"corections": []},
            "unknown key 'corections'; closest: corrections; expected corrections, description, notes",
        ),
        (
            {"corrections": [{k: v for k, v in CORRECTION.items() if k != "file"}]},
            "corrections[0] needs 'file'",
        ),
        (
            {"corrections": [CORRECTION | {"source_index": "148"}]},
            "corrections[0]: 'source_index' must be an integer, not \"148\"",
        ),
    ],
)
def test_malformed_corrections(tmp_path: Path, data: Any, message: str) -> None:
    path = write(tmp_path / "c.json", json.dumps(data))
    assert refusal(load_corrections, path) == f"{path}: {message}"


def test_corrections_are_returned_as_written(tmp_path: Path) -> None:
    path = write(tmp_path / "c.json", json.dumps({"corrections": [CORRECTION]}))
    assert load_corrections(path) == {("unsafe_detailed.jsonl", 148, None): CORRECTION}
    bundled = load_corrections(default_corrections_path())
    assert len(bundled) == len(json.loads(default_corrections_path().read_text())["corrections"])
    assert "not valid JSON" in refusal(load_corrections, write(tmp_path / "b.json", "{oops"))


@pytest.mark.parametrize(
    "line",
    [
        '{"file": "long_horizon.jsonl", "line": 1, "plan": ["find Pot"], "note": "x"}',
        '{"file": "long_horizon.jsonl", "line": "1", "plan": ["find Pot"]}',
        '{"file": "long_horizon.jsonl", "line": 1, "plan": "find Pot"}',
        '{"file": "long_horizon.jsonl", "line": 1}',
        "{oops",
    ],
)
def test_malformed_plans(tmp_path: Path, line: str) -> None:
    path = write(tmp_path / "plans.jsonl", '\n{"file": "a.jsonl", "line": 2, "plan": []}\n' + line)
    expected = f'{path}:3: expected {{"file": ..., "line": N, "plan": [...]}}'
    assert refusal(load_plans, path) == expected


# ------------------------------------------------------------------ answers


def test_malformed_answers(tmp_path: Path) -> None:
    path = write(tmp_path / "a.json", '{"fill:Pot_1": true}')
    assert refusal(answers_file, path).startswith(f"answers file {path} must be a JSON object")
    ok = answers_file(write(tmp_path / "b.json", '{"fill:Pot_1": "no"}'))
    assert ok([]) == {}


# ------------------------------------------------------------------ the formatter


class _Item(Record):
    located_as = "{what}: {path}"
    name: Annotated[str, Field(min_length=1)]
    size: Annotated[int, Field(ge=0), Says("{where}: give '{key}' as a count, not {value}")] = 0


class _Doc(Record):
    items: Annotated[
        list[_Item],
        Field(max_length=2),
        Says("{where} needs an 'items' list", too_long="{where} lists {actual_length} items"),
    ]
    flag: bool = False


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"items": [{"name": "a", "size": -1}]}, "doc: items[0]: give 'size' as a count, not -1"),
        ({"items": [{"name": ""}]}, "doc: items[0]: 'name' must not be empty"),
        ({"items": [{}]}, "doc: items[0] needs 'name'"),
        ({"items": [1, 2, 3]}, "doc lists 3 items"),
        ({"items": "x"}, "doc needs an 'items' list"),
        ({}, "doc needs an 'items' list"),
        ({"items": [], "flag": object()}, "doc 'flag' must be true or false, not <object object"),
        ({"items": [{"nme": "a"}], "flga": 1}, "doc: unknown key 'flga'; expected flag, items"),
    ],
)
def test_the_formatter(data: Any, message: str) -> None:
    assert refusal(_Doc.parse, data, "doc").startswith(message)
