"""Planner specs: parsed once, checked, spelled back canonically, and built
through the registry of planner kinds."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from virf.errors import InputError
from virf.planner import (
    Apprentice,
    PlannerKind,
    PlannerSpec,
    RunLog,
    ScriptedApprentice,
    make_apprentice,
)
from virf.planner import spec as spec_module
from virf.planner.spec import planner_kind, planner_kinds, register, spec_forms

FORMS = "openai:MODEL, local:NAME (or local:PATH.gguf), replay:FILE or scripted"


@pytest.mark.parametrize(
    ("typed", "kind", "argument", "canonical"),
    [
        ("openai:gpt-4o-mini", "openai", "gpt-4o-mini", "openai:gpt-4o-mini"),
        ("  openai:  gpt-4o-mini ", "openai", "gpt-4o-mini", "openai:gpt-4o-mini"),
        ("local:smollm2-135m", "local", "smollm2-135m", "local:smollm2-135m"),
        ("local:~/models/m.gguf", "local", "~/models/m.gguf", "local:~/models/m.gguf"),
        ("replay:runs/virf.jsonl", "replay", "runs/virf.jsonl", "replay:runs/virf.jsonl"),
        # Only the first colon separates: a path or a model may hold more.
        ("replay:C:/runs/a.jsonl", "replay", "C:/runs/a.jsonl", "replay:C:/runs/a.jsonl"),
        ("openai:org/model:tag", "openai", "org/model:tag", "openai:org/model:tag"),
        ("scripted", "scripted", None, "scripted"),
        (" scripted ", "scripted", None, "scripted"),
    ],
)
def test_specs_parse_into_kind_and_argument(
    typed: str, kind: str, argument: str | None, canonical: str
) -> None:
    spec = PlannerSpec.parse(typed)
    assert (spec.kind, spec.argument) == (kind, argument)
    assert str(spec) == canonical
    assert PlannerSpec.parse(str(spec)) == spec
    assert PlannerSpec.parse(spec) is spec


@given(
    kind=st.sampled_from(["openai", "local", "replay"]),
    argument=st.text(min_size=1, max_size=40).filter(lambda t: t.strip() == t and t),
)
def test_the_canonical_spelling_reads_back_to_the_same_spec(kind: str, argument: str) -> None:
    spec = PlannerSpec(kind, argument)
    assert PlannerSpec.parse(str(spec)) == spec
    assert PlannerSpec.parse(f" {kind}: {argument} ") == spec


def test_a_spec_is_immutable_and_checked_however_it_is_made() -> None:
    spec = PlannerSpec("openai", " gpt-4o ")
    assert spec.argument == "gpt-4o" and str(spec) == "openai:gpt-4o"
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.kind = "local"  # type: ignore[misc]
    with pytest.raises(InputError, match=r"^unknown planner 'nope'; choose "):
        PlannerSpec("nope")
    with pytest.raises(InputError, match=r"^no replay file: use replay:FILE"):
        PlannerSpec("replay")
    assert hash(spec) == hash(PlannerSpec.parse("openai:gpt-4o"))


@pytest.mark.parametrize(
    ("typed", "message"),
    [
        ("gpt-4o", f"unknown planner 'gpt-4o'; choose {FORMS}"),
        ("", f"unknown planner ''; choose {FORMS}"),
        ("opnai:gpt-4o", f"unknown planner 'opnai:gpt-4o'; choose {FORMS} (did you mean openai:gpt-4o?)"),
        ("OpenAI:gpt-4o", f"unknown planner 'OpenAI:gpt-4o'; choose {FORMS} (did you mean openai:gpt-4o?)"),
        ("replays:r.jsonl", f"unknown planner 'replays:r.jsonl'; choose {FORMS} (did you mean replay:r.jsonl?)"),
        ("loca", f"unknown planner 'loca'; choose {FORMS} (did you mean local:NAME?)"),
        ("scripted:x", f"unknown planner 'scripted:x'; choose {FORMS} (did you mean scripted?)"),
        ("scripted:", f"unknown planner 'scripted:'; choose {FORMS} (did you mean scripted?)"),
        ("scriptd", f"unknown planner 'scriptd'; choose {FORMS} (did you mean scripted?)"),
        ("openai", "no model name: use openai:MODEL, e.g. openai:gpt-4o-mini"),
        ("openai:  ", "no model name: use openai:MODEL, e.g. openai:gpt-4o-mini"),
        ("local:", "no model: use local:smollm2-135m or local:PATH.gguf"),
        ("replay", "no replay file: use replay:FILE, e.g. replay:runs/virf.jsonl"),
    ],
)  # fmt: skip
def test_bad_specs_are_one_line_errors_naming_the_valid_forms(typed: str, message: str) -> None:
    with pytest.raises(InputError) as exc:
        PlannerSpec.parse(typed)
    assert str(exc.value) == message


def test_an_unknown_spec_is_printed_safely() -> None:
    with pytest.raises(InputError) as exc:
        PlannerSpec.parse("evil\x1b[2J:" + "x" * 200)
    text = str(exc.value)
    assert "\x1b" not in text and "\n" not in text and "..." in text


def test_what_a_spec_means_is_asked_of_its_kind(tmp_path: Path) -> None:
    online = PlannerSpec.parse("openai:m")
    assert online.over_http and online.sampling and online.source_file() is None
    packaged = PlannerSpec.parse("local:smollm2-135m")
    assert not packaged.over_http and packaged.sampling and packaged.source_file() is None
    weights = PlannerSpec.parse("local:~/m.GGUF")
    assert weights.source_file() == Path("~/m.GGUF").expanduser()
    replay = PlannerSpec.parse(f"replay:{tmp_path / 'r.jsonl'}")
    assert not replay.over_http and not replay.sampling
    assert replay.source_file() == tmp_path / "r.jsonl"
    scripted = PlannerSpec.parse("scripted")
    assert not scripted.over_http and scripted.source_file() is None
    assert planner_kinds() == ["openai", "local", "replay", "scripted"]
    assert spec_forms() == FORMS
    with pytest.raises(
        InputError, match=r"^unknown planner 'lokal'; .* \(did you mean local:NAME\?\)$"
    ):
        planner_kind("lokal")


def test_make_apprentice_takes_a_parsed_spec() -> None:
    app = make_apprentice(PlannerSpec.parse("scripted"), replies=["find Apple"])
    assert isinstance(app, ScriptedApprentice) and app.label == "scripted"


def test_a_registered_kind_is_parsed_listed_and_built(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(spec_module, "_REGISTRY", {})
    built: list[tuple[str, dict[str, Any]]] = []

    def echo(
        spec: PlannerSpec,
        settings: Mapping[str, Any],
        *,
        run_log: RunLog | None,
        environ: Mapping[str, str] | None,
    ) -> Apprentice:
        built.append((str(spec), dict(settings)))
        return ScriptedApprentice([spec.argument or ""], run_log=run_log)

    register(PlannerKind("echo", "TEXT", "echo:TEXT", "no text: use echo:TEXT", echo))
    assert planner_kinds() == ["openai", "local", "replay", "scripted", "echo"]
    assert spec_forms().endswith("replay:FILE, scripted or echo:TEXT")
    app = make_apprentice(" echo: hello ", temperature=0.5)
    assert built == [("echo:hello", {"temperature": 0.5})]
    assert isinstance(app, ScriptedApprentice) and app.replies == ["hello"]
    with pytest.raises(InputError, match=r"^no text: use echo:TEXT$"):
        PlannerSpec.parse("echo")
    with pytest.raises(InputError, match=r"\(did you mean echo:hi\?\)$"):
        PlannerSpec.parse("ecoh:hi")
    with pytest.raises(ValueError, match="without ':'"):
        PlannerKind("a:b", None, "a:b", "", echo)
