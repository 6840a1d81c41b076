"""ask_user_and_update: the user's answers to an UNKNOWN report's questions,
and the scene they update.

The questions are the report's own (:class:`virf.schema.Question`, built by
:mod:`virf.verify.questions`); nothing here builds questions. An answer that
settles one turns into scene data: a stated material or fill state, a
receptacle whose listed contents are complete, a confirmed fact, the
instance a plan's word means, a missing object and where it is, or the
removal of the contradictory fact the user says is wrong. The loop then
rebuilds the scene with the one scene reader (``build_scene``) and verifies
the same plan again. A question nobody settles stays open: the plan cannot
be approved on it (fail closed).

Answers come from a policy:

* the CLI asks interactively;
* the API takes any callable;
* batch runs read an answers file (JSON object ``{key: answer}``) or deny
  everything.

Question keys and the answers that settle them:

* ``material:X``: a material name (``Glass``);
* ``fill:X``: ``yes`` or ``no`` (does X hold liquid?);
* ``contents:contains:X`` or ``contents:supports:X``: ``yes`` (the listed
  contents are complete: the list is closed for X, and X leaves the scene's
  ``unknown_contents``);
* ``confirm:S P O``: ``yes``, or ``no`` for a fact the scene marked
  ``assumed`` (the entry is removed);
* ``which:TERM``: one of the instances offered (``Bowl_2``);
* ``where:TERM``: a receptacle of the scene, optionally after ``in`` or
  ``on`` (``on CounterTop_1``);
* ``contradiction:...``: the wrong fact, by its number in the list or its text;
* ``requirement:N`` and ``other:...`` cannot be settled by scene data: their
  reports go back to the apprentice.
"""

from __future__ import annotations

import copy
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from pydantic import ConfigDict, TypeAdapter, ValidationError

from virf.errors import InputError, clip, closest, read_json_file
from virf.ontology.tbox import Vocabulary
from virf.schema import Fact, Provenance, Question, QuestionKind, Report, Triple
from virf.verify.questions import materials, parse_triple_text
from virf.world.scene import build_scene

__all__ = [
    "SETTLEABLE",
    "AnswerPolicy",
    "Answers",
    "Question",
    "Settled",
    "Update",
    "answers_file",
    "apply_answers",
    "check_answer",
    "deny",
    "read_answers",
    "settle",
]

YES = {"yes", "y", "true", "confirm", "confirmed", "filled", "full"}
NO = {"no", "n", "false", "deny", "denied", "empty"}
# Answers that leave a question open, whatever its kind.
OPEN = {"", "none", "unknown", "?", "skip", "absent", "n/a", "dont know", "don't know"}
# Kinds an answer can turn into scene data; the others are reported back.
SETTLEABLE: frozenset[QuestionKind] = frozenset(
    {"material", "fill", "contents", "confirm", "which", "where", "contradiction"}
)
_PLACE = re.compile(r"^(?:(in|inside|into|on|onto)\s+)?(?:the\s+)?(\S+)$", re.IGNORECASE)

Answers = Mapping[str, str]
AnswerPolicy = Callable[[Sequence[Question]], Answers]


def deny(questions: Sequence[Question]) -> Answers:
    """The batch default: nobody answers, so nothing assumed becomes known."""
    return {}


# Keys are question keys, open-ended: the file's only shape is strings to strings.
_ANSWERS: Final = TypeAdapter(dict[str, str], config=ConfigDict(strict=True))


def read_answers(path: str | Path) -> dict[str, str]:
    """The ``{key: answer}`` object of an answers file."""
    p = Path(path)
    data = read_json_file(p, "answers")
    try:
        return _ANSWERS.validate_python(data)
    except ValidationError:
        raise InputError(
            f'answers file {p} must be a JSON object of strings, e.g. {{"fill:Pot_1": "no"}}'
        ) from None


def answers_file(path: str | Path) -> AnswerPolicy:
    """A policy reading ``{key: answer}`` from a JSON file (keys as above)."""
    fixed = read_answers(path)

    def policy(questions: Sequence[Question]) -> Answers:
        return {q.key: fixed[q.key] for q in questions if q.key in fixed}

    return policy


def check_answer(q: Question, answer: str, vocab: Vocabulary) -> str | None:
    """``answer`` to ``q`` in canonical form, or None when it leaves ``q``
    open. An answer that cannot be used (an unknown material, an option not
    offered) is an InputError naming the closest valid choices, so a person
    can be asked again."""
    text = " ".join(answer.split())
    low = text.lower()
    if q.kind not in SETTLEABLE or low in OPEN:
        return None
    if q.kind in ("fill", "contents", "confirm"):
        if low in YES:
            return "yes"
        if low in NO:
            return "no"
        raise InputError(f"answer to '{q.key}': '{clip(text)}' is not yes or no")
    if low in NO:
        return None
    if q.kind == "material":
        choices = materials(vocab)
        return _choose(q, text, choices, "material", choices[:8])
    if q.kind == "which":
        return _choose(q, text, q.options, "choice", q.options)
    if q.kind == "where":
        m = _PLACE.match(text)
        if m is None:
            raise InputError(
                f"answer to '{q.key}': say where it is, like 'on {_example(q)}' or 'in {_example(q)}'"
            )
        prep, place = m[1], m[2]
        if q.options:  # the scene's receptacles, as the verifier saw them
            place = _choose(q, place, q.options, "receptacle", q.options)
        return f"{_preposition(prep)} {place}" if prep else place
    # contradiction: the wrong fact, by number or by text
    if low.isascii() and low.isdigit() and 1 <= int(low) <= len(q.options):
        return q.options[int(low) - 1]
    for option in q.options:
        t = parse_triple_text(option)
        forms = {option.lower(), Fact.from_triple(t).render().lower()} if t else {option.lower()}
        if low in forms:
            return option
    numbered = "; ".join(f"{i}) {o}" for i, o in enumerate(q.options, start=1))
    raise InputError(f"answer to '{q.key}': name the wrong fact by its number or text: {numbered}")


def _choose(
    q: Question, answer: str, choices: Sequence[str], what: str, fallback: Sequence[str]
) -> str:
    by_lower = {c.lower(): c for c in choices}
    found = by_lower.get(answer.lower())
    if found is None:
        near = closest(answer, choices) or list(fallback)
        listed = f"; choose from {', '.join(near)}" if near else ""
        raise InputError(f"answer to '{q.key}': unknown {what} '{clip(answer)}'{listed}")
    return found


def _example(q: Question) -> str:
    return q.options[0] if q.options else "CounterTop_1"


def _preposition(word: str) -> str:
    return "in" if word.lower() in ("in", "inside", "into") else "on"


@dataclass(frozen=True)
class Update:
    scene: dict[str, Any]
    applied: tuple[str, ...]  # keys of questions the answers settled
    unsettled: tuple[str, ...]


def apply_answers(
    scene: Mapping[str, Any], questions: Sequence[Question], answers: Answers, vocab: Vocabulary
) -> Update:
    """The scene data with every settling answer written into it (the input
    is not modified)."""
    data: dict[str, Any] = copy.deepcopy(dict(scene))
    applied, unsettled = [], []
    for q in questions:
        raw = answers.get(q.key)
        value = check_answer(q, raw if isinstance(raw, str) else "", vocab)
        if value is not None and _settle(data, q, value, vocab):
            applied.append(q.key)
        else:
            unsettled.append(q.key)
    return Update(data, tuple(applied), tuple(unsettled))


# Every round applies all the answers the open questions have, so another
# round is needed only when an answer brings up a new question; the planner's
# loop has the same bound (virf.planner.loop.MAX_ROUNDS).
MAX_SETTLE_ROUNDS: Final = 8


@dataclass(frozen=True)
class Settled:
    """A plan verified with a fixed set of answers (``virf verify --answers``)."""

    report: Report  # the last verification: of ``scene``
    scene: dict[str, Any]  # the scene data with every settling answer written in
    # Each question an answer settled, with the answer in canonical form
    # ('yes', 'no', 'Plastic'), in the order they were settled.
    answered: tuple[tuple[Question, str], ...]
    asked: frozenset[str]  # every question key a report asked
    rounds: int

    def unused(self, answers: Mapping[str, str]) -> list[str]:
        """Keys of ``answers`` that no report asked."""
        return [k for k in answers if k not in self.asked]


def settle(
    scene: Mapping[str, Any],
    verify: Callable[[Mapping[str, Any]], Report],
    answers: Answers,
    vocab: Vocabulary,
) -> Settled:
    """Verify ``scene``, apply the answers its questions have, verify again,
    and so on while the answers settle new questions (at most
    ``MAX_SETTLE_ROUNDS`` rounds; a question is settled at most once).  An
    answer that cannot be used is an InputError naming the closest choices;
    a question without an answer stays open (fail closed)."""
    data: dict[str, Any] = copy.deepcopy(dict(scene))
    report = verify(data)
    answered: list[tuple[Question, str]] = []
    asked: set[str] = {q.key for q in report.questions}
    done: set[str] = set()
    rounds = 0
    while report.status == "UNKNOWN" and rounds < MAX_SETTLE_ROUNDS:
        open_ = [
            q
            for q in report.questions
            if q.kind in SETTLEABLE and q.key not in done and q.key in answers
        ]
        if not open_:
            break
        update = apply_answers(data, open_, answers, vocab)
        if not update.applied:
            break
        rounds += 1
        for q in open_:
            if q.key in update.applied:
                value = check_answer(q, answers[q.key], vocab)
                assert value is not None  # it settled the question
                answered.append((q, value))
                done.add(q.key)
        data = update.scene
        report = verify(data)
        asked.update(q.key for q in report.questions)
    return Settled(report, data, tuple(answered), frozenset(asked), rounds)


def _settle(data: dict[str, Any], q: Question, value: str, vocab: Vocabulary) -> bool:
    """Write one checked answer into ``data``; False when it settles nothing."""
    declared = _declared(data)
    if q.kind == "material":
        if q.subject not in declared:  # made by the plan, not the scene's to state
            return False
        _drop_marker(data, q.subject, "UnknownMaterial")
        _drop_assumed_materials(data, q.subject, vocab)
        _assert(data, q.subject, "hasMaterial", value)
        return True
    if q.kind == "fill":
        if q.subject not in declared:
            return False
        _drop_marker(data, q.subject, "UnknownFillState")
        state = "FilledWithLiquidState" if value == "yes" else "EmptyState"
        _assert(data, q.subject, "hasState", state)
        return True
    if q.kind == "contents":
        if value != "yes" or q.subject not in declared:  # 'no' does not say what else is there
            return False
        rel = q.key.split(":")[1]
        closed: list[Any] = list(data.get("closed_world", []))
        unknown: list[Any] = list(data.get("unknown_contents", []))
        if q.subject in unknown:
            # unknown_contents overrides closed_world for both of an object's
            # lists, so dropping the object from it also closes the list the
            # user was not asked about, when the scene closes that one.
            other, kind = (
                ("supports", "SurfaceReceptacle")
                if rel == "contains"
                else ("contains", "ContainerReceptacle")
            )
            if vocab.any_is_a(_classes(declared[q.subject], vocab), kind) and (
                other in closed or f"{other}:{q.subject}" in closed
            ):
                return False
            # The user said the listed contents are complete, so they are no
            # longer unknown; left in the list, the answer would change nothing.
            data["unknown_contents"] = [u for u in unknown if u != q.subject]
        if rel not in closed and f"{rel}:{q.subject}" not in closed:
            closed.append(f"{rel}:{q.subject}")
        data["closed_world"] = closed
        return True
    if q.kind == "confirm":
        if q.fact is None or q.fact.subject not in declared:
            return False
        if value == "no":
            # What the scene itself marked as assumed (perception unsure of
            # it) is taken back; an assumption of the reader's own (what an
            # open-world object's name suggests, a knob controlling the
            # burners) is written down as denied, so that it is not made again.
            if _retract(data, q.fact, vocab, Provenance.ASSUMED):
                return True
            return _deny(data, q.fact, vocab)
        if q.fact.predicate == "rdf:type":
            data["instances"] = [
                *data.get("instances", []),
                {"class_name": q.fact.object, "instance_name": q.fact.subject},
            ]
        else:
            _assert(data, q.fact.subject, q.fact.predicate, q.fact.object)
        return True
    if q.kind == "which":
        if value not in declared:
            return False
        # The plan's word as written: the scene reader and the simulator
        # compare words by term_key, so spelling variants share the choice.
        data["referents"] = {**data.get("referents", {}), q.subject: value}
        return True
    if q.kind == "where":
        return _place_missing(data, q, value, vocab)
    if q.kind == "contradiction":
        t = parse_triple_text(value)
        return t is not None and _retract(data, t, vocab)
    return False


def _deny(data: dict[str, Any], fact: Triple, vocab: Vocabulary) -> bool:
    """Record that ``fact``, an assumption of the scene reader, is false."""
    try:
        if build_scene(data, vocab).facts.get(Fact.from_triple(fact)) is not Provenance.ASSUMED:
            return False
    except InputError:
        return False
    text = f"{fact.subject} {fact.predicate} {fact.object}"
    denied: list[Any] = list(data.get("denied", []))
    if text not in denied:
        denied.append(text)
    data["denied"] = denied
    return True


def _declared(data: Mapping[str, Any]) -> dict[str, list[str]]:
    """Instance name -> its declared class names, in scene order."""
    out: dict[str, list[str]] = {}
    for inst in data.get("instances", []):
        if isinstance(inst, dict) and "instance_name" in inst:
            out.setdefault(str(inst["instance_name"]), []).append(str(inst.get("class_name", "")))
    return out


def _assert(data: dict[str, Any], subject: str, prop: str, obj: str) -> None:
    data["assertions"] = [
        *data.get("assertions", []),
        {"subject": subject, "property": prop, "object": obj},
    ]


def _drop_marker(data: dict[str, Any], subject: str, marker: str) -> None:
    """The scene's own 'unknown' marker goes once the user has said what it is."""
    data["assertions"] = [
        a
        for a in data.get("assertions", [])
        if not (
            isinstance(a, dict)
            and a.get("subject") == subject
            and str(a.get("object", "")).lower() == marker.lower()
        )
    ]


def _drop_assumed_materials(data: dict[str, Any], subject: str, vocab: Vocabulary) -> None:
    """Materials the scene only assumed for ``subject`` go once the user says
    what it is made of."""
    data["assertions"] = [
        a
        for a in data.get("assertions", [])
        if not (
            isinstance(a, dict)
            and a.get("subject") == subject
            and a.get("assumed") is True
            and vocab.canonical_property(str(a.get("property", ""))) == "hasMaterial"
        )
    ]


def _place_missing(data: dict[str, Any], q: Question, value: str, vocab: Vocabulary) -> bool:
    """Declare the missing object where the user says it is."""
    prep, _, place = value.rpartition(" ")
    declared = _declared(data)
    receptacles = {
        name: classes
        for name, classes in declared.items()
        if vocab.any_is_a(_classes(classes, vocab), "Receptacle")
    }
    by_lower = {name.lower(): name for name in receptacles}
    found = by_lower.get(place.lower())
    if found is None:
        near = closest(place, receptacles) or sorted(receptacles)[:8]
        listed = f"; choose from {', '.join(near)}" if near else "; the scene declares none"
        raise InputError(
            f"answer to '{q.key}': '{clip(place)}' is not a receptacle of the scene{listed}"
        )
    named = _named_type(q.subject, vocab)
    if named is None:  # a word that names no object type: nothing to declare
        return False
    cls, name = named
    if name is None:
        n = 1
        while f"{cls}_{n}" in declared:
            n += 1
        name = f"{cls}_{n}"
    elif name in declared:
        return False
    classes = _classes(receptacles[found], vocab)
    surface = vocab.any_is_a(classes, "SurfaceReceptacle")
    container = vocab.any_is_a(classes, "ContainerReceptacle")
    # The receptacle's kind decides; the user's 'in' or 'on' only breaks a tie
    # for receptacles that are both (a sink holds things and has a rim).
    inside = not surface or (container and prep == "in")
    data["instances"] = [*data.get("instances", []), {"class_name": cls, "instance_name": name}]
    _assert(data, name, "isInside" if inside else "isOn", found)
    return True


def _classes(names: Sequence[str], vocab: Vocabulary) -> set[str]:
    return {c for c in (vocab.canonical_class(n) for n in names) if c is not None}


def _named_type(term: str, vocab: Vocabulary) -> tuple[str, str | None] | None:
    """The object type a plan's word names, and the instance when the word is
    numbered (``Mug_2``, SafeAgentBench's ``Mug 2``)."""
    cls = vocab.canonical_class(re.sub(r"[\s_]+", "", term))
    if cls is not None and vocab.is_a(cls, "PhysicalObject"):
        return cls, None
    numbered = re.fullmatch(r"(.+?)[\s_]*(\d+)", term)
    if numbered:
        cls = vocab.canonical_class(re.sub(r"[\s_]+", "", numbered[1]))
        if cls is not None and vocab.is_a(cls, "PhysicalObject") and int(numbered[2]) > 0:
            return cls, f"{cls}_{int(numbered[2])}"
    return None


def _retract(
    data: dict[str, Any],
    wrong: Triple,
    vocab: Vocabulary,
    provenance: Provenance = Provenance.SCENE,
) -> bool:
    """Remove the scene entry that states ``wrong`` (with ``provenance``).

    The entry is found by the scene reader itself: it is the one without
    which the rebuilt scene no longer holds the fact, so inverse properties
    (isInside, isOn, isHeldBy), synonyms (isMadeOf), value words and
    material classes (a MetallicObject is made of metal) all match as the
    reader reads them. A fact the scene does not state (a default, or one
    the plan produced) cannot be retracted."""
    fact = Fact.from_triple(wrong)
    try:
        if build_scene(data, vocab).facts.get(fact) is not provenance:
            return False
    except InputError:
        return False
    names = {fact.subject, fact.object}
    declared = _declared(data)
    for field in ("assertions", "instances"):
        entries: list[Any] = list(data.get(field, []))
        for i, entry in enumerate(entries):
            if not isinstance(entry, dict):
                continue
            if field == "instances":
                # Only a second declaration can go; the first one is the object.
                who = str(entry.get("instance_name", ""))
                if who not in names or len(declared.get(who, [])) < 2:
                    continue
            elif not names & {str(entry.get("subject")), str(entry.get("object"))}:
                continue
            trial = {**data, field: entries[:i] + entries[i + 1 :]}
            try:
                rebuilt = build_scene(trial, vocab)
            except InputError:
                continue
            if fact not in rebuilt.facts:
                data[field] = trial[field]
                return True
    return False
