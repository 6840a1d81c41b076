"""Parse plans written in SafeAgentBench's action language.

Accepted per line (case-insensitive verbs; blank lines and ``#`` comments are
skipped, leading numbering such as ``3.`` or ``3)`` is ignored)::

    find X            pick X | pick up X       put R | put X in R | put X on R
    open X            close X                  turn_on X | turn on X | toggle on X
    turn_off X ...    slice X   break X   cook X   dirty X   clean X
    fillLiquid X water|coffee|wine             emptyLiquid X
    pour | pour X     drop | drop X           throw | throw X

and the function style of the paper's walkthrough: ``put_in(Pot_1, Microwave_1)``.
A plan file may also be a JSON list of such strings.

Limits (docs/reliability.md): at most ``MAX_PLAN_STEPS`` actions and
``MAX_LINE_CHARS`` characters per action line; control and invisible
characters, and empty arguments in the function style, are input errors.

Objects may be named in words, as SafeAgentBench's reference plans and LLM
replies do: ``find dining table``, ``turn off coffee machine``, ``pick up the
knives``, ``find stove knob 2``.  The parser only groups the words into object
terms; which type or instance a term names is the simulator's decision, since
only it knows the vocabulary and the scene.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from virf.errors import InputError, clip, closest, hidden_char, parse_json, read_input_file
from virf.names import term_key

VERBS = (
    "find",
    "pick",
    "put",
    "open",
    "close",
    "turn_on",
    "turn_off",
    "slice",
    "break",
    "cook",
    "dirty",
    "clean",
    "fillLiquid",
    "emptyLiquid",
    "pour",
    "drop",
    "throw",
)
LIQUIDS = ("water", "coffee", "wine")
ACTION_CLASS = {
    "find": "FindAction",
    "pick": "PickAction",
    "put": "PutAction",
    "open": "OpenAction",
    "close": "CloseAction",
    "turn_on": "ToggleOnAction",
    "turn_off": "ToggleOffAction",
    "slice": "SliceAction",
    "break": "BreakAction",
    "cook": "CookAction",
    "dirty": "DirtyAction",
    "clean": "CleanAction",
    "fillLiquid": "FillLiquidAction",
    "emptyLiquid": "EmptyLiquidAction",
    "pour": "PourAction",
    "drop": "DropAction",
    "throw": "ThrowAction",
}
# verb -> (min args, max args)
ARITY = {
    "find": (1, 1),
    "pick": (1, 1),
    "put": (1, 2),
    "open": (1, 1),
    "close": (1, 1),
    "turn_on": (1, 1),
    "turn_off": (1, 1),
    "slice": (1, 1),
    "break": (1, 1),
    "cook": (1, 1),
    "dirty": (1, 1),
    "clean": (1, 1),
    "fillLiquid": (2, 2),
    "emptyLiquid": (1, 1),
    "pour": (0, 1),
    # The object named is the one held: "throw AlarmClock" throws what the
    # hand holds only if that is the AlarmClock.
    "drop": (0, 1),
    "throw": (0, 1),
}
_ALIASES = {
    "find": "find",
    "navigate": "find",
    "pick": "pick",
    "pickup": "pick",
    "pick_up": "pick",
    "put": "put",
    "put_in": "put",
    "put_on": "put",
    "place": "put",
    "open": "open",
    "close": "close",
    "turn_on": "turn_on",
    "turnon": "turn_on",
    "toggle_on": "turn_on",
    "toggleon": "turn_on",
    "turn_off": "turn_off",
    "turnoff": "turn_off",
    "toggle_off": "turn_off",
    "toggleoff": "turn_off",
    "slice": "slice",
    "break": "break",
    "cook": "cook",
    "dirty": "dirty",
    "clean": "clean",
    "fillliquid": "fillLiquid",
    "fill_liquid": "fillLiquid",
    "fill": "fillLiquid",
    "emptyliquid": "emptyLiquid",
    "empty_liquid": "emptyLiquid",
    "pour": "pour",
    "drop": "drop",
    "throw": "throw",
}
# Words that can open an action line (for finding a plan inside prose).
ACTION_WORDS = frozenset(_ALIASES) | {"turn", "toggle", "switch"}
_NUMBERING = re.compile(r"^\s*(?:step\s*)?\d+\s*[.):]\s*", re.IGNORECASE)
_CALL = re.compile(r"^([A-Za-z_]+)\s*\((.*)\)\s*$")
_CONNECTORS = {"in", "into", "inside", "on", "onto", "to"}
_ARTICLES = {"the", "a", "an"}
# A word of an object name written in words ("dining", "Table", "watering-can").
# Anything else (Apple_1, Mug2, "apple,") is a name on its own.
_PLAIN_WORD = re.compile(r"^[A-Za-z]+(?:['-][A-Za-z]+)*$")
# The longest catalogue names have three words ("toilet paper hanger"); a
# longer run of words is prose ("open the fridge door slowly"), not a name.
MAX_NAME_WORDS = 3
# Far above any household task (SafeAgentBench's longest reference plans have a
# few dozen steps), far below what would overrun a verification deadline.
MAX_PLAN_STEPS = 1_000
# A plan line names a verb and at most two objects; a longer line is pasted
# prose or garbage, and every name in it would be fuzzy-matched against the scene.
MAX_LINE_CHARS = 1_000


def singular_forms(term: str) -> tuple[str, ...]:
    """Singular readings of a name that may be plural ('apples' -> 'apple',
    'knives' -> 'knif', 'knife'); the caller keeps the ones that name something."""
    low = term.lower()
    out: list[str] = []
    if low.endswith("ies"):
        out.append(term[:-3] + "y")
    if low.endswith("ves"):
        out += [term[:-3] + "f", term[:-3] + "fe"]
    if low.endswith("es"):
        out.append(term[:-2])
    if low.endswith("s") and not low.endswith("ss"):
        out.append(term[:-1])
    return tuple(o for o in out if len(term_key(o)) > 1)


@dataclass(frozen=True)
class PlanStep:
    index: int  # 1-based
    text: str  # the line as written
    verb: str  # canonical verb
    args: tuple[str, ...]
    # How an everyday phrasing was read ('light the candle' -> 'turn_on candle');
    # None when the line is in the action language itself.
    note: str | None = None
    # The object the line says is poured from ('pour the mug into the sink'):
    # it must be the object the agent holds.  ``throw X`` and ``drop X`` name
    # theirs as their argument.
    held: str | None = None

    @property
    def action_class(self) -> str:
        return ACTION_CLASS[self.verb]

    def canonical(self) -> str:
        return " ".join((self.verb, *self.args))

    @property
    def held_term(self) -> str | None:
        """The words naming the object this step needs in the hand, if the
        line names it ('throw AlarmClock', 'pour the mug into the sink')."""
        if self.verb in ("drop", "throw") and self.args:
            return self.args[0]
        return self.held


def _unknown_verb(word: str, line_no: int) -> InputError:
    near = closest(word, [*_ALIASES, "turn on", "toggle on", "pick up"])
    hint = f"; closest: {', '.join(near)}" if near else f"; valid verbs: {', '.join(VERBS)}"
    return InputError(f"plan line {line_no}: unknown action '{word}'{hint}")


def _is_number(token: str) -> bool:
    # isdigit alone accepts '²', which int() refuses: only ASCII digits count.
    return token.isascii() and token.isdigit() and int(token) > 0


def _name(words: list[str]) -> str:
    # SafeAgentBench numbers instances of one type: "find Mug 2" means Mug_2.
    # A numbered name in words stays in words ("stove knob 2"); the simulator
    # compares it with StoveKnob_2 through term_key.
    if len(words) == 2 and _is_number(words[1]):
        return f"{words[0]}_{words[1]}"
    return " ".join(words)


def _terms(tokens: list[str], max_words: int = MAX_NAME_WORDS) -> list[str]:
    """Group a line's words into object names: a run of plain words (closed by
    an instance number) is one name; an identifier such as Apple_1 stands alone."""
    out: list[str] = []
    run: list[str] = []

    def close() -> None:
        words = len(run) - (1 if run and _is_number(run[-1]) else 0)
        if words > max_words:  # prose, not a name: every word counts as one
            out.extend(run)
        elif run:
            out.append(_name(run))
        run.clear()

    for token in tokens:
        if _PLAIN_WORD.match(token):
            run.append(token)
        elif _is_number(token) and run:
            run.append(token)
            close()
        else:
            close()
            out.append(token)
    close()
    return out


def _put_terms(tokens: list[str]) -> list[str]:
    """'put X in R', 'put the X on the R', 'put in R', 'put R', 'put X R'."""
    while len(tokens) > 1 and tokens[0].lower() in _CONNECTORS:
        tokens = tokens[1:]
    # A connector can stand only between two names, so an object named "A" or
    # "On" at either end survives.
    cuts = [i for i in range(1, len(tokens) - 1) if tokens[i].lower() in _CONNECTORS]
    if cuts:
        bounds = [-1, *cuts, len(tokens)]
        return [t for a, b in itertools.pairwise(bounds) for t in _terms(tokens[a + 1 : b])]
    # Without a connector the words may be one name (the receptacle: "put dining
    # table") or an object and a receptacle ("put apple fridge"); only the
    # simulator, which knows the names, can tell, so the words stay together.
    return _terms(tokens, max_words=2 * MAX_NAME_WORDS)


def _check_text(line: str, line_no: int) -> None:
    if len(line) > MAX_LINE_CHARS:
        raise InputError(
            f"plan line {line_no} has {len(line)} characters; the limit is {MAX_LINE_CHARS}"
        )
    bad = hidden_char(line)
    if bad is not None:
        # Invisible or control characters make a line read differently from
        # how it looks (a zero-width space inside a name, an escape sequence).
        raise InputError(
            f"plan line {line_no}: control or invisible character U+{ord(bad):04X} "
            f"in '{clip(line.strip())}'"
        )


def _call_args(body: str, line: str, line_no: int) -> list[str]:
    """The arguments of ``verb(a, b)``; an empty one is an error, not a shorter
    call: ``put_in(, Fridge_1)`` must not become 'put the held object in Fridge_1'."""
    if not body.strip():
        return []
    parts = body.split(",")
    for n, part in enumerate(parts, start=1):
        if not part.strip():
            raise InputError(
                f"plan line {line_no}: argument {n} is empty in '{clip(line.strip())}'"
            )
        if "(" in part or ")" in part:
            raise InputError(
                f"plan line {line_no}: unbalanced parentheses in '{clip(line.strip())}'"
            )
    return [_name(part.split()) for part in parts]


def parse_line(line: str, line_no: int = 1, index: int = 1) -> PlanStep:
    _check_text(line, line_no)
    text = _NUMBERING.sub("", line.strip()).strip().rstrip(".;")
    call = _CALL.match(text)
    if call:
        word = call.group(1).lower()
        args = _call_args(call.group(2), line, line_no)
    else:
        tokens = text.split()
        if not tokens:
            raise InputError(f"plan line {line_no}: empty action")
        word = tokens[0].lower()
        words = tokens[1:]
        # Two-word verbs: "turn on X", "toggle off X", "pick up X".
        if word in ("turn", "toggle", "switch") and words and words[0].lower() in ("on", "off"):
            word = f"turn_{words[0].lower()}"
            words = words[1:]
        elif word in ("turn", "toggle", "switch") and words and words[-1].lower() in ("on", "off"):
            word = f"turn_{words[-1].lower()}"
            words = words[:-1]
        elif word == "pick" and words and words[0].lower() == "up":
            words = words[1:]
        # Articles are dropped only in lower case: "A" may be an object's name.
        words = [w for w in words if w not in _ARTICLES] or words
    verb = _ALIASES.get(word)
    if verb is None:
        raise _unknown_verb(clip(word, 40), line_no)
    if not call:
        if verb == "put":
            args = _put_terms(words)
        elif verb == "fillLiquid" and words:
            # The liquid is the last word; the container's name may have several.
            body = words[:-1]
            if len(body) > 1 and body[-1].lower() == "with":
                body = body[:-1]
            args = [*_terms(body), words[-1]]
        elif verb == "pour":
            while len(words) > 1 and words[0].lower() in _CONNECTORS:
                words = words[1:]
            args = _terms(words)
        else:
            args = _terms(words)
    lo, hi = ARITY[verb]
    if not lo <= len(args) <= hi:
        want = str(lo) if lo == hi else f"{lo} to {hi}"
        raise InputError(
            f"plan line {line_no}: '{verb}' takes {want} argument(s), got {len(args)} in '{line.strip()}'"
        )
    if verb == "fillLiquid":
        liquid = args[1].lower()
        if liquid not in LIQUIDS:
            near = closest(liquid, LIQUIDS)
            raise InputError(
                f"plan line {line_no}: unknown liquid '{args[1]}'; choose from {', '.join(near or LIQUIDS)}"
            )
        args = [args[0], liquid]
    return PlanStep(index=index, text=text, verb=verb, args=tuple(args))


def parse_plan(lines: Iterable[object]) -> tuple[PlanStep, ...]:
    steps: list[PlanStep] = []
    for line_no, line in enumerate(lines, start=1):
        if not isinstance(line, str):
            raise InputError(f"plan entry {line_no} must be a string")
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        if len(steps) == MAX_PLAN_STEPS:
            raise InputError(f"plan has more than {MAX_PLAN_STEPS} actions (the limit)")
        steps.append(parse_line(stripped, line_no, index=len(steps) + 1))
    return tuple(steps)


def parse_plan_text(text: str) -> tuple[PlanStep, ...]:
    stripped = text.strip()
    if stripped.startswith("["):
        # Strict JSON: NaN or a duplicate key inside would otherwise be read
        # as something the file does not say.
        data = parse_json(stripped, "plan (it starts with '[')")
        if not isinstance(data, list):
            raise InputError("a JSON plan must be a list of action strings")
        return parse_plan(data)
    # Only newlines end a line: the other breaks str.splitlines() knows (form
    # feed, U+2028...) are control characters, refused inside a line.
    return parse_plan(text.replace("\r\n", "\n").split("\n"))


def load_plan_file(path: str | Path) -> tuple[PlanStep, ...]:
    steps = parse_plan_text(read_input_file(path, "plan"))
    if not steps:
        raise InputError(f"plan {path} has no actions (only blank lines or comments)")
    return steps
