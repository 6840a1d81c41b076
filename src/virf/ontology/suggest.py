"""Which class a user meant: the classes nearest a name, by meaning and by spelling.

A scene names its objects' classes, and a user who does not know the
vocabulary guesses (``HairDryer``, ``Toddler``).  Spelling alone answers a
typo (``Mircowave``) but not a guess; meaning answers the guess: the
all-MiniLM-L6-v2 embedding of the name's words (``hair dryer``) against those
of the classes' names (``vacuum cleaner``), as the perception catalogue
matches a camera's labels.

Shared by the unknown-class error (:meth:`Vocabulary.require_class`) and
``virf kb classes --search``.  Pure Python: the embedder loads only when a
ranking is asked for (an error being raised, a search), and the class vectors
are computed once per process for each vocabulary.
"""

from __future__ import annotations

import difflib
import functools
import re
from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from virf.errors import EnvironmentProblem, InputError, clip, closest, unknown_term
from virf.names import name_words, term_key

if TYPE_CHECKING:
    from virf.embed import Matrix
    from virf.ontology.tbox import Vocabulary

# What `virf kb classes` lists, each kind the classes under one root.
CLASS_KINDS: Final = ("object", "agent", "state", "material", "property")
KIND_ROOTS: Final = {
    "object": "PhysicalObject",
    "agent": "Agent",
    "state": "State",
    "material": "Material",
    "property": "Attribute",
}
# Classes a scene does not name: findings, preconditions, plan steps.
_NOT_LISTED: Final = ("UnsafeStateConcept", "PreconditionViolation", "Action")
# A spelling counts when it is this close (difflib ratio of the compacted
# names): 'mircowave' is 0.89 from 'microwave', 'toastr' 0.92 from
# 'toaster'; unrelated names of similar length reach 0.5-0.6 ('hairdryer' and
# 'chair' 0.57), as high as a fair match by meaning.
SPELLING_FLOOR: Final = 0.8
# A scene's class is nearly always an object type or a person: the error's
# neighbours by meaning come from these kinds (its spelling neighbours, as
# before, from every class).
_ERROR_KINDS: Final = ("object", "agent")
# Below this cosine a neighbour by meaning is noise, not a suggestion: a typo's
# meaning neighbours ('mircowave': Microwave 0.41, DishSponge 0.35, Fruit 0.34).
MEANING_FLOOR: Final = 0.4
_SEARCH_WORDS: Final = re.compile(r"[a-z0-9 ]{1,40}")


Kinds = str | Iterable[str] | None


def check_kind(kind: str | None) -> str | None:
    """``kind`` itself, or an InputError naming the kinds there are."""
    if kind is not None and kind not in CLASS_KINDS:
        raise unknown_term("kind", kind, CLASS_KINDS)
    return kind


def _kinds(kinds: Kinds) -> frozenset[str]:
    """One kind, several, or (None) every kind, each checked."""
    if kinds is None:
        return frozenset(CLASS_KINDS)
    if isinstance(kinds, str):
        kinds = (kinds,)
    return frozenset(k for k in kinds if check_kind(k) is not None)


def class_kind(vocab: Vocabulary, cls: str) -> str | None:
    """The kind of ``cls`` (see :data:`CLASS_KINDS`), or None for a class a
    scene does not name (a rule, a precondition, an action, the upper
    ontology) and for a synonym."""
    if cls in vocab.class_synonyms or cls in vocab.uscs or cls in vocab.preconditions:
        return None
    if any(vocab.is_a(cls, root) for root in _NOT_LISTED):
        return None
    for kind, root in KIND_ROOTS.items():
        if vocab.is_a(cls, root):
            return kind
    return None


def listed_classes(vocab: Vocabulary, kinds: Kinds = None) -> tuple[str, ...]:
    """The classes of one kind, of several, or of every kind, by name."""
    wanted = _kinds(kinds)
    return tuple(c for c in sorted(vocab.classes) if class_kind(vocab, c) in wanted)


@dataclass(frozen=True)
class Ranked:
    """A class and how near it is to a query: ``score`` is the larger of the
    two similarities, the spelling one counting from :data:`SPELLING_FLOOR`."""

    name: str
    kind: str
    score: float
    meaning: float  # cosine of the sentence embeddings
    spelling: float  # difflib ratio of the compacted names


@functools.lru_cache(maxsize=8)
def _class_vectors(names: tuple[str, ...]) -> Matrix:
    from virf.embed import default_embedder

    return default_embedder().encode([name_words(n) for n in names])


def _spelling(term: str, name: str) -> float:
    return difflib.SequenceMatcher(None, term_key(term), term_key(name)).ratio()


def rank_classes(query: str, vocab: Vocabulary, kinds: Kinds = None) -> list[Ranked]:
    """Every listed class of ``kinds`` (one kind, several, None for all), the
    nearest to ``query`` first (ties by name).  EnvironmentProblem when the
    embedding model is not installed."""
    from virf.embed import default_embedder

    names = listed_classes(vocab, kinds)
    if not names:
        return []
    text = query[:200]
    meaning = _class_vectors(names) @ default_embedder().encode([name_words(text)])[0]
    out = []
    for name, m in zip(names, meaning.tolist(), strict=True):
        spelling = _spelling(text, name)
        score = max(m, spelling) if spelling >= SPELLING_FLOOR else m
        kind = class_kind(vocab, name) or ""
        out.append(Ranked(name, kind, round(score, 4), round(m, 4), round(spelling, 4)))
    out.sort(key=lambda r: (-r.score, r.name))
    return out


def _has_words(term: str) -> bool:
    return re.search(r"[a-z]{2}", name_words(term)) is not None


def _by_meaning(term: str, vocab: Vocabulary, n: int, kinds: Kinds) -> tuple[str, ...]:
    """The classes nearest ``term`` by meaning alone, those at least
    :data:`MEANING_FLOOR` near; none for a term without words, or when the
    model is missing (the caller still has the spelling neighbours)."""
    if not _has_words(term):
        return ()
    try:
        ranked = rank_classes(term, vocab, kinds)
    except (EnvironmentProblem, OSError):
        return ()
    ranked.sort(key=lambda r: (-r.meaning, r.name))
    return tuple(r.name for r in ranked[:n] if r.meaning >= MEANING_FLOOR)


def suggest_classes(
    term: str, vocab: Vocabulary, n: int = 3, kind: str | None = None
) -> tuple[str, ...]:
    """The ``n`` classes a user most likely meant by ``term``: spelling
    neighbours (a typo) and meaning neighbours (a guess) ranked together, as
    ``virf kb classes --search`` ranks them.  Without the embedding model,
    the spelling neighbours alone."""
    try:
        return tuple(r.name for r in rank_classes(term, vocab, kind)[:n])
    except (EnvironmentProblem, OSError):
        return tuple(closest(term[:200], listed_classes(vocab, kind), n))


def unknown_class(term: str, vocab: Vocabulary) -> InputError:
    """The one-line error for a class the vocabulary does not have: the
    closest classes by meaning and by spelling, and the command that lists
    them all."""
    meaning = _by_meaning(term, vocab, 3, _ERROR_KINDS)
    spelling = closest(term[:200], vocab.classes)
    hints = []
    if meaning:
        hints.append(f"closest by meaning: {', '.join(meaning)}")
    if spelling:
        hints.append(f"{'by' if meaning else 'closest by'} spelling: {', '.join(spelling)}")
    words = name_words(term)
    search = f"'{words}'" if _has_words(term) and _SEARCH_WORDS.fullmatch(words) else "WORDS"
    hints.append(f"`virf kb classes --search {search}` lists more")
    return InputError(f"unknown class '{clip(term)}'; {'; '.join(hints)}")
