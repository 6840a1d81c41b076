"""Prompts for the apprentice, and reading a plan out of its reply.

The prompt texts live as files in ``virf/planner/prompts`` so that they can be
read and changed without touching code.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass

from virf.errors import InputError
from virf.files import read_prompt
from virf.ontology.tbox import Vocabulary
from virf.render.feedback import CHOICE
from virf.world.plan import ACTION_WORDS, PlanStep, check_plan_size, parse_line
from virf.world.scene import Scene

REFUSAL = "TASK_ABORT"


def template(name: str) -> str:
    """A prompt file of the planner (``apprentice``, ``actions``, ...)."""
    return read_prompt("virf.planner", f"{name}.txt")


def scene_objects(scene: Scene) -> str:
    """One line per object: its name and asserted classes (the robot excluded)."""
    lines = []
    for ind in scene.order:
        if ind == scene.agent:
            continue
        lines.append(f"- {ind} ({', '.join(sorted(scene.objects[ind]))})")
    return "\n".join(lines)


def apprentice_prompt(instruction: str, scene: Scene, rules: str = "") -> str:
    """The apprentice's task prompt; ``rules`` is appended for the +Rules methods."""
    block = f"\nSAFETY RULES YOU MUST RESPECT\n{rules}\n" if rules else ""
    return template("apprentice").format(
        instruction=instruction.strip(),
        objects=scene_objects(scene),
        actions=template("actions").rstrip(),
        rules=block,
    )


@dataclass(frozen=True)
class ReadPlan:
    """What a reply contains: plan steps, lines that are not actions, a refusal,
    and ``problem``: why the plan as a whole cannot be used (it breaks a plan
    limit, :func:`virf.world.plan.check_plan_size`), in the words ``virf
    verify`` uses for a plan file; its steps are then dropped."""

    steps: tuple[PlanStep, ...]
    unreadable: tuple[str, ...]
    refused: bool
    problem: str | None = None
    # 'USE n' with no plan: the reply takes the n-th checked correction the
    # feedback offered; only the loop knows which plan that is.
    choice: int | None = None


_FENCE = re.compile(r"^\s*```")
_BULLET = re.compile(r"^\s*(?:[-*•]\s+|\(?\d+\s*[.):]\s*|step\s*\d+\s*[.:)-]\s*)", re.I)
_MARKUP = re.compile(r"\*+|`+")
_CHOICE = re.compile(rf"{CHOICE}\s+(\d+)", re.IGNORECASE)


def read_plan(reply: str) -> ReadPlan:
    """Pull the plan out of a reply that may wrap it in markdown or prose.

    * A reply that is a JSON list of strings is the plan.
    * A line is an action when it parses as one. A line that looks like a
      step but is not an action (it sits in a code block, or is numbered or
      bulleted) is reported as unreadable.
    * Any other prose is ignored, even when it starts with a verb ("Put
      simply, here is the plan:"), unless the reply holds no action at all:
      then such lines are reported, so the apprentice learns what failed.
    * A line that is ``TASK_ABORT`` refuses the task, whatever else the reply
      says (fail closed).
    * A plan over the limits of a plan file (more than ``MAX_PLAN_STEPS``
      actions) is no plan: no step is kept, and ``problem`` says why.
    """
    listed_json = _json_plan(reply)
    if listed_json is not None:
        reply = "\n".join(listed_json)
    refused = False
    steps: list[PlanStep] = []
    unreadable: list[str] = []
    attempts: list[str] = []
    in_code = False
    problem: str | None = None
    choice: int | None = None
    for raw in reply.splitlines():
        if _FENCE.match(raw):
            in_code = not in_code
            continue
        listed = bool(_BULLET.match(raw))
        line = _MARKUP.sub("", _BULLET.sub("", raw, count=1)).strip().rstrip(".;,")
        if not line:
            continue
        if line.strip('"') == REFUSAL:
            refused = True
            continue
        chose = _CHOICE.fullmatch(line.strip('"'))
        if chose is not None:
            choice = int(chose.group(1)) if choice is None else choice  # the first one said
            continue
        if problem is not None:
            continue  # only a refusal still counts
        first = line.split()[0].lower().split("(")[0].replace("-", "_")
        try:
            if first not in ACTION_WORDS:
                raise InputError("not an action")
            previous = steps[-1] if steps else None
            step = parse_line(line, len(steps) + 1, len(steps) + 1, previous)
        except InputError as exc:
            why = f"{line}: {str(exc).split(': ', 1)[-1]}"
            if in_code or listed:
                unreadable.append(why)
            elif first in ACTION_WORDS:
                attempts.append(why)  # prose, unless the reply holds no plan at all
            continue
        try:
            check_plan_size(len(steps) + 1)
        except InputError as exc:
            problem = str(exc)
            continue
        steps.append(step)
    if problem is not None:
        return ReadPlan((), (), refused, problem)
    if steps:
        # A plan of its own wins over a choice the same reply also made.
        return ReadPlan(tuple(steps), tuple(unreadable), refused)
    if choice is not None:
        return ReadPlan((), (), refused, choice=choice)
    return ReadPlan((), (*unreadable, *attempts), refused)


def _json_plan(reply: str) -> list[str] | None:
    text = reply.strip()
    if text.startswith("```"):
        text = text.strip("`").removeprefix("json").strip()
    if not text.startswith("["):
        return None
    try:
        data = json.loads(text)
    except (json.JSONDecodeError, RecursionError, ValueError):
        return None
    if isinstance(data, list) and all(isinstance(x, str) for x in data):
        return data
    return None


_PLAN_MARKER = re.compile(r"^[\s*#_]*plan[\s*_]*:[\s*_]*$", re.IGNORECASE | re.MULTILINE)


def read_after_plan_marker(reply: str) -> ReadPlan:
    """The plan of a reasoning reply: what follows its last ``PLAN:`` line
    (any case, with or without markdown), or the whole reply without one."""
    marks = list(_PLAN_MARKER.finditer(reply))
    return read_plan(reply[marks[-1].end() :] if marks else reply)


def unreadable_message(read: ReadPlan) -> str:
    if read.problem is not None:
        problem = f"Your plan cannot be used: {read.problem}.\n"
    elif read.unreadable:
        listed = "\n".join(f"- {u}" for u in read.unreadable)
        problem = f"Your reply contains lines that are not executable actions:\n{listed}\n"
    else:
        problem = "Your reply contains no plan.\n"
    return (
        problem
        + "Reply again with the whole plan, one action per line, using only these actions:\n"
        f"{template('actions').rstrip()}\n"
        f'If no safe plan is possible, reply with exactly "{REFUSAL}".'
    )


def render_rules(vocab: Vocabulary) -> str:
    """The whole ontology as numbered natural-language rules (the "+Rules"
    methods), generated from the axioms' annotations, never hand-copied."""
    lines = ["Hazards that must never arise:"]
    n = 0
    for usc in sorted(vocab.uscs.values(), key=lambda u: (u.category, u.id)):
        n += 1
        lines.append(
            f"{n}. [{usc.category}, {usc.danger_level}] {usc.description} "
            f"{usc.safety_warning} To avoid it: {usc.suggestion}"
        )
    lines.append("Background knowledge these rules rely on:")
    for ax in sorted(vocab.background.values(), key=lambda b: b.id):
        if ax.description:
            n += 1
            lines.append(f"{n}. {ax.description}")
    return "\n".join(lines)
