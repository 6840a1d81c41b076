"""Learning from answers: what a user confirmed about an object the knowledge
base did not know becomes a candidate class, reviewed like a drafted rule.

A scene may name an object by a class the knowledge base lacks
(``HairDryer_1`` of class ``HairDryer``): the scene reader keeps it as an
open-world object and assumes what WordNet suggests of the word, so a hazard
that needs one of those guesses is UNKNOWN with a yes/no question
(:mod:`virf.world.scene`).  The answers settle that scene only.  This module
turns them into knowledge for later scenes:

* yes to ``X hasProperty P``  ->  ``Word SubClassOf hasProperty value P``;
* yes to ``X rdf:type C``  ->  ``Word SubClassOf C`` (its parent);
* a material (``material:X``, or yes to ``X hasMaterial M``)  ->
  ``Word SubClassOf hasMaterial value M``;
* the parent ``PhysicalObject`` (``MaterialEntity`` for a word WordNet reads
  as a person) when no type was confirmed.

A 'no' gives no axiom; it is kept in the candidate's evidence, with every
answer (who, when, the scene and a digest of it, the question and the
answer), so the reviewer sees it.  Answers that disagree between two objects
of the same class give no axiom either.

The candidate goes through the workspace like any other (origin "answer"):
the same normalisation and HermiT checks (parse, consistency,
satisfiability), the effect preview (the bundled examples, a benchmark file,
and the scene it was learned from, verified again without the answers) with
``virf kb test`` run on top, the review page, and a person's decision.  Only
an accepted class enters the workspace's modules, so nothing learned changes
a verdict before a person accepts it.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Final

from virf.authoring.models import (
    CheckReport,
    Learned,
    LearnedAnswer,
    Preview,
)
from virf.errors import InputError, clip, hidden_char, printable
from virf.migrations import now
from virf.names import term_key
from virf.ontology.lexicon import propose
from virf.ontology.tbox import Vocabulary
from virf.schema import FactKind, Provenance, Question
from virf.world.open_world import HYPOTHESIS_WORDS
from virf.world.scene import build_scene

if TYPE_CHECKING:
    from virf.authoring.workspace import Workspace

CATEGORY: Final = "Learned class"
# A learned class's name: the word as written, in UpperCamelCase.
CLASS_NAME: Final = re.compile(r"^[A-Z][A-Za-z0-9]{1,80}$")
# What an answer can say about a class (other facts are about one object).
CLASS_PREDICATES: Final = frozenset({"hasProperty", "hasMaterial"})
TYPE_PREDICATE: Final = "rdf:type"
# The reader's 'not known' markers are not guesses about the class.
MARKERS: Final = frozenset({"UnknownMaterial"})


def class_name(word: str) -> str:
    """The class a word written in a scene names: ``hair dryer``,
    ``hair_dryer`` and ``HairDryer`` are all ``HairDryer``."""
    pieces = [p for p in re.split(r"[\s_\-.]+", word.strip()) if p]
    name = "".join(p[:1].upper() + p[1:] for p in pieces)
    if not CLASS_NAME.match(name):
        raise InputError(
            f"cannot learn the class '{clip(word)}': a class name is a word in UpperCamelCase "
            "(letters and digits, at least two), e.g. HairDryer"
        )
    return name


def scene_digest(data: Mapping[str, Any]) -> str:
    """SHA-256 of the scene data (its JSON with sorted keys, no spaces)."""
    text = json.dumps(data, sort_keys=True, ensure_ascii=False, separators=(",", ":"))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


@dataclass(frozen=True)
class Source:
    """The scene and plan the answers were given for (before the answers)."""

    name: str
    data: Mapping[str, Any]
    plan: tuple[str, ...]

    @property
    def sha256(self) -> str:
        return scene_digest(self.data)


@dataclass
class _Group:
    """What the answers say about one class word, while it is collected."""

    name: str
    words: list[str] = field(default_factory=list)
    instances: list[str] = field(default_factory=list)
    base: str = "PhysicalObject"
    readings: list[str] = field(default_factory=list)
    # (predicate, object) -> instance -> True (yes) / False (no)
    said: dict[tuple[str, str], dict[str, bool]] = field(default_factory=dict)
    assumed: dict[tuple[str, str], set[str]] = field(default_factory=dict)
    answers: list[tuple[Question, str, tuple[str, str]]] = field(default_factory=list)


@dataclass(frozen=True)
class Lesson:
    """A class to learn: its name, what the answers confirmed, and the
    answers themselves."""

    name: str
    words: tuple[str, ...]
    instances: tuple[str, ...]
    reading: str
    parents: tuple[str, ...]
    restrictions: tuple[str, ...]  # 'hasProperty value P', 'hasMaterial value M'
    answers: tuple[LearnedAnswer, ...]
    unconfirmed: tuple[str, ...]
    # Whether an answer confirmed something of the class (the default parent
    # alone is no lesson).
    confirmed: bool

    @property
    def axiom(self) -> str:
        """Its superclasses as one Manchester class expression: what the
        candidate proposes as ``Name SubClassOf <axiom>``."""
        parts = [*self.parents, *(f"({r})" for r in self.restrictions)]
        return " and ".join(parts)

    @property
    def axioms(self) -> tuple[str, ...]:
        return tuple(f"{self.name} SubClassOf {p}" for p in (*self.parents, *self.restrictions))


def _said_words(predicate: str, obj: str) -> str:
    if predicate == TYPE_PREDICATE:
        return f"a {obj}"
    if predicate == "hasMaterial":
        return f"made of {obj}"
    return HYPOTHESIS_WORDS.get(obj, obj)


def lessons(
    scene_data: Mapping[str, Any],
    answered: Sequence[tuple[Question, str]],
    vocab: Vocabulary,
    *,
    scene_name: str = "scene",
) -> list[Lesson]:
    """What ``answered`` (questions settled, with their canonical answers)
    says about each class of the scene's open-world objects.  A class
    nothing was confirmed about is left out."""
    scene = build_scene(scene_data, vocab, name=scene_name)
    groups: dict[str, _Group] = {}
    owner: dict[str, _Group] = {}
    for ind, word in sorted(scene.open_world.items()):
        name = class_name(word)
        known = vocab.canonical_class(name) or vocab.term_by_key(term_key(name))
        if known is not None:
            raise InputError(
                f"cannot learn '{clip(word)}' ({ind}) as the class {name}: the knowledge base "
                f"already names {known}; write the class as {known} in the scene"
            )
        g = groups.setdefault(name, _Group(name))
        proposal = propose(word)
        if word not in g.words:
            g.words.append(word)
            g.readings.append(proposal.describe())
        g.instances.append(ind)
        if proposal.person:
            g.base = "MaterialEntity"
        owner[ind] = g
        for f, p in scene.facts.items():
            if p is not Provenance.ASSUMED or f.subject != ind:
                continue
            if f.kind is FactKind.TYPE:
                g.assumed.setdefault((TYPE_PREDICATE, f.object), set()).add(ind)
            elif f.predicate in CLASS_PREDICATES and f.object not in MARKERS:
                g.assumed.setdefault((f.predicate, f.object), set()).add(ind)
    for q, value in answered:
        subject = q.fact.subject if q.fact is not None else q.subject
        group = owner.get(subject)
        if group is None:
            continue
        if q.kind == "material":
            key = ("hasMaterial", value)
            yes = True
        elif q.kind == "confirm" and q.fact is not None:
            predicate = TYPE_PREDICATE if q.fact.predicate in ("rdf:type", "type") else None
            predicate = predicate or (
                q.fact.predicate if q.fact.predicate in CLASS_PREDICATES else None
            )
            if predicate is None:
                continue  # a fact about this object alone (where it is, what it touches)
            key = (predicate, q.fact.object)
            yes = value == "yes"
        else:
            continue  # fill, contents, which, where: about this object, not its class
        group.said.setdefault(key, {})[subject] = yes
        group.answers.append((q, value, key))
    out = []
    for name in sorted(groups):
        lesson = _lesson(groups[name], vocab)
        if lesson.confirmed:
            out.append(lesson)
    return out


def _lesson(g: _Group, vocab: Vocabulary) -> Lesson:
    materials_said: dict[str, set[str]] = {}
    for (pred, obj), by in g.said.items():
        if pred == "hasMaterial":
            for ind, said_yes in by.items():
                if said_yes:
                    materials_said.setdefault(ind, set()).add(obj)
    effect: dict[tuple[str, str], str] = {}
    parents: list[str] = []
    restrictions: list[str] = []
    for key in sorted(g.said):
        pred, obj = key
        by = g.said[key]
        yes = sorted(i for i, v in by.items() if v)
        no = sorted(i for i, v in by.items() if not v)
        if pred == "hasMaterial":
            # Another object of the class said to be made of something else
            # disagrees as much as a 'no' does.
            no = sorted(set(no) | {i for i, ms in materials_said.items() if obj not in ms})
        if yes and no:
            effect[key] = (
                f"no axiom: {', '.join(yes)} said yes but {', '.join(no)} no"
                if pred != "hasMaterial"
                else f"no axiom: {', '.join(yes)} is made of {obj} but {', '.join(no)} is not"
            )
        elif yes:
            if pred == TYPE_PREDICATE:
                parent = vocab.canonical_class(obj) or obj
                parents.append(parent)
                effect[key] = f"{g.name} SubClassOf {parent}"
            else:
                restriction = f"{pred} value {obj}"
                restrictions.append(restriction)
                effect[key] = f"{g.name} SubClassOf {restriction}"
        else:
            effect[key] = "no axiom: answered no (kept as evidence for the reviewer)"
    answers = tuple(
        LearnedAnswer(
            key=q.key, question=q.text, subject=q.subject, answer=value, effect=effect[key]
        )
        for q, value, key in g.answers
    )
    confirmed_parents = tuple(dict.fromkeys(parents))

    def why(key: tuple[str, str]) -> str:
        said = g.said.get(key)
        if said is None:
            return "not asked"
        return "the answers disagree" if any(said.values()) else "answered no"

    unconfirmed = tuple(
        f"{_said_words(*key)} ({why(key)})"
        for key in sorted(g.assumed)
        if not effect.get(key, "").startswith(g.name)
    )
    return Lesson(
        name=g.name,
        words=tuple(g.words),
        instances=tuple(g.instances),
        reading="; ".join(dict.fromkeys(g.readings)),
        parents=confirmed_parents or (g.base,),
        restrictions=tuple(restrictions),
        answers=answers,
        unconfirmed=unconfirmed,
        confirmed=bool(restrictions or confirmed_parents),
    )


# ---------------------------------------------------------------------- candidates
def document(lesson: Lesson, source: Source, who: str, when: str) -> dict[str, Any]:
    """What a learned candidate stores as its draft: the lesson and its
    evidence (the view the reviewer sees) and the scene as given."""
    learned = Learned(
        class_name=lesson.name,
        words=lesson.words,
        instances=lesson.instances,
        reading=lesson.reading,
        axioms=lesson.axioms,
        answers=lesson.answers,
        who=who,
        when=when,
        scene_name=source.name,
        scene_sha256=source.sha256,
        plan=source.plan,
        unconfirmed=lesson.unconfirmed,
    )
    return {"learned": learned.model_dump(mode="json"), "scene": dict(source.data)}


def rule_of(lesson: Lesson, source: Source, who: str) -> dict[str, Any]:
    """The candidate's rule fields (what the queue and the terminal show of
    every candidate), for a learned class."""
    words = ", ".join(f"'{w}'" for w in lesson.words)
    return {
        "name": lesson.name,
        "definition": lesson.axiom,
        "kind": "class",
        "category": CATEGORY,
        "danger_level": "",
        "description": (
            f"{lesson.name}: a kind of thing the knowledge base did not know ({words} in scene "
            f"{source.name}), learned from {who}'s answers about {', '.join(lesson.instances)}."
        ),
        "safety_warning": "",
        "trigger_reason": "",
        "suggestion": "",
        "check_at": "",
    }


# ---------------------------------------------------------------------- the whole step
MAX_WHO: Final = 100


def check_who(who: str) -> str:
    """Who answered, on one line: it is kept as evidence and written into
    the module when the class is accepted."""
    flat = " ".join(who.split())
    if not flat:
        raise InputError("say who answered (--who NAME)")
    bad = hidden_char(flat)
    if bad is not None:
        raise InputError(f"the name of who answered contains the hidden character {printable(bad)}")
    if len(flat) > MAX_WHO:
        raise InputError(f"the name of who answered is longer than {MAX_WHO} characters")
    return flat


@dataclass(frozen=True)
class Outcome:
    """A learned candidate, as stored and checked."""

    id: int
    lesson: Lesson
    check: CheckReport | None
    preview: Preview | None


def learn(
    ws: Workspace,
    source: Source,
    answered: Sequence[tuple[Question, str]],
    who: str,
    *,
    check_it: bool = True,
    preview: bool = True,
    examples: Any = None,
    tasks: Any = None,
) -> tuple[list[Outcome], list[str]]:
    """Store a candidate for every class of ``source``'s open-world objects
    that the answers confirmed something about; check and preview each.
    Returns the candidates and, for the open-world classes left out, why."""
    who = check_who(who)
    vocab = ws.tbox().vocabulary
    found = lessons(source.data, answered, vocab, scene_name=source.name)
    scene = build_scene(source.data, vocab, name=source.name)
    learned_names = {lesson.name for lesson in found}
    skipped = sorted(
        {
            f"{class_name(w)}: no answer confirmed anything about it"
            for w in scene.open_world.values()
            if class_name(w) not in learned_names
        }
    )
    when = now()
    ids = ws.propose_learned(
        [
            (
                lesson.name,
                lesson.axiom,
                rule_of(lesson, source, who),
                document(lesson, source, who, when),
            )
            for lesson in found
        ],
        who,
    )
    out = []
    for cid, lesson in zip(ids, found, strict=True):
        report = ws.check(cid) if check_it else None
        shown = None
        if preview and report is not None and report.passed:
            shown = ws.preview(cid, tasks=tasks, examples=examples)
        out.append(Outcome(cid, lesson, report, shown))
    return out, skipped


def answered_from_transcript(
    turns: Sequence[Any], vocab: Vocabulary
) -> tuple[list[tuple[Question, str]], tuple[str, ...]]:
    """The questions a ``virf plan`` run's answers settled, with the answers
    in canonical form, and the plan they were asked about (the last such):
    read from the run's transcript (questions, then answers, turns)."""
    from virf.planner.questions import check_answer

    out: list[tuple[Question, str]] = []
    asked: list[Question] = []
    plan: tuple[str, ...] = ()
    current: tuple[str, ...] = ()
    for turn in turns:
        if turn.kind == "proposal":
            current = tuple(line for line in turn.text.splitlines() if line.strip())
        elif turn.kind == "questions" and turn.data:
            asked = [Question.model_validate(q) for q in turn.data.get("questions", [])]
        elif turn.kind == "answers" and turn.data:
            given = json.loads(turn.text)
            settled = set(turn.data.get("settled", []))
            for q in asked:
                if q.key in settled and isinstance(given.get(q.key), str):
                    value = check_answer(q, given[q.key], vocab)
                    if value is not None:
                        out.append((q, value))
                        plan = current
            asked = []
    return out, plan


def summary(outcomes: Sequence[Outcome], skipped: Sequence[str], workspace: str) -> list[str]:
    """What learning did, in lines for a person (the terminal)."""
    lines: list[str] = []
    for o in outcomes:
        lines.append(f"learned: candidate {o.id}, {o.lesson.name} SubClassOf {o.lesson.axiom}")
        for a in o.lesson.answers:
            lines.append(f"  '{a.question}' {a.answer}: {a.effect}")
        if o.check is not None:
            errors = [i for i in o.check.items if i.severity == "error"]
            warnings = [i for i in o.check.items if i.severity == "warning" and not i.ok]
            verdict = "PASSED" if o.check.passed else f"FAILED ({errors[0].message})"
            lines.append(f"  checks {verdict}")
            lines += [f"  warning: {w.message}" for w in warnings]
        if o.preview is not None:
            p = o.preview
            where = f", {p.tasks} tasks of {p.tasks_file}" if p.tasks_file else ""
            lines.append(
                f"  preview over {p.examples} examples{where} and {p.scenes} scene(s): "
                f"{len(p.changes)} change(s)"
            )
            lines += [f"    {c.item}: {c.before} -> {c.after}" for c in p.changes]
            if p.kb_test:
                lines.append(f"  {p.kb_test}")
            lines += [f"    new failure: {f}" for f in p.kb_test_failures]
        lines.append(
            f"  it applies to later scenes once accepted: virf kb decide {o.id} accept "
            f"-w {workspace} (or review it: virf kb review -w {workspace})"
        )
    lines += [f"not learned: {s}" for s in skipped]
    if not outcomes and not skipped:
        lines.append("nothing learned: the scene has no object of a class the knowledge base lacks")
    return lines
