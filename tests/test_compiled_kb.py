"""The compiled knowledge artifact: rebuilt from the modules it is the same,
it loads without Java, and a stale one is never used."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import replace
from functools import cache
from pathlib import Path
from types import MappingProxyType

import pytest

import virf.ontology.tbox as tbox_module
from virf.ontology import artifact as kba
from virf.ontology import compile as kbc
from virf.ontology.owlapi import OwlModules
from virf.ontology.tbox import load_tbox, ontology_dir, scenario_names

ROOT = Path(__file__).resolve().parent.parent
WALKTHROUGH = ROOT / "examples" / "walkthrough"


def test_every_artifact_was_compiled_from_the_modules_as_they_are() -> None:
    assert kbc.stale_artifacts() == [], "run 'make kb' and commit src/virf/ontology/compiled"


@cache
def _rebuilt(scenario: str) -> kba.CompiledKB:
    return kbc.compile_kb(OwlModules(scenario, ontology_dir()), kbc.source_digest())


@pytest.mark.parametrize("scenario", scenario_names())
def test_rebuilding_an_artifact_with_the_jvm_gives_the_same_bytes(scenario: str) -> None:
    rebuilt = kba.to_json(_rebuilt(scenario))
    # Through the index: a scenario that shares another's file gets its own
    # name and module back.
    shipped = kba.to_json(kbc.read_artifact(scenario))
    assert rebuilt == shipped, f"run 'make kb': the {scenario} artifact is out of date"


def test_the_compiled_folder_holds_exactly_what_make_kb_writes() -> None:
    files = kbc.artifact_files([_rebuilt(s) for s in scenario_names()])
    shipped = {p.name: p.read_text(encoding="utf-8") for p in kbc.artifact_dir().glob("*.json")}
    assert sorted(shipped) == sorted(files), "run 'make kb' and commit src/virf/ontology/compiled"
    for name, text in files.items():
        assert shipped[name] == text, f"run 'make kb': {name} is out of date"


ROOMS = ("bathroom", "bedroom", "kitchen", "living-room")


def test_rooms_that_compile_to_the_same_knowledge_share_one_artifact() -> None:
    # Each room imports the same rules; only its own module differs.
    assert {kbc.artifact_path(room).name for room in ROOMS} == {"kitchen.json"}
    index = json.loads(kbc.index_path().read_text(encoding="utf-8"))["scenarios"]
    assert sorted(index) == scenario_names()
    named = {entry["artifact"] for entry in index.values()}
    on_disk = {p.name for p in kbc.artifact_dir().glob("*.json")} - {kbc.INDEX}
    assert named == on_disk, "every artifact file is some scenario's, and only those"
    forms = [kbc.shared_form(kba.from_json((kbc.artifact_dir() / n).read_text())) for n in named]
    assert len(set(forms)) == len(forms), "two files hold the same knowledge"


@pytest.mark.parametrize("scenario", scenario_names())
def test_every_scenario_name_loads_as_itself(scenario: str) -> None:
    tbox = tbox_module._load.__wrapped__(scenario, (), "", None)
    assert tbox.source == "artifact" and tbox.scenario == scenario
    own = [m for m in tbox.module_stats if m.name.startswith("scenario-")]
    assert f"scenario-{scenario}" in {m.name for m in own}
    assert all(m.iri.endswith("/" + m.name) for m in tbox.module_stats)


def test_scenarios_share_a_file_only_when_their_knowledge_is_the_same() -> None:
    kitchen = kbc.read_artifact("kitchen")
    [own] = [m for m in kitchen.module_stats if m.name == "scenario-kitchen"]
    attic = replace(own, name="scenario-attic", iri=own.iri.replace("kitchen", "attic"))
    same = kbc.as_scenario(kitchen, "attic", attic)
    files = kbc.artifact_files([same, kitchen])
    assert sorted(files) == ["kitchen.json", kbc.INDEX]
    entry = json.loads(files[kbc.INDEX])["scenarios"]["attic"]
    assert entry["artifact"] == "kitchen.json" and entry["module"]["name"] == "scenario-attic"
    # One rule fewer: its own file.
    vocabulary = same.vocabulary
    fewer = dict(vocabulary.uscs)
    fewer.pop(sorted(fewer)[0])
    other = replace(same, vocabulary=replace(vocabulary, uscs=MappingProxyType(fewer)))
    files = kbc.artifact_files([other, kitchen])
    assert sorted(files) == ["attic.json", "kitchen.json", kbc.INDEX]


def test_the_loaded_artifact_is_the_knowledge_the_compiler_built() -> None:
    built = kbc.compile_kb(OwlModules("kitchen", ontology_dir()), kbc.source_digest())
    loaded = kba.from_json(kbc.artifact_path("kitchen").read_text(encoding="utf-8"))
    assert loaded.vocabulary == built.vocabulary
    assert loaded.module_stats == built.module_stats
    assert loaded.fragment.axioms == built.fragment.axioms
    assert loaded.fragment.query_defs == built.fragment.query_defs
    assert loaded.fragment.sinks == built.fragment.sinks
    assert loaded.fragment.kb == built.fragment.kb


def test_the_default_knowledge_base_comes_from_the_artifact() -> None:
    assert load_tbox().source == "artifact"


def test_a_module_edited_after_compiling_is_compiled_again(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(kbc, "source_digest", lambda module_dir=None: "edited")
    # Past the per-process cache: the artifact is read again and found stale.
    tbox = tbox_module._load.__wrapped__("kitchen", (), "", None)
    assert tbox.source == "modules"
    assert tbox.vocabulary == load_tbox().vocabulary


def test_an_artifact_of_another_format_is_refused() -> None:
    doc = json.loads(kbc.artifact_path("kitchen").read_text(encoding="utf-8"))
    doc["format"] = kba.FORMAT + 1
    with pytest.raises(ValueError, match="format"):
        kba.from_json(json.dumps(doc))


def _without_java(argv: list[str], tmp_path: Path) -> subprocess.CompletedProcess[str]:
    """Run ``argv`` where no Java runtime can be found."""
    env = {k: v for k, v in os.environ.items() if k not in ("JAVA_HOME", "VIRF_JARS")}
    env["PATH"] = str(tmp_path)  # nothing there; the tools are called by full path
    return subprocess.run(argv, capture_output=True, text=True, env=env, timeout=120)


def test_the_fast_engine_verifies_without_java(tmp_path: Path) -> None:
    virf = Path(sys.executable).with_name("virf")
    run = _without_java(
        [str(virf), "verify", str(WALKTHROUGH / "scene.json"), str(WALKTHROUGH / "plan.txt")],
        tmp_path,
    )
    assert run.returncode == 1, run.stderr  # UNSAFE, as with Java
    assert "Verdict: UNSAFE at step 7" in run.stdout
    probe = (
        "import jpype; from virf.api import LogicTutor; "
        f"r = LogicTutor().verify_files({str(WALKTHROUGH / 'scene.json')!r}, "
        f"{str(WALKTHROUGH / 'plan.txt')!r}); "
        "print(r.status, jpype.isJVMStarted())"
    )
    run = _without_java([sys.executable, "-c", probe], tmp_path)
    assert run.stdout.split() == ["UNSAFE", "False"], run.stderr


def test_without_java_a_question_the_fast_engine_cannot_answer_is_an_error(
    tmp_path: Path,
) -> None:
    # A name shaped like one of the engine's own goes to the reference reasoner.
    probe = (
        "from virf.ontology.tbox import load_tbox; from virf.reasoning import make_engine, "
        "ReasonerFailure; from virf.schema import Fact, FactKind\n"
        "fast = make_engine('fast', load_tbox())\n"
        "try:\n"
        "    fast.classify([Fact('_:x', 'type', 'Fridge', FactKind.TYPE)], ['ColdStorageLeftOpenDanger'])\n"
        "except ReasonerFailure as exc:\n"
        "    print('failure:', exc)\n"
    )
    run = _without_java([sys.executable, "-c", probe], tmp_path)
    assert run.stdout.startswith("failure: the fast engine needed the reference reasoner"), (
        run.stdout + run.stderr
    )
    assert "java not found" in run.stdout


def test_a_java_only_feature_without_java_names_what_to_install(tmp_path: Path) -> None:
    virf = Path(sys.executable).with_name("virf")
    run = _without_java(
        [
            str(virf),
            "verify",
            "--engine",
            "reference",
            str(WALKTHROUGH / "scene.json"),
            str(WALKTHROUGH / "plan.txt"),
        ],
        tmp_path,
    )
    assert run.returncode == 4
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "openjdk-17-jre-headless" in lines[0], run.stderr
    assert "Traceback" not in run.stderr


# ---------------------------------------------------------------------- a workspace's cache
# A workspace's compiled artifact lives in its writable cache/ folder.  Its
# digest names the modules it was compiled from, which anyone can copy into a
# forged artifact; the cache is trusted only when this installation wrote it.


def _workspace_artifact(root: Path) -> Path:
    [path] = (root / "cache").glob("compiled-*.json")
    return path


def _without_rules(path: Path) -> None:
    """Drop every Unsafe State Concept from a cached artifact, keeping its
    digest (and whatever precedes the JSON document) as it was."""
    text = path.read_text(encoding="utf-8")
    start = text.index("{")
    doc = json.loads(text[start:])
    assert doc["vocabulary"]["uscs"]
    doc["vocabulary"]["uscs"] = {}
    path.write_text(text[:start] + json.dumps(doc), encoding="utf-8")


def _walkthrough_status(kb: Path) -> str:
    from virf.api import LogicTutor

    tbox_module._load.cache_clear()  # a new process: the workspace is loaded again
    report = LogicTutor(kb=kb).verify_files(WALKTHROUGH / "scene.json", WALKTHROUGH / "plan.txt")
    return report.status


@pytest.fixture
def kitchen_workspace(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    from virf.authoring.workspace import Workspace

    # This user's sealing key, kept apart from the one of whoever runs the tests.
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "user-cache"))

    ws = Workspace.init(tmp_path / "ws", "kitchen", starter=False)
    ws.close()
    return ws.root


def test_a_tampered_workspace_cache_is_compiled_again(kitchen_workspace: Path, cli) -> None:
    assert _walkthrough_status(kitchen_workspace) == "UNSAFE"
    artifact = _workspace_artifact(kitchen_workspace)
    # The cache this installation wrote is used: no Java on the next load.
    tbox_module._load.cache_clear()
    assert load_tbox(kb=kitchen_workspace).source == "artifact"
    _without_rules(artifact)
    assert _walkthrough_status(kitchen_workspace) == "UNSAFE"
    assert load_tbox(kb=kitchen_workspace).source == "modules"
    rules = len(load_tbox().vocabulary.uscs)
    tbox_module._load.cache_clear()
    _without_rules(artifact)
    checked = cli("kb", "check", "--kb", kitchen_workspace, "--json")
    assert checked.exit_code == 0, checked.output
    assert json.loads(checked.output)["uscs"] == rules


def test_a_workspace_cache_is_not_trusted_without_a_key_of_this_installation(
    kitchen_workspace: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    blocked = tmp_path / "not-a-folder"
    blocked.write_text("")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocked))  # no key can be kept there
    assert _walkthrough_status(kitchen_workspace) == "UNSAFE"
    tbox_module._load.cache_clear()
    assert load_tbox(kb=kitchen_workspace).source == "modules"


def test_kb_check_compares_the_artifact_with_the_modules(
    cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    import virf.ontology.check as check_module

    doc = json.loads(kbc.artifact_path("paper").read_text(encoding="utf-8"))
    doc["vocabulary"]["uscs"] = {}
    forged = tbox_module.TBox(kba.from_json(json.dumps(doc)))
    monkeypatch.setattr(check_module, "load_tbox", lambda scenario=None, kb=None: forged)
    checked = cli("kb", "check", "--scenario", "paper", "--json")
    assert checked.exit_code == 1, checked.output
    result = json.loads(checked.output)
    assert result["artifact_matches_modules"] is False
    assert result["artifact_differs_in"] == ["vocabulary.uscs"]
    text = cli("kb", "check", "--scenario", "paper")
    assert "Compiled artifact: DIFFERS from what the modules compile to, in vocabulary.uscs" in (
        text.output
    )


def test_a_seal_opens_only_under_its_key_and_a_key_others_can_read_is_none(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from virf.ontology import seal

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    key = seal.local_key()
    assert key is not None and seal.local_key() == key  # created once, then read
    path = seal.key_path()
    assert path == tmp_path / "virf" / "artifact.key"
    assert oct(path.stat().st_mode & 0o777) == oct(0o600)
    sealed = seal.seal('{"a": 1}\n', key)
    assert seal.unseal(sealed, key) == '{"a": 1}\n'
    assert seal.unseal(sealed.replace('"a": 1', '"a": 2'), key) is None
    assert seal.unseal(sealed, bytes(32)) is None
    assert seal.unseal('{"a": 1}\n', key) is None
    path.chmod(0o644)  # others could read it, and forge seals
    assert seal.local_key() is None
    path.chmod(0o600)
    path.write_bytes(b"short")
    assert seal.local_key() is None
