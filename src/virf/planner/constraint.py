"""The plan lines a scene allows, for decoding constrained to them.

A small model names objects the scene lacks and applies actions to objects
that cannot take them; every such line costs an iteration of the loop and
teaches it nothing.  :func:`plan_constraint` lists, per verb of the action
language, the scene's objects the verb may take, and :class:`PlanConstraint`
turns that list into what a model's decoder can enforce: a llama.cpp GBNF
grammar (:meth:`PlanConstraint.gbnf`) or a JSON schema for a server's
structured output (:meth:`PlanConstraint.json_schema`).

"May take" is the simulator's own rule, never a second one: a verb is left
out for an object only when the simulator would certainly refuse it
(:func:`virf.world.actions.type_lacks`, :func:`virf.world.actions.cannot_receive`).
An open-world type, whose affordances nobody declared, takes every verb.  A
constrained plan can still be unsafe or fail a precondition (a closed
fridge, an empty hand): the tutor verifies it as any other.

Every line is offered in one spelling only, the one the plan reader reads
back to exactly that step (``verb Object``; ``put PLACE``; ``fillLiquid
Object water``; ``pour``, ``drop`` and ``throw`` with their object); a name
the reader would read as something else (an instance called ``it``) is not
offered at all.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import TYPE_CHECKING, Any, Final

from virf.ontology.tbox import Vocabulary
from virf.planner.prompting import REFUSAL, read_plan
from virf.render.feedback import CHOICE
from virf.world.actions import AFFORDANCE, cannot_receive, type_lacks
from virf.world.language import LIQUIDS, VERBS
from virf.world.scene import Scene

if TYPE_CHECKING:
    from virf.planner.stepwise import Sandbox

# SmolLM2 writes about 4 characters a token: 15 lines of ~6 tokens, after at
# most 3 reasoning lines of ~30 tokens, fit the local planner's 256-token
# budget, so a constrained reply ends by the grammar rather than being cut
# off mid-line (the local planner drops such a line; a smaller --max-tokens
# can still cut one).
MAX_LINES: Final = 15
MAX_REASONING_LINES: Final = 3
MAX_REASONING_CHARS: Final = 120
REASONING_MARK: Final = "REASONING:"
PLAN_MARK: Final = "PLAN:"
# The grammar's choice is one digit ('USE [1-n]'); the feedback offers at most
# virf.verify.repairs.MAX_OFFERED (3) corrections.
MAX_CHOICES: Final = 9


@dataclass(frozen=True)
class PlanConstraint:
    """The valid plan lines of one scene: for each verb that takes any
    object, the objects it takes (sorted), in the language's verb order."""

    takes: tuple[tuple[str, tuple[str, ...]], ...]
    # How many checked corrections the feedback just offered: the reply may
    # then be ``USE n``, taking the n-th as it is (CHOICE).
    choices: int = 0
    # The scene the lines are for, when a decoder can write a plan one line
    # at a time and be offered only the lines that run next
    # (:mod:`virf.planner.stepwise`); it leaves the lines themselves as they are.
    sandbox: Sandbox | None = field(default=None, compare=False)

    def objects_of(self, verb: str) -> tuple[str, ...]:
        return next((names for v, names in self.takes if v == verb), ())

    def narrowed(self, objects: frozenset[str]) -> PlanConstraint:
        """These lines about ``objects`` only (:mod:`virf.planner.focus`)."""
        takes = ((verb, tuple(n for n in names if n in objects)) for verb, names in self.takes)
        return replace(self, takes=tuple((verb, names) for verb, names in takes if names))

    def with_choices(self, n: int) -> PlanConstraint:
        """These lines, or ``USE k`` for a correction k of the ``n`` offered."""
        return replace(self, choices=min(n, MAX_CHOICES))

    def within(self, sandbox: Sandbox) -> PlanConstraint:
        """These lines, to be offered one at a time as they run in ``sandbox``."""
        return replace(self, sandbox=sandbox)

    def lines(self) -> tuple[str, ...]:
        """Every valid plan line, in a fixed order."""
        out: list[str] = []
        for verb, names in self.takes:
            for name in names:
                if verb == "fillLiquid":
                    out += [f"{verb} {name} {liquid}" for liquid in LIQUIDS]
                else:
                    out.append(f"{verb} {name}")
        return tuple(out)

    def gbnf(self, reasoning: bool = False, *, lines: int = MAX_LINES) -> str:
        """The grammar of a reply: ``TASK_ABORT``, or 1 to ``lines``
        valid lines; with ``reasoning``, a short ``REASONING:`` section and
        ``PLAN:`` before them, as the thinking methods ask (the reader then
        reads what follows ``PLAN:``)."""
        abort = _literal(REFUSAL)
        if not self.takes and not self.choices:
            # A scene without objects: a refusal is the only valid reply.
            return f"root ::= {abort}\n"
        # What may follow: lines, or the choice of an offered correction.
        body = " | ".join((["plan"] if self.takes else []) + (["choice"] if self.choices else []))
        if reasoning:
            rules = [
                f"root ::= {abort} | {_literal(REASONING_MARK + chr(10))} "
                f"note{{1,{MAX_REASONING_LINES}}} {_literal(PLAN_MARK + chr(10))} ({abort} | {body})",
                # A free line that cannot run on for ever, and not an empty
                # one, so the section cannot be padded with newlines.  It may
                # not start with P: a note reading "PLAN:" would let the model
                # write its plan as free text, outside the grammar of lines.
                f'note ::= [^P\\n] [^\\n]{{0,{MAX_REASONING_CHARS - 1}}} "\\n"',
            ]
        else:
            rules = [f"root ::= {abort} | {body}"]
        # No newline after the last line: once a line is complete the model
        # may only end the reply or start another, so it stops by the grammar.
        if self.choices:
            rules.append(f"choice ::= {_literal(CHOICE + ' ')} [1-{self.choices}]")
        if not self.takes:
            return "\n".join(rules) + "\n"
        more = f' ("\\n" line){{0,{lines - 1}}}' if lines > 1 else ""
        rules.append(f"plan ::= line{more}")
        return "\n".join(rules + self._line_rules()) + "\n"

    def next_gbnf(self) -> str:
        """The grammar of what may follow a plan's last line: nothing (the
        plan ends there) or one more of these lines on a line of its own."""
        if not self.takes:
            return 'root ::= ""\n'
        return "\n".join(['root ::= ("\\n" line)?', *self._line_rules()]) + "\n"

    def _line_rules(self) -> list[str]:
        rules = ["line ::= " + " | ".join(_rule(verb) for verb, _ in self.takes)]
        for verb, names in self.takes:
            head = f"{_literal(verb + ' ')} {_rule(verb, 'obj')}"
            if verb == "fillLiquid":
                head += " (" + " | ".join(_literal(" " + liquid) for liquid in LIQUIDS) + ")"
            rules.append(f"{_rule(verb)} ::= {head}")
            rules.append(f"{_rule(verb, 'obj')} ::= " + " | ".join(_literal(n) for n in names))
        return rules

    def json_schema(self) -> dict[str, Any]:
        """A strict JSON schema for a served model's structured output: an
        object whose ``steps`` are valid lines (1 to ``MAX_LINES``), or the
        single step ``TASK_ABORT``."""
        return {
            "type": "object",
            "properties": {
                "steps": {
                    "type": "array",
                    "items": {
                        "type": "string",
                        "enum": [
                            *self.lines(),
                            *(f"{CHOICE} {k}" for k in range(1, self.choices + 1)),
                            REFUSAL,
                        ],
                    },
                    "minItems": 1,
                    "maxItems": MAX_LINES,
                }
            },
            "required": ["steps"],
            "additionalProperties": False,
        }


def plan_constraint(scene: Scene, vocab: Vocabulary) -> PlanConstraint:
    """The valid lines of ``scene``: every object but the robot itself, each
    with the verbs the simulator would not certainly refuse for it."""
    objects = sorted(o for o in scene.order if o != scene.agent)
    takes: list[tuple[str, tuple[str, ...]]] = []
    for verb in VERBS:
        names = tuple(n for n in objects if _may_take(verb, scene.objects[n], vocab))
        names = tuple(n for n in names if _reads_back(verb, n))
        if names:
            takes.append((verb, names))
    return PlanConstraint(tuple(takes))


def _may_take(verb: str, classes: frozenset[str], vocab: Vocabulary) -> bool:
    if verb == "put":
        return not cannot_receive(vocab, classes)
    # 'drop X' and 'throw X' name the object in the hand, which got there by
    # 'pick' (or was held from the start, and the scene's types say nothing
    # against that): the same affordance.
    affordance = AFFORDANCE.get("pick" if verb in ("drop", "throw") else verb)
    return affordance is None or not type_lacks(vocab, classes, affordance)


@lru_cache(maxsize=8192)
def _reads_back(verb: str, name: str) -> bool:
    """Whether the loop's reader reads the line as this verb on this name
    and nothing else (every liquid, for a fill)."""
    tails = [f" {liquid}" for liquid in LIQUIDS] if verb == "fillLiquid" else [""]
    for tail in tails:
        got = read_plan(f"{verb} {name}{tail}")
        want = (name, *tail.split())
        if got.refused or len(got.steps) != 1:
            return False
        step = got.steps[0]
        if step.verb != verb or step.args != want or step.note is not None:
            return False
    return True


def _rule(verb: str, part: str = "") -> str:
    # GBNF rule names are letters, digits and dashes: fillLiquid -> fillliquid-line.
    return f"{verb.lower().replace('_', '-')}-{part or 'line'}"


def _literal(text: str) -> str:
    """A GBNF string literal of ``text``.  Scene names are plain ASCII
    (``NAME_RE``), but a literal must stay one whatever it holds: the quote
    and backslash are escaped, and anything outside printable ASCII is
    written as a code point, which llama.cpp reads back as the character."""
    out = []
    for ch in text:
        if ch in '"\\':
            out.append("\\" + ch)
        elif ch == "\n":
            out.append("\\n")
        elif " " <= ch <= "~":
            out.append(ch)
        elif ord(ch) <= 0xFFFF:
            out.append(f"\\u{ord(ch):04X}")
        else:
            out.append(f"\\U{ord(ch):08X}")
    return '"' + "".join(out) + '"'
