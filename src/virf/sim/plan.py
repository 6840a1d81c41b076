"""Parse plans written in SafeAgentBench's action language.

Accepted per line (case-insensitive verbs; blank lines and ``#`` comments are
skipped, leading numbering such as ``3.`` or ``3)`` is ignored)::

    find X            pick X | pick up X       put R | put X in R | put X on R
    open X            close X                  turn_on X | turn on X | toggle on X
    turn_off X ...    slice X   break X   cook X   dirty X   clean X
    fillLiquid X water|coffee|wine             emptyLiquid X
    pour | pour X     drop      throw

and the function style of the paper's walkthrough: ``put_in(Pot_1, Microwave_1)``.
A plan file may also be a JSON list of such strings.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

from virf.errors import InputError, clip, closest, read_input_file

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
    "drop": (0, 0),
    "throw": (0, 0),
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
_CONNECTORS = {"in", "into", "on", "onto", "to"}
_ARTICLES = {"the", "a", "an"}


def term_key(term: str) -> str:
    """How a plan's object name is compared with types and instances: case,
    spaces, underscores and hyphens do not matter ('stove knob 2', 'StoveKnob_2')."""
    return re.sub(r"[\s_\-]+", "", term).lower()


@dataclass(frozen=True)
class PlanStep:
    index: int  # 1-based
    text: str  # the line as written
    verb: str  # canonical verb
    args: tuple[str, ...]

    @property
    def action_class(self) -> str:
        return ACTION_CLASS[self.verb]

    def canonical(self) -> str:
        return " ".join((self.verb, *self.args))


def _unknown_verb(word: str, line_no: int) -> InputError:
    near = closest(word, [*_ALIASES, "turn on", "toggle on", "pick up"])
    hint = f"; closest: {', '.join(near)}" if near else f"; valid verbs: {', '.join(VERBS)}"
    return InputError(f"plan line {line_no}: unknown action '{word}'{hint}")


def parse_line(line: str, line_no: int = 1, index: int = 1) -> PlanStep:
    text = _NUMBERING.sub("", line.strip()).strip().rstrip(".;")
    call = _CALL.match(text)
    if call:
        word = call.group(1).lower()
        args = [a.strip() for a in call.group(2).split(",") if a.strip()]
    else:
        tokens = text.split()
        if not tokens:
            raise InputError(f"plan line {line_no}: empty action")
        word = tokens[0].lower()
        args = tokens[1:]
        # Two-word verbs: "turn on X", "toggle off X", "pick up X".
        if word in ("turn", "toggle", "switch") and args and args[0].lower() in ("on", "off"):
            word = f"turn_{args[0].lower()}"
            args = args[1:]
        elif word in ("turn", "toggle", "switch") and args and args[-1].lower() in ("on", "off"):
            word = f"turn_{args[-1].lower()}"
            args = args[:-1]
        elif word == "pick" and args and args[0].lower() == "up":
            args = args[1:]
    verb = _ALIASES.get(word)
    if verb is None:
        raise _unknown_verb(clip(word, 40), line_no)
    # SafeAgentBench numbers instances of one type: "find Mug 2" means Mug_2.
    merged: list[str] = []
    for a in args:
        if a.isdigit() and int(a) > 0 and merged and not merged[-1].isdigit():
            merged[-1] = f"{merged[-1]}_{a}"
        else:
            merged.append(a)
    args = merged
    if verb == "put" and not call:
        # "put X in R", "put the X into the R", "put in R": drop connecting words,
        # but only where a connector can stand, so an object named "A" survives.
        # Articles are dropped only in lower case: "A" may be an object's name.
        args = [a for a in args if a not in _ARTICLES] or args
        while len(args) > 2 and args[-2].lower() in _CONNECTORS:
            args = [*args[:-2], args[-1]]
        while len(args) > 1 and args[0].lower() in _CONNECTORS:
            args = args[1:]
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


def parse_plan(lines: list[str]) -> tuple[PlanStep, ...]:
    steps: list[PlanStep] = []
    for line_no, line in enumerate(lines, start=1):
        if not isinstance(line, str):
            raise InputError(f"plan entry {line_no} must be a string")
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        steps.append(parse_line(stripped, line_no, index=len(steps) + 1))
    return tuple(steps)


def parse_plan_text(text: str) -> tuple[PlanStep, ...]:
    stripped = text.strip()
    if stripped.startswith("["):
        try:
            data = json.loads(stripped)
        except json.JSONDecodeError as exc:
            raise InputError(
                f"plan looks like JSON but is not valid: {exc.msg} at line {exc.lineno}"
            ) from None
        except (RecursionError, ValueError):
            raise InputError("plan looks like JSON but is nested too deeply or malformed") from None
        if not isinstance(data, list):
            raise InputError("a JSON plan must be a list of action strings")
        return parse_plan(data)
    return parse_plan(text.splitlines())


def load_plan_file(path: str | Path) -> tuple[PlanStep, ...]:
    steps = parse_plan_text(read_input_file(path, "plan"))
    if not steps:
        raise InputError(f"plan {path} has no actions (only blank lines or comments)")
    return steps
