"""Prompts for the apprentice, and reading a plan out of its reply.

The prompt texts live as files in ``virf/planner/prompts`` so that they can be
read and changed without touching code.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import cache
from importlib import resources

from virf.errors import InputError
from virf.kb.scene import Scene
from virf.kb.tbox import Vocabulary
from virf.sim.plan import ACTION_WORDS, PlanStep, parse_line

REFUSAL = "TASK_ABORT"


@cache
def template(name: str) -> str:
    """A prompt file from the package (``apprentice``, ``actions``, ...)."""
    path = resources.files("virf.planner").joinpath("prompts", f"{name}.txt")
    return path.read_text(encoding="utf-8")


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
    """What a reply contains: plan steps, lines that are not actions, a refusal."""

    steps: tuple[PlanStep, ...]
    unreadable: tuple[str, ...]
    refused: bool


_FENCE = re.compile(r"^\s*```")
_BULLET = re.compile(r"^\s*(?:[-*•]\s+|\(?\d+\s*[.):]\s*|step\s*\d+\s*[.:)-]\s*)", re.I)
_MARKUP = re.compile(r"\*+|`+")


def read_plan(reply: str) -> ReadPlan:
    """Pull the plan out of a reply that may wrap it in markdown or prose.

    A line counts as an action when its first word is an action verb; other
    lines inside a code block, or numbered or bulleted lines outside one, are
    reported as unreadable (they look like steps but are not actions).  Prose
    around the plan is ignored.
    """
    refused = REFUSAL in reply
    steps: list[PlanStep] = []
    unreadable: list[str] = []
    in_code = False
    for raw in reply.splitlines():
        if _FENCE.match(raw):
            in_code = not in_code
            continue
        listed = bool(_BULLET.match(raw))
        line = _MARKUP.sub("", _BULLET.sub("", raw, count=1)).strip().rstrip(".;,")
        if not line or line == REFUSAL:
            continue
        first = line.split()[0].lower().split("(")[0].replace("-", "_")
        if first in ACTION_WORDS:
            try:
                steps.append(parse_line(line, len(steps) + 1, len(steps) + 1))
            except InputError as exc:
                unreadable.append(f"{line}: {str(exc).split(': ', 1)[-1]}")
        elif in_code or listed:
            unreadable.append(line)
    return ReadPlan(tuple(steps), tuple(unreadable), refused)


def unreadable_message(read: ReadPlan) -> str:
    listed = "\n".join(f"- {u}" for u in read.unreadable)
    return (
        "Your reply contains lines that are not executable actions:\n"
        f"{listed}\n"
        "Reply again with the whole plan, one action per line, using only these actions:\n"
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
