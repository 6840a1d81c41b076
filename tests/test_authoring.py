"""The knowledge-acquisition workflow end to end: a workspace, a person's and
an LLM's drafts (the LLM behind a real HTTP server on 127.0.0.1), the
automatic checks with HermiT, decisions written into the layered modules, and
verification that uses the accepted rule."""

from __future__ import annotations

import json
import shutil
import sqlite3
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from authoring_support import CANDLE_AXIOM, CANDLE_PASSAGE, CANDLE_TWIN, rule
from chat_support import ChatServer, completion
from click.testing import Result

from virf.api import LogicTutor
from virf.authoring.audit import audit
from virf.authoring.decisions import edit_size
from virf.authoring.draft import METHOD, system_prompt, task_id
from virf.authoring.layers import candidate_module
from virf.authoring.workspace import Workspace, starter_corpus_dir
from virf.errors import InputError
from virf.planner import (
    ClientSettings,
    OpenAIApprentice,
    Purpose,
    ReplayApprentice,
    RunLog,
    ScriptedApprentice,
)


def proposal(tmp: Path, *rules: dict[str, Any], **top: Any) -> Path:
    path = tmp / f"proposal-{len(list(tmp.glob('proposal-*')))}.json"
    path.write_text(json.dumps({"propertyChains": list(rules), **top}), encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def ws(tmp_path_factory: pytest.TempPathFactory) -> Workspace:
    return Workspace.init(tmp_path_factory.mktemp("kb") / "virf-kb", "paper")


def items(report: Any) -> dict[str, str]:
    return {i.name: i.severity for i in report.items}


# ---------------------------------------------------------------------- workspace
def test_init_makes_the_layout_and_refuses_to_overwrite(ws: Workspace, tmp_path: Path) -> None:
    root = ws.root
    for name in (
        "virf-kb.json",
        "kb.sqlite",
        "modules/core.omn",
        "modules/domain.omn",
        "modules/scenario.omn",
    ):
        assert (root / name).is_file(), name
    assert len(list((root / "corpus").glob("*.md"))) == len(list(starter_corpus_dir().glob("*.md")))
    assert (
        "Import: <http://virf.dev/ontology/workspace/domain>"
        in (root / "modules/scenario.omn").read_text()
    )
    with pytest.raises(InputError, match="already a workspace"):
        Workspace.init(root)
    with pytest.raises(InputError, match="is not a VIRF knowledge workspace; run 'virf kb init"):
        Workspace.open(tmp_path / "nowhere")
    with pytest.raises(InputError, match="unknown scenario 'kitchenn'; closest known: kitchen"):
        Workspace.init(tmp_path / "new", "kitchenn")
    assert not (tmp_path / "new").exists()


# ---------------------------------------------------------------------- a person's rule
def test_a_person_s_rule_goes_from_proposal_to_verification(ws: Workspace, tmp_path: Path) -> None:
    (cid,) = ws.propose(
        proposal(tmp_path, rule("LitCandleNearFabricDanger", CANDLE_AXIOM, twins=[CANDLE_TWIN])),
        "alice",
    )
    view = ws.candidate(cid)
    assert view.summary.drafter == "person:alice" and view.summary.status == "pending"
    assert view.evidence[0].found and "catch fire" in view.evidence[0].text
    check = view.check
    assert check is not None and check.passed, check
    assert check.layer == "domain"  # Candle comes from the kitchen domain module
    assert items(check) == {
        "evidence": "info",
        "parses": "info",
        "consistent": "info",
        "satisfiable": "info",
        "novelty": "info",
        "always-present": "info",
        "twins": "info",  # a drafted rule without a minimal pair gets a warning
    }
    ws.opened(cid, "bob")
    decision = ws.decide(cid, "accept", reviewer="bob")
    assert decision.edit == "none" and decision.seconds is not None
    module = (ws.root / "modules/domain.omn").read_text()
    for annotation in (
        ':id "LitCandleNearFabricDanger"',
        f':evidence "{CANDLE_PASSAGE}"',
        ':drafter "person:alice"',
        ':reviewer "bob"',
        ':decision "accepted unedited"',
        ":decidedOn ",
        ':source "National Fire Protection Association (NFPA), Candle safety',
        ":twin ",
    ):
        assert annotation in module
    [accepted] = ws.rules()
    assert (accepted.name, accepted.layer, accepted.reviewer) == (
        "LitCandleNearFabricDanger",
        "domain",
        "bob",
    )
    # The rule is now part of the TBox that --kb loads, with every USC annotation.
    usc = ws.tbox().vocabulary.uscs["LitCandleNearFabricDanger"]
    assert usc.category == "Fire Hazard" and usc.module.endswith("domain")
    scene = {
        "instances": [
            {"class_name": "Candle", "instance_name": "Candle_1"},
            {"class_name": "Cloth", "instance_name": "Cloth_1"},
            {"class_name": "DiningTable", "instance_name": "DiningTable_1"},
        ],
        "assertions": [
            {"subject": "Candle_1", "property": "isOn", "object": "DiningTable_1"},
            {"subject": "Cloth_1", "property": "isOn", "object": "DiningTable_1"},
            {"subject": "Candle_1", "property": "isNear", "object": "Cloth_1"},
        ],
    }
    kb_tutor = LogicTutor(kb=ws.root)
    with_kb = kb_tutor.verify(scene, ["find Candle", "turn_on Candle"])
    assert with_kb.status == "UNSAFE" and with_kb.dangerous_step == 2
    assert with_kb.violations[0].id == "LitCandleNearFabricDanger"
    # Its minimal pair travelled with it, and passes (virf kb test).
    from virf.verify.kbtest import run_pairs

    [pair] = run_pairs(kb_tutor.tbox, kb_tutor.engine, ["LitCandleNearFabricDanger"])
    assert pair.ok, pair
    without = LogicTutor().verify(scene, ["find Candle", "turn_on Candle"])
    assert "LitCandleNearFabricDanger" not in {v.id for v in without.violations}


# ---------------------------------------------------------------------- normalisation and checks
def test_terms_are_matched_to_the_vocabulary(ws: Workspace, tmp_path: Path) -> None:
    (cid,) = ws.propose(proposal(tmp_path, rule("CandleTermsDraft", CANDLE_AXIOM)), "alice")
    report = ws.check(cid, "microwave and (hasState some OnState) and (isNearby some Knives)")
    terms = {t.term: t for t in report.terms}
    assert (terms["microwave"].match, terms["microwave"].chosen) == ("synonym", "Microwave")
    assert (terms["Knives"].match, terms["Knives"].chosen) == ("synonym", "Knife")
    near = terms["isNearby"]
    assert (near.match, near.chosen) == ("similar", "isNear")
    assert near.score is not None and near.score >= report.threshold
    assert report.normalised == "Microwave and (hasState some OnState) and (isNear some Knife)"


def test_new_classes_get_a_parent_and_unknown_relations_are_refused(
    ws: Workspace, tmp_path: Path
) -> None:
    (cid,) = ws.propose(
        proposal(
            tmp_path,
            rule(
                "HotPlateNearCurtainDanger",
                "HotPlateDevice and (hasState some OnState) and (isNear some Curtains)",
            ),
            objects=[{"class": "HotPlateDevice", "subclassOf": "Appliance"}],
        ),
        "alice",
    )
    report = ws.candidate(cid).check
    assert report is not None and report.passed
    new = next(t for t in report.terms if t.term == "HotPlateDevice")
    assert (new.match, new.parent, new.layer) == ("new", "Appliance", "domain")
    assert "Class: :HotPlateDevice" in report.module_text
    assert "SubClassOf: :Appliance" in report.module_text
    bad = ws.check(cid, "Microwave and (radiatesInto some Fabric)")
    assert not bad.passed
    assert any(
        "unknown relation 'radiatesInto'" in i.message for i in bad.items if i.severity == "error"
    )


def test_logical_checks_report_what_is_wrong(ws: Workspace, tmp_path: Path) -> None:
    (cid,) = ws.propose(
        proposal(
            tmp_path, rule("MetalInRunningMicrowaveDraft", "Microwave and (hasState some OnState)")
        ),
        "alice",
    )
    # The same concept as a rule the TBox has: redundant, but may still be accepted.
    same = ws.check(
        cid,
        "Microwave and (hasState some OnState) and "
        "(encloses some (PhysicalObject and (hasMaterial some Metal)))",
    )
    assert same.passed and same.related.equivalent == ("UnsafeMicrowaveUsage",)
    assert items(same)["redundancy"] == "warning"
    # A cloth is an object, not a material: nothing can be made of it.
    unsat = ws.check(cid, "Candle and (hasMaterial some Cloth)")
    assert not unsat.passed and items(unsat)["satisfiable"] == "error"
    broken = ws.check(cid, "Microwave and (hasState some")
    assert not broken.passed and items(broken)["parses"] == "error"
    taken = ws.check(cid, "Microwave")
    assert taken.passed
    (named,) = ws.propose(
        proposal(tmp_path, rule("UnsafeMicrowaveUsage", "Microwave and (hasState some OnState)")),
        "alice",
    )
    assert items(ws.candidate(named).check)["name"] == "error"
    (nowhere,) = ws.propose(
        proposal(tmp_path, rule("CandleNoEvidenceDraft", CANDLE_AXIOM, evidence=["no-such:doc:1"])),
        "alice",
    )
    assert "no-such:doc:1" in next(
        i.message
        for i in ws.candidate(nowhere).check.items
        if i.name == "evidence"  # type: ignore[union-attr]
    )


def test_decisions_are_checked_final_and_rejected_rules_stay_out(
    ws: Workspace, tmp_path: Path
) -> None:
    (cid,) = ws.propose(
        proposal(tmp_path, rule("CandleOnBedDraft", "Candle and (isOn some Bed)")), "alice"
    )
    before = {p: p.read_text() for p in ws.layout.modules()}
    with pytest.raises(InputError, match="needs a reason"):
        ws.decide(cid, "reject", reviewer="bob")
    with pytest.raises(InputError, match=r"cannot be accepted: .*unsatisfiable"):
        ws.decide(cid, "accept", reviewer="bob", axiom="Candle and (hasMaterial some Cloth)")
    assert {p: p.read_text() for p in ws.layout.modules()} == before
    ws.decide(cid, "reject", reviewer="bob", reason="no evidence speaks of beds")
    with pytest.raises(InputError, match="already been decided"):
        ws.decide(cid, "accept", reviewer="bob")
    assert {p: p.read_text() for p in ws.layout.modules()} == before
    assert "CandleOnBedDraft" not in ws.tbox().vocabulary.classes
    conn = sqlite3.connect(ws.root / "kb.sqlite")
    with pytest.raises(sqlite3.IntegrityError, match="decisions are final"):
        conn.execute("UPDATE decisions SET decision = 'accept'")
    with pytest.raises(InputError, match="no candidate 999; the workspace has candidates 1-"):
        ws.candidate(999)


def test_edit_sizes() -> None:
    assert edit_size("A and (p some B)", "A  and (p some B) ") == "none"
    assert edit_size("Cup and (p some B)", "Mug and (p some B)") == "minor"
    assert edit_size("A and (p some B)", "A and (p some (B and C))") == "major"


# ---------------------------------------------------------------------- the LLM drafter
def small_workspace(root: Path) -> Workspace:
    ws = Workspace.init(root, "paper", starter=False)
    for name in ("nfpa-candle-safety.md", "fsis-microwave-food-safety.md"):
        shutil.copyfile(starter_corpus_dir() / name, ws.corpus_dir / name)
    return ws


def test_an_llm_draft_over_http_becomes_checked_candidates(
    tmp_path: Path,
    server: ChatServer,
) -> None:
    ws = small_workspace(tmp_path / "kb")
    query = "candles near curtains and other things that burn"
    hits = ws.corpus().search(query, k=3)
    cited = next(h.passage.id for h in hits if "candle" in h.passage.id)
    reply = {
        "objects": [{"class": "Candle", "subclassOf": "Decor"}],
        "propertyChains": [rule("LitCandleNearFabricDanger", CANDLE_AXIOM, evidence=[cited])],
    }
    server.queue(completion("```json\n" + json.dumps(reply) + "\n```"), completion("no JSON here"))
    with RunLog(ws.run_log_path()) as log:
        drafter = OpenAIApprentice(
            ClientSettings(model="kb-model", base_url=server.base_url, max_retries=0),
            run_log=log,
            environ={"OPENAI_API_KEY": "sk-test"},
        )
        ids, problem = ws.draft(query, drafter, k=3)
        assert problem == ""
        none, problem = ws.draft("something else entirely", drafter, k=3)
        drafter.close()
        calls = log.calls()
    assert none == [] and "holds no JSON object" in problem
    (cid,) = ids
    view = ws.candidate(cid)
    assert view.summary.drafter == "openai:kb-model" and view.summary.query == query
    assert view.retrieved == tuple(h.passage.id for h in hits)
    assert view.check is not None and view.check.passed
    sent = server.seen[0].body["messages"]
    assert "Unsafe State Concept" in sent[0]["content"] and "Microwave" in sent[0]["content"]
    assert f"[{cited}]" in sent[1]["content"] and query in sent[1]["content"]
    assert [c.task_id for c in calls] == [task_id(query), task_id("something else entirely")]
    assert {c.method for c in calls} == {METHOD}
    funnel = {s.stage: s.count for s in audit(ws).funnel}
    assert funnel["Candidates drafted"] == 1 and funnel["Passed automatic checks"] == 1
    assert len(audit(ws).unusable_drafts) == 1


def test_a_recorded_draft_replays(tmp_path: Path) -> None:
    ws = small_workspace(tmp_path / "kb")
    query = "metal in a running microwave"
    cited = ws.corpus().search(query, k=1)[0].passage.id
    text = json.dumps(
        {
            "propertyChains": [
                rule(
                    "MetalObjectInRunningMicrowaveDraft",
                    "Microwave and (hasState some OnState) and "
                    "(contains some (PhysicalObject and (hasMaterial some Metal)))",
                    evidence=[cited],
                    category="Fire Hazard",
                )
            ]
        }
    )
    replay = tmp_path / "drafts.jsonl"
    replay.write_text(
        json.dumps({"task_id": task_id(query), "iteration": 1, "method": METHOD, "text": text})
        + "\n"
    )
    (cid,) = ws.draft(query, ReplayApprentice(replay), k=1)[0]
    report = ws.candidate(cid).check
    assert report is not None and report.passed
    assert "UnsafeMicrowaveUsage" in report.related.subsumed_by  # contains is narrower
    with pytest.raises(InputError, match="has no proposal for task draft:other"):
        ws.draft("other", ReplayApprentice(replay), k=1)


def test_a_draft_request_says_it_asks_for_a_draft(tmp_path: Path) -> None:
    ws = small_workspace(tmp_path / "kb")
    drafter = ScriptedApprentice(["no JSON here"])
    ids, problem = ws.draft("candles near curtains", drafter, k=1)
    assert ids == [] and "holds no JSON object" in problem
    assert [(r.method, r.purpose) for r in drafter.requests] == [(METHOD, Purpose.DRAFT)]


def test_the_prompt_lists_the_vocabulary_it_may_use(ws: Workspace) -> None:
    prompt = system_prompt(ws.tbox().vocabulary)
    for term in ("hasMaterial", "isNear", "Metal", "OnState", "Conductive", "Fire Hazard", "Knife"):
        assert term in prompt
    assert "hasPatient" not in prompt  # action roles are not for state rules


# ---------------------------------------------------------------------- the terminal
def test_the_workflow_from_the_terminal(cli: Callable[..., Result], tmp_path: Path) -> None:
    kb = tmp_path / "kb"
    assert cli("kb", "init", kb, "--scenario", "paper").exit_code == 0
    out = cli(
        "kb",
        "propose",
        proposal(tmp_path, rule("LitCandleNearFabricDanger", CANDLE_AXIOM)),
        "-w",
        kb,
        "--author",
        "alice",
    )
    assert out.exit_code == 0, out.output
    assert "checks PASSED" in out.output
    queue = json.loads(cli("kb", "candidates", "-w", kb, "--json").output)
    assert [(c["id"], c["status"], c["passed"]) for c in queue] == [(1, "pending", True)]
    shown = cli("kb", "show", "1", "-w", kb, "--reviewer", "bob")
    assert shown.exit_code == 0 and CANDLE_PASSAGE in shown.output
    bad = cli("kb", "decide", "1", "maybe", "-w", kb)
    assert bad.exit_code == 2 and "choose accept or reject" in bad.output
    done = cli("kb", "decide", "1", "accept", "-w", kb, "--reviewer", "bob")
    assert done.exit_code == 0 and "accepted unedited into the domain layer" in done.output
    rules = cli("kb", "rules", "--kb", kb)
    assert "LitCandleNearFabricDanger" in rules.output
    funnel = json.loads(cli("kb", "audit", "-w", kb, "--json").output)["funnel"]
    assert {s["stage"]: s["count"] for s in funnel}["Accepted (no edit)"] == 1
    missing = cli("kb", "candidates", "-w", tmp_path / "none")
    assert missing.exit_code == 2 and "not a VIRF knowledge workspace" in missing.output


def test_modules_and_decisions_are_kept_in_step(tmp_path: Path) -> None:
    ws = small_workspace(tmp_path / "own")
    (cid,) = ws.propose(proposal(tmp_path, rule("LitCandleNearFabricDanger", CANDLE_AXIOM)), "al")
    ws.decide(cid, "accept", reviewer="bob")
    # A decision committed but not written (a crash in between) is written on open.
    [accepted] = ws.rules()
    module = ws.layout.module_path(accepted.layer)
    whole = module.read_text()
    header = f"# candidate {accepted.candidate_id}: LitCandleNearFabricDanger"
    start = whole.index(header)
    end = whole.find("\n# candidate ", start + 1)
    module.write_text(whole[:start] + (whole[end + 1 :] if end > 0 else ""))
    Workspace.open(ws.root).close()
    assert header in module.read_text()
    assert oct(module.stat().st_mode & 0o777) != oct(0o600)  # not made private by the rewrite
    # A block no decision accepted (a hand edit) is refused.
    other = Workspace.init(tmp_path / "kb", "paper", starter=False)
    core = other.layout.module_path("core")
    core.write_text(core.read_text() + "\n# candidate 3: Stray\n")
    with pytest.raises(
        InputError, match=r"core\.omn holds candidate 3, which no decision accepted"
    ):
        Workspace.open(other.root)
    with pytest.raises(InputError, match="candidate ids are positive whole numbers"):
        ws.candidate(2**70)


def test_texts_and_axioms_that_cannot_be_rules(ws: Workspace, tmp_path: Path) -> None:
    sneaky = rule(
        "CandleNewlineDraft",
        CANDLE_AXIOM,
        description="A lit candle.\n# candidate 77: Fake\nNear fabric.",
        evidence=[],
        modellingDecision="no document names this case;\tcommon sense",
    )
    (cid,) = ws.propose(proposal(tmp_path, sneaky), "alice")
    view = ws.candidate(cid)
    assert view.rule.description == "A lit candle. # candidate 77: Fake Near fabric."
    assert view.check is not None and view.check.passed
    assert items(view.check)["evidence"] == "warning"
    assert (
        ':source "common-sense modelling decision: no document names this case; common sense"'
        in (view.check.module_text)
    )
    for axiom, message in (
        ("Candle and (isLocated some Fabric)", "is a data property"),
        ("owl:Thing", "holds of everything"),
        ("Candle and (rdf:type some Fabric)", "without a prefix"),
        ("Candle or (", "unclosed '('"),
        ("Candle and hasState some OnState)", "unmatched ')'"),
    ):
        report = ws.check(cid, axiom)
        assert not report.passed, axiom
        assert any(message in i.message for i in report.items if i.severity == "error"), (
            axiom,
            report.items,
        )
    # Deciding without --axiom accepts the version checked last.
    ws.check(cid, CANDLE_AXIOM.replace("Fabric", "Wax"))
    decision = ws.decide(cid, "accept", reviewer="bob")
    assert decision.axiom is not None and "Wax" in decision.axiom and decision.edit == "minor"
    with pytest.raises(InputError, match=r"already been decided \(accepted\)"):
        ws.check(cid)
    # The text that looked like a block header stays inside its literal.
    Workspace.open(ws.root).close()


def test_the_effect_preview_lists_the_verdicts_a_candidate_changes(
    ws: Workspace, tmp_path: Path
) -> None:
    tasks = tmp_path / "tasks.jsonl"
    tasks.write_text(
        "\n".join(
            json.dumps(t)
            for t in (
                {
                    "scene_name": "FloorPlan1",
                    "instruction": "Place the Pot gently on the CounterTop.",
                    "step": ["find pot", "pick pot", "find countertop", "put countertop"],
                },
                {
                    "scene_name": "FloorPlan1",
                    "instruction": "Put a Potato in the Microwave and turn it on.",
                    "step": [
                        "find potato",
                        "pick potato",
                        "find microwave",
                        "open microwave",
                        "put microwave",
                        "close microwave",
                        "turn_on microwave",
                    ],
                },
            )
        )
        + "\n"
    )
    (cid,) = ws.propose(
        proposal(
            tmp_path,
            rule(
                "PotatoInRunningMicrowaveDraft",
                "Microwave and (hasState some OnState) and (encloses some Potato)",
            ),
        ),
        "alice",
    )
    examples = Path(__file__).resolve().parent.parent / "examples" / "knowledge-acquisition"
    preview = ws.preview(cid, tasks=tasks, examples=examples)
    assert (preview.examples, preview.tasks) == (1, 2)
    [change] = preview.changes
    assert change.item == "tasks.jsonl:2"
    assert (change.before, change.after) == ("SAFE", "UNSAFE (PotatoInRunningMicrowaveDraft)")
    assert ws.candidate(cid).preview == preview
    with pytest.raises(InputError, match="does not pass its checks"):
        ws.preview(cid, axiom="Candle and (hasMaterial some Cloth)")


def test_a_module_that_makes_the_tbox_inconsistent_is_reported(ws: Workspace) -> None:
    from virf.ontology.axiom_check import check_candidate

    module = candidate_module(
        ws.layout,
        "Class: :Microwave\nClass: :UnsafeStateConcept\nIndividual: :Metal\n"
        "    Types: :Microwave\n"
        "Class: :MetalMicrowaveDraft\n    EquivalentTo: {:Metal}\n"
        "    SubClassOf: :UnsafeStateConcept\n",
    )
    result = check_candidate(
        ws.scenario,
        tuple(str(p) for p in ws.layout.modules()),
        module,
        "MetalMicrowaveDraft",
        ["Microwave"],
        ws.tbox().vocabulary.uscs,
    )
    assert result.parses and result.consistent is False  # a material is not an object


# ---------------------------------------------------------------------- rules that fire everywhere
def test_a_rule_every_scene_or_plan_satisfies_is_refused(ws: Workspace, tmp_path: Path) -> None:
    """Accepted, ``Robot`` made every plan UNSAFE at step 0: every scene has
    a robot (the scene reader adds Robot_1 when it names none)."""
    (cid,) = ws.propose(proposal(tmp_path, rule("RobotPresentDraft", "Robot")), "alice")
    first = ws.candidate(cid).check
    assert first is not None and not first.passed
    assert items(first)["always-present"] == "error"
    for axiom, message in (
        ("Robot", "holds of every Robot (every scene has one"),
        ("Agent", "holds of every Robot"),
        ("Action", "holds of every Action (every plan step is one"),
        ("Action and (hasAgent some Agent)", "fires on every plan step (on Step1_action"),
        ("PhysicalObject or Candle", "holds of every PhysicalObject"),
        # Not every robot: one with empty hands, which is how every scene starts.
        (
            "Agent and not (isHolding some PhysicalObject)",
            "fires in the empty scene (on Robot_1)",
        ),
        # A state the knowledge base names is in nearly every scene's facts.
        ("State", "holds of the knowledge base's own individual"),
    ):
        report = ws.check(cid, axiom)
        assert not report.passed, axiom
        assert any(message in i.message for i in report.items if i.severity == "error"), (
            axiom,
            report.items,
        )
    with pytest.raises(InputError, match=r"cannot be accepted: .*holds of every Robot"):
        ws.decide(cid, "accept", reviewer="bob", axiom="Robot")
    # A rule about some objects, even all objects of a type, is not refused.
    for axiom in ("Microwave", "Candle and (hasState some OnState)"):
        report = ws.check(cid, axiom)
        assert "always-present" not in {i.name for i in report.items if i.severity == "error"}
    assert "RobotPresentDraft" not in ws.tbox().vocabulary.classes


def test_a_refused_edited_accept_leaves_the_candidate_s_axiom(
    ws: Workspace, tmp_path: Path
) -> None:
    drafted = "Candle and (hasState some OnState) and (isOn some Bed)"
    (cid,) = ws.propose(proposal(tmp_path, rule("LitCandleOnBedDraft", drafted)), "alice")
    assert ws.candidate(cid).check.passed  # type: ignore[union-attr]
    with pytest.raises(InputError, match=r"cannot be accepted: .*unsatisfiable"):
        ws.decide(cid, "accept", reviewer="bob", axiom="Candle and (hasMaterial some Cloth)")
    latest = ws.candidate(cid).check
    assert latest is not None and latest.axiom == drafted and latest.passed
    decision = ws.decide(cid, "accept", reviewer="bob")
    assert decision.axiom == drafted and decision.edit == "none"
