"""ask_user_and_update: the questions of an UNKNOWN report, the user's answers,
and the scene they update.

An UNKNOWN finding rests on open-world assumptions (the report lists them as
``assumed_facts``). Each assumption becomes one question with a stable key.
An answer that settles it turns into scene data: a stated material, a stated
fill state, a receptacle whose listed contents are complete, a confirmed fact.
The loop then rebuilds the scene and verifies the same plan again. An
assumption nobody settles stays unknown: the plan cannot be approved on it
(fail closed).

Answers come from a policy:

* the CLI asks interactively;
* the API takes any callable;
* batch runs read an answers file (JSON object ``{key: answer}``) or deny
  everything.

Question keys:

* ``material:X``, answered by a material name (``Glass``);
* ``fill:X``, answered ``yes`` or ``no``: does X hold liquid?
* ``contents:contains:X`` or ``contents:supports:X``, answered ``yes``: the
  listed contents are complete;
* ``confirm:S P O``, answered ``yes`` or ``no``.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from virf.errors import InputError, closest, read_json_file
from virf.kb.tbox import Vocabulary
from virf.schema import Report, Triple

Kind = Literal["material", "fill", "contents", "confirm"]
YES = {"yes", "y", "true", "confirm", "confirmed", "filled", "full"}
NO = {"no", "n", "false", "deny", "denied", "empty"}


@dataclass(frozen=True)
class Question:
    key: str
    kind: Kind
    text: str
    subject: str
    fact: Triple


def questions_from(report: Report) -> list[Question]:
    """One question per open-world assumption behind the report's findings,
    and per unknown-material or unknown-fill marker they rest on (a scene may
    state those markers itself)."""
    out: dict[str, Question] = {}
    for v in report.violations:
        markers = [t for t in v.triggering_facts if (t.predicate, t.object) in _MARKERS]
        for t in (*markers, *v.assumed_facts):
            q = _question(t)
            out.setdefault(q.key, q)
    return list(out.values())


_MARKERS = {("hasMaterial", "UnknownMaterial"), ("hasState", "UnknownFillState")}


def _question(t: Triple) -> Question:
    if t.predicate == "hasMaterial" and t.object == "UnknownMaterial":
        return Question(
            f"material:{t.subject}",
            "material",
            f"What material is {t.subject} made of?",
            t.subject,
            t,
        )
    if t.predicate == "hasState" and t.object == "UnknownFillState":
        return Question(
            f"fill:{t.subject}", "fill", f"Does {t.subject} hold any liquid? (yes/no)", t.subject, t
        )
    if t.predicate.endswith(" only"):
        rel = t.predicate.removesuffix(" only")
        where = "in" if rel == "contains" else "on"
        listed = t.object.strip("{}").strip()
        claim = (
            f"only {listed} is {where} {t.subject}" if listed else f"nothing is {where} {t.subject}"
        )
        return Question(
            f"contents:{rel}:{t.subject}",
            "contents",
            f"Is it true that {claim}? (yes/no)",
            t.subject,
            t,
        )
    return Question(
        f"confirm:{t.subject} {t.predicate} {t.object}",
        "confirm",
        f"Is it true that {t.subject} {t.predicate} {t.object}? (yes/no)",
        t.subject,
        t,
    )


Answers = Mapping[str, str]
AnswerPolicy = Callable[[Sequence[Question]], Answers]


def deny(questions: Sequence[Question]) -> Answers:
    """The batch default: nobody answers, so nothing assumed becomes known."""
    return {}


def answers_file(path: str | Path) -> AnswerPolicy:
    """A policy reading ``{key: answer}`` from a JSON file (keys as above)."""
    p = Path(path)
    data = read_json_file(p, "answers")
    if not isinstance(data, dict) or not all(
        isinstance(k, str) and isinstance(v, str) for k, v in data.items()
    ):
        raise InputError(
            f'answers file {p} must be a JSON object of strings, e.g. {{"fill:Pot_1": "no"}}'
        )
    fixed = dict(data)

    def policy(questions: Sequence[Question]) -> Answers:
        return {q.key: fixed[q.key] for q in questions if q.key in fixed}

    return policy


@dataclass(frozen=True)
class Update:
    scene: dict[str, Any]
    applied: tuple[str, ...]  # keys of questions the answers settled
    unsettled: tuple[str, ...]


def apply_answers(
    scene: Mapping[str, Any], questions: Sequence[Question], answers: Answers, vocab: Vocabulary
) -> Update:
    """The scene data with every settling answer written into it."""
    data = copy.deepcopy(dict(scene))
    assertions: list[Any] = list(data.get("assertions", []))
    closed: list[Any] = list(data.get("closed_world", []))
    applied, unsettled = [], []
    for q in questions:
        raw = answers.get(q.key)
        answer = raw.strip() if isinstance(raw, str) else ""
        low = answer.lower()
        if q.kind == "material" and answer and low not in NO:
            material = _material(answer, vocab, q)
            assertions = _without_marker(assertions, q.subject, "UnknownMaterial")
            assertions.append({"subject": q.subject, "property": "hasMaterial", "object": material})
        elif q.kind == "fill" and low in YES | NO:
            state = "FilledWithLiquidState" if low in YES else "EmptyState"
            assertions = _without_marker(assertions, q.subject, "UnknownFillState")
            assertions.append({"subject": q.subject, "property": "hasState", "object": state})
        elif q.kind == "contents" and low in YES:
            rel = q.key.split(":")[1]
            entry = f"{rel}:{q.subject}"
            if rel not in closed and entry not in closed:
                closed.append(entry)
        elif q.kind == "confirm" and low in YES:
            f = q.fact
            assertions.append({"subject": f.subject, "property": f.predicate, "object": f.object})
        else:
            unsettled.append(q.key)
            continue
        applied.append(q.key)
    data["assertions"] = assertions
    if closed:
        data["closed_world"] = closed
    return Update(data, tuple(applied), tuple(unsettled))


def _without_marker(assertions: list[Any], subject: str, marker: str) -> list[Any]:
    """The scene's own 'unknown' marker goes once the user has said what it is."""
    return [
        a
        for a in assertions
        if not (
            isinstance(a, dict)
            and a.get("subject") == subject
            and str(a.get("object", "")).lower() == marker.lower()
        )
    ]


def _material(answer: str, vocab: Vocabulary, q: Question) -> str:
    materials = sorted(
        i for i in vocab.individuals if vocab.is_a(i, "Material") and i != "UnknownMaterial"
    )
    by_lower = {m.lower(): m for m in materials}
    found = by_lower.get(answer.lower())
    if found is None:
        near = closest(answer, materials) or materials[:8]
        raise InputError(
            f"answer to '{q.key}': unknown material '{answer}'; choose from {', '.join(near)}"
        )
    return found
