"""The learn loop from the terminal, end to end with the real checks (HermiT):
an open-world object's question, the answer, a candidate class with the
answer as evidence, nothing changed before a person accepts it, and the
next verdict using it once accepted."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from click.testing import Result
from learn_support import ELECTRIC, HAIR_DRYER, HAIR_DRYER_PLAN, TODDLER

from virf.authoring.workspace import Workspace


def write(tmp: Path, name: str, data: Any) -> Path:
    path = tmp / name
    path.write_text(data if isinstance(data, str) else json.dumps(data), encoding="utf-8")
    return path


@pytest.fixture
def files(tmp_path: Path) -> dict[str, Path]:
    return {
        "scene": write(tmp_path, "bathroom.json", HAIR_DRYER),
        "plan": write(tmp_path, "dry.txt", "\n".join(HAIR_DRYER_PLAN) + "\n"),
        "yes": write(tmp_path, "yes.json", {ELECTRIC: "yes"}),
        "typo": write(
            tmp_path, "typo.json", {ELECTRIC.replace("Electrically", "Electricaly"): "yes"}
        ),
    }


def test_options_that_cannot_work_together_are_refused(
    cli: Callable[..., Result], files: dict[str, Path], tmp_path: Path
) -> None:
    scene, plan = files["scene"], files["plan"]
    for args, words in (
        (("--learn", tmp_path / "kb"), "--learn needs --answers FILE"),
        (("--answers", files["yes"], "--who", "alice"), "--who names who answered, for --learn"),
        (
            ("--answers", files["yes"], "--learn", tmp_path / "a", "--kb", tmp_path / "b"),
            "name different workspaces",
        ),
        (
            ("--answers", files["yes"], "--learn", tmp_path / "none"),
            "not a VIRF knowledge workspace",
        ),
        (("--answers", files["plan"]), "is not valid JSON"),
    ):
        out = cli("verify", scene, plan, *args)
        assert out.exit_code == 2, (args, out.output)
        assert words in out.stderr and "Traceback" not in out.output
        assert len(out.stderr.strip().splitlines()) == 1
    strict = cli("verify", scene, plan, "--strict-vocabulary")
    assert strict.exit_code == 2 and "unknown class 'HairDryer'" in strict.stderr


def test_answers_settle_the_questions_of_verify(
    cli: Callable[..., Result], files: dict[str, Path]
) -> None:
    asked = cli("verify", files["scene"], files["plan"])
    assert asked.exit_code == 3 and "Is HairDryer_1 an electrical appliance?" in asked.stdout
    answered = cli("verify", files["scene"], files["plan"], "--answers", files["yes"], "--json")
    assert answered.exit_code == 1, answered.output
    report = json.loads(answered.stdout)
    assert (report["status"], report["dangerous_step"], report["questions"]) == ("UNSAFE", 2, [])
    typo = cli("verify", files["scene"], files["plan"], "--answers", files["typo"])
    assert typo.exit_code == 3
    assert f"no question '{ELECTRIC.replace('Electrically', 'Electricaly')}' was asked" in (
        typo.stderr
    )
    assert f"closest asked: {ELECTRIC}" in typo.stderr


def test_the_learn_loop_end_to_end(
    cli: Callable[..., Result], files: dict[str, Path], tmp_path: Path
) -> None:
    kb = tmp_path / "kb"
    assert cli("kb", "init", kb, "--no-starter").exit_code == 0
    scene, plan = files["scene"], files["plan"]
    # The knowledge base does not know hair dryers: the tutor asks.
    before = cli("verify", scene, plan, "--kb", kb)
    assert before.exit_code == 3 and "Is HairDryer_1 an electrical appliance?" in before.stdout

    # The answer settles this scene and becomes a candidate class.
    learned = cli(
        "verify", scene, plan, "--answers", files["yes"], "--learn", kb, "--who", "alice", "--json"
    )
    assert learned.exit_code == 1, learned.output
    assert json.loads(learned.stdout)["status"] == "UNSAFE"  # stdout: one JSON report
    err = learned.stderr
    assert (
        "learned: candidate 1, HairDryer SubClassOf PhysicalObject and "
        "(hasProperty value ElectricallyPowered)" in err
    )
    assert "checks PASSED" in err
    assert (
        "scene bathroom (learned from): UNKNOWN (LiveDeviceBesideWaterDanger) -> "
        "UNSAFE (LiveDeviceBesideWaterDanger)" in err
    )
    assert "virf kb test with the candidate:" in err and "new failure" not in err
    assert f"virf kb decide 1 accept -w {kb}" in err

    [queued] = json.loads(cli("kb", "candidates", "-w", kb, "--json").stdout)
    assert (queued["name"], queued["origin"], queued["drafter"], queued["passed"]) == (
        "HairDryer",
        "answer",
        "answer:alice",
        True,
    )
    view = json.loads(cli("kb", "show", "1", "-w", kb, "--json", "--reviewer", "bob").stdout)
    evidence = view["learned"]
    assert (evidence["who"], evidence["scene_name"]) == ("alice", "bathroom")
    assert len(evidence["scene_sha256"]) == 64 and evidence["when"].startswith("20")
    assert evidence["answers"] == [
        {
            "key": ELECTRIC,
            "question": "Is HairDryer_1 an electrical appliance?",
            "subject": "HairDryer_1",
            "answer": "yes",
            "effect": "HairDryer SubClassOf hasProperty value ElectricallyPowered",
        }
    ]
    checks = {i["name"]: i["severity"] for i in view["check"]["items"]}
    assert checks == {
        "evidence": "info",
        "open world": "warning",  # the heat-source guess would no longer be asked
        "parses": "info",
        "consistent": "info",
        "satisfiable": "info",
    }
    assert view["check"]["layer"] == "core"

    # Nothing learned changes a verdict before a person accepts it.
    pending = cli("verify", scene, plan, "--kb", kb)
    assert pending.exit_code == 3 and "Is HairDryer_1 an electrical appliance?" in pending.stdout

    # A learned class is placed under known classes only.
    bad = cli("kb", "recheck", "1", "-w", kb, "--axiom", "Blowdryer and (hasProperty value Sharp)")
    assert bad.exit_code == 1 and "'Blowdryer' is not a class of the knowledge base" in bad.stdout
    cli("kb", "recheck", "1", "-w", kb)  # back to the learned axiom

    accepted = cli("kb", "decide", "1", "accept", "-w", kb, "--reviewer", "bob")
    assert accepted.exit_code == 0, accepted.output
    assert "accepted unedited into the core layer" in accepted.stdout
    module = (kb / "modules" / "core.omn").read_text()
    assert ':drafter "answer:alice"' in module and ':reviewer "bob"' in module
    assert ':evidence "answer by alice at ' in module and "-> yes" in module

    # The next verdict uses it: UNSAFE at the hazard step, without asking.
    after = cli("verify", scene, plan, "--kb", kb, "--json")
    assert after.exit_code == 1, after.output
    report = json.loads(after.stdout)
    assert (report["status"], report["dangerous_step"], report["questions"]) == ("UNSAFE", 2, [])
    background = {b["id"]: b["source"] for b in report["causal_chain"]["background"]}
    assert "answers by alice" in background["LEARNED-HairDryer-property-ElectricallyPowered"]
    assert not report["notes"]  # HairDryer_1 is no longer an open-world object

    # Answering again teaches nothing new: the class is known.
    again = cli("verify", scene, plan, "--answers", files["yes"], "--learn", kb)
    assert again.exit_code == 1 and "nothing learned" in again.stderr
    assert "no question" in again.stderr  # the answer was not needed


def test_plan_learns_from_the_answers_of_its_run(
    cli: Callable[..., Result], tmp_path: Path
) -> None:
    kb = tmp_path / "kb"
    Workspace.init(kb, starter=False).close()
    scene = write(tmp_path, "nursery.json", TODDLER)
    replay = write(
        tmp_path,
        "replay.jsonl",
        "\n".join(
            json.dumps({"task_id": "task", "iteration": i, "text": f"PLAN:\n{text}"})
            for i, text in enumerate(["turn_on Toaster_1", "find Toaster_1"])
        ),
    )
    answers = write(tmp_path, "answers.json", {"confirm:Toddler_1 rdf:type Child": "yes"})
    out = cli(
        "plan",
        "--scene",
        scene,
        "-i",
        "make toast",
        "--planner",
        f"replay:{replay}",
        "--answers",
        answers,
        "--learn",
        kb,
        "--who",
        "carol",
        "--json",
    )
    assert out.exit_code == 0, out.output
    assert json.loads(out.stdout)["outcome"] == "APPROVED"
    assert "learned: candidate 1, Toddler SubClassOf Child" in out.stderr
    assert "checks PASSED" in out.stderr
    rejected = cli("kb", "decide", "1", "reject", "-w", kb, "--reason", "toddlers vary")
    assert rejected.exit_code == 0 and "rejected: toddlers vary" in rejected.stdout
    # A rejected class never enters the knowledge base.
    assert "Toddler" not in (kb / "modules" / "core.omn").read_text()
