"""The questions behind an UNKNOWN verdict, built once, as typed data.

The verifier calls one builder per kind of open point (an unknown marker or
open-world assumption in a proof, an ambiguous or missing object, a
contradictory scene, an unreadable requirement). The report carries the
questions; the planner's loop, the CLI and the JSON output use them as they
are, and :mod:`virf.planner.questions` turns answers into scene data.

Keys are stable (answers files are keyed by them): ``material:X``,
``fill:X``, ``contents:contains:X`` / ``contents:supports:X``,
``confirm:S P O``, ``which:TERM``, ``where:TERM``, ``contradiction:FACTS``,
``requirement:N`` and ``other:RULE:X``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence

from virf.ontology.tbox import UnsafeStateConcept, Vocabulary
from virf.schema import Fact, FactKind, Question, QuestionKind, Triple
from virf.world.open_world import HYPOTHESIS_WORDS

YES_NO = ("yes", "no")
# The epistemic markers a scene (or VIRF's defaults) puts on an object whose
# material or fill state nobody knows, and the question each one raises.
MARKERS: dict[tuple[str, str], QuestionKind] = {
    ("hasMaterial", "UnknownMaterial"): "material",
    ("hasState", "UnknownFillState"): "fill",
    ("hasState", "UnknownContentsState"): "contents",
}
_MARKER_CLASS: dict[QuestionKind, str] = {
    "material": "UnknownMaterial",
    "fill": "UnknownFillState",
    "contents": "UnknownContentsState",
}


def materials(vocab: Vocabulary) -> tuple[str, ...]:
    """The materials an answer may name."""
    return tuple(
        sorted(i for i in vocab.individuals if vocab.is_a(i, "Material") and i != "UnknownMaterial")
    )


def triple_text(t: Triple) -> str:
    """A fact as one line ``S P O``, the form ``confirm:`` keys and
    contradiction options use (names never contain spaces)."""
    return f"{t.subject} {t.predicate} {t.object}"


def parse_triple_text(text: str) -> Triple | None:
    """Inverse of :func:`triple_text`; None when ``text`` is not one."""
    subject, _, rest = text.strip().partition(" ")
    closure = re.fullmatch(r"(\S+ only) (\{.*\})", rest)
    if closure:
        return Triple(subject=subject, predicate=closure[1], object=closure[2])
    predicate, _, obj = rest.partition(" ")
    if not (subject and predicate and obj) or " " in obj:
        return None
    return Triple(subject=subject, predicate=predicate, object=obj)


def fact_question(f: Fact, step: int, vocab: Vocabulary, text: str | None = None) -> Question:
    """The question that settles one marker or open-world assumption."""
    t = f.triple()

    def ask(key: str, kind: QuestionKind, default: str, options: tuple[str, ...]) -> Question:
        return Question(
            key=key,
            kind=kind,
            text=text or default,
            subject=f.subject,
            fact=t,
            options=options,
            step=step,
        )

    kind = MARKERS.get((f.predicate, f.object))
    # A material assumed rather than known (one of the materials a type's
    # instances may have, or a reading perception was unsure of) is settled
    # by saying what the object is made of, like the unknown-material marker.
    if kind == "material" or f.predicate == "hasMaterial":
        return ask(
            f"material:{f.subject}",
            "material",
            f"What material is {f.subject} made of?",
            materials(vocab),
        )
    if kind == "fill":
        return ask(f"fill:{f.subject}", "fill", f"Does {f.subject} hold any liquid?", YES_NO)
    if kind == "contents":
        return ask(
            f"contents:contains:{f.subject}",
            "contents",
            f"Is everything inside {f.subject} listed in the scene? "
            "The scene does not say its 'contains' list is complete.",
            YES_NO,
        )
    if f.kind is FactKind.CLOSURE:
        where = "in" if f.predicate == "contains" else "on"
        listed = ", ".join(f.members)
        claim = (
            f"only {listed} is {where} {f.subject}" if listed else f"nothing is {where} {f.subject}"
        )
        return ask(
            f"contents:{f.predicate}:{f.subject}",
            "contents",
            f"Is it true that {claim}? "
            f"The scene does not say its '{f.predicate}' list is complete.",
            YES_NO,
        )
    return ask(f"confirm:{triple_text(t)}", "confirm", _confirm_text(f), YES_NO)


def _confirm_text(f: Fact) -> str:
    """A yes-or-no question in words where the fact is a property or a type
    ('Is HairDryer_1 an electrical appliance?', 'Is Toddler_1 a child?')."""
    if f.predicate == "hasProperty":
        words = HYPOTHESIS_WORDS.get(f.object, f"'{f.object}'")
        return f"Is {f.subject} {words}?"
    if f.kind is FactKind.TYPE:
        noun = re.sub(r"(?<=[a-z])(?=[A-Z])", " ", f.object).lower()
        article = "an" if noun[:1] in "aeiou" else "a"
        return f"Is {f.subject} {article} {noun}?"
    return f"Please confirm: {f.render()}?"


def rule_questions(
    usc: UnsafeStateConcept,
    ind: str,
    facts: Sequence[Fact],
    assumed: Iterable[Fact],
    step: int,
    vocab: Vocabulary,
) -> list[Question]:
    """The questions behind an uncertain finding of ``usc`` on ``ind``, whose
    minimal support is ``facts`` (``assumed`` among them).

    A rule's own question (its ``question`` annotation) words the question
    about the marker its definition names; a rule naming both markers, or
    none, cannot say which typed question its text belongs to, so the typed
    questions keep their own wording and the rule's text stands alone only
    when no typed question covers what the rule asks."""
    markers = [f for f in facts if (f.predicate, f.object) in MARKERS]
    topics = {
        kind for kind, cls in _MARKER_CLASS.items() if re.search(rf"\b{cls}\b", usc.definition)
    }
    own = next(iter(topics)) if len(topics) == 1 else None
    out: dict[str, Question] = {}
    for f in (*markers, *assumed):
        kind = MARKERS.get((f.predicate, f.object))
        own_text = usc.question and kind is not None and kind == own
        text = usc.question.replace("{x}", f.subject) if own_text else None
        q = fact_question(f, step, vocab, text)
        out.setdefault(q.key, q)
    covered = any(q.kind in topics for q in out.values())
    if usc.question and not covered:
        x = markers[0].subject if markers else ind
        q = _other(usc, x, usc.question.replace("{x}", x), step)
        out.setdefault(q.key, q)
    elif not out:  # an UNKNOWN verdict always says what is open
        text = (
            f"VIRF cannot tell whether {ind} is safe here: {usc.trigger_reason}. "
            "What do you know about it?"
        )
        q = _other(usc, ind, text, step)
        out.setdefault(q.key, q)
    return list(out.values())


def _other(usc: UnsafeStateConcept, subject: str, text: str, step: int) -> Question:
    return Question(
        key=f"other:{usc.id}:{subject}", kind="other", text=text, subject=subject, step=step
    )


def which_question(step: int, action: str, term: str, candidates: Sequence[str]) -> Question:
    """A type word that fits several instances equally well."""
    options = " or ".join(candidates)
    return Question(
        key=f"which:{term}",
        kind="which",
        text=f"Step {step} ('{action}') says '{term}': do you mean {options}?",
        subject=term,
        options=tuple(candidates),
        step=step,
    )


def where_question(
    step: int, action: str, term: str, near: Sequence[str], receptacles: Sequence[str]
) -> Question:
    """An object the plan needs and the scene lacks; the options are the
    scene's receptacles (an answer may say ``in`` or ``on`` before one)."""
    hint = f" (closest in the scene: {', '.join(near)})" if near else ""
    return Question(
        key=f"where:{term}",
        kind="where",
        text=f"Step {step} ('{action}') needs '{term}', but the scene has none{hint}. Where is it?",
        subject=term,
        options=tuple(receptacles),
        step=step,
    )


def contradiction_question(step: int, facts: Sequence[Fact]) -> Question:
    """A minimal set of facts that cannot all hold; the answer names the wrong one."""
    listed = "; ".join(f.render() for f in facts)
    options = tuple(triple_text(f.triple()) for f in facts)
    return Question(
        key=f"contradiction:{'; '.join(options)}",
        kind="contradiction",
        text=f"The scene is contradictory: {listed}. Which of these is wrong?",
        subject=facts[0].subject if facts else "",
        options=options,
        step=step,
    )


def requirement_question(n: int, text: str, reason: str, step: int) -> Question:
    """A task requirement VIRF cannot read, so cannot check."""
    return Question(
        key=f"requirement:{n}",
        kind="requirement",
        text=f"VIRF cannot read the requirement '{text}' ({reason}). Does the plan satisfy it?",
        subject=text,
        step=step,
    )
