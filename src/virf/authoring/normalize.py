"""Normalisation: each name of a drafted axiom matched to the TBox vocabulary.

In order: the exact name; a synonym or spelling variant the vocabulary knows
(case, separators, ``:synonym`` annotations, a plural); then the nearest
vocabulary entry by sentence-embedding similarity, if it reaches the
workspace's threshold.  A class name nothing matches becomes a proposed new
class with a parent; a relation or individual nothing matches is an error,
because the simulator gives meaning only to the relations it knows.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Final

from virf.authoring.models import CheckItem, TermChoice
from virf.names import name_words, term_key
from virf.ontology import manchester
from virf.ontology.tbox import Vocabulary

if TYPE_CHECKING:
    import numpy as np

DEFAULT_THRESHOLD: Final = 0.80
# Where a new class goes when neither the drafter nor the vocabulary says.
FALLBACK_PARENT: Final = "PhysicalObject"
ALTERNATIVES: Final = 3

Encoder = Callable[[Sequence[str]], "np.ndarray"]


@dataclass(frozen=True)
class Normalised:
    axiom: str  # Manchester, names prefixed with ':' (for OWLAPI)
    display: str  # the same with the vocabulary's short names (for people)
    terms: tuple[TermChoice, ...]
    new_classes: tuple[tuple[str, str], ...]  # (class, parent)
    problems: tuple[CheckItem, ...]

    @property
    def rename(self) -> dict[str, str]:
        return {t.term: t.chosen for t in self.terms}


class VocabularyIndex:
    """Embeddings of the vocabulary's names, cached on disk per vocabulary."""

    def __init__(self, vocab: Vocabulary, encode: Encoder, cache_dir: Path | None) -> None:
        import numpy as np

        self.vocab = vocab
        self._encode = encode
        self._np = np
        self.entries: dict[str, tuple[str, ...]] = {
            "class": tuple(sorted(c for c in vocab.classes if c not in vocab.class_synonyms)),
            "property": tuple(sorted(vocab.object_properties)),
            "individual": tuple(sorted(vocab.individuals)),
        }
        everything = sorted({n for names in self.entries.values() for n in names})
        key = hashlib.sha256("\n".join(everything).encode()).hexdigest()[:16]
        path = cache_dir / f"vocabulary-{key}.npy" if cache_dir is not None else None
        matrix = None
        if path is not None and path.is_file():
            try:
                loaded = np.load(path)
                if loaded.shape[0] == len(everything):
                    matrix = loaded
            except (OSError, ValueError):
                matrix = None  # a damaged cache is rebuilt
        if matrix is None:
            matrix = np.asarray(encode([name_words(n) for n in everything]), dtype=np.float32)
            if path is not None:
                try:
                    path.parent.mkdir(parents=True, exist_ok=True)
                    tmp = path.with_suffix(".tmp.npy")
                    np.save(tmp, matrix)
                    tmp.replace(path)
                except OSError:
                    pass  # only costs the next run an encoding
        row = {n: i for i, n in enumerate(everything)}
        self._rows = {role: [row[n] for n in names] for role, names in self.entries.items()}
        self._matrix = matrix

    def nearest(self, name: str, role: str, n: int = ALTERNATIVES) -> list[tuple[str, float]]:
        names = self.entries[role]
        if not names:
            return []
        query = self._np.asarray(self._encode([name_words(name)]), dtype=self._np.float32)[0]
        scores = self._matrix[self._rows[role]] @ query
        order = sorted(range(len(names)), key=lambda i: (-float(scores[i]), names[i]))[:n]
        return [(names[i], round(float(scores[i]), 4)) for i in order]


def _variant(name: str, vocab: Vocabulary, role: str) -> str | None:
    """The vocabulary's own name for a spelling of it, if any."""
    if role == "property":
        found = vocab.canonical_property(name)
        if found is None:
            lowered = {p.lower(): p for p in vocab.object_properties}
            found = lowered.get(name.lower())
            if found is not None:
                found = vocab.canonical_property(found)
        return found if found in vocab.object_properties else None
    candidates = [name]
    # English plurals: knives, batteries, dishes, cups.
    for plural, singular in (("ves", "fe"), ("ves", "f"), ("ies", "y"), ("es", ""), ("s", "")):
        if name.endswith(plural):
            candidates.append(name[: -len(plural)] + singular)
    for c in candidates:
        hit = vocab.canonical_class(c) if role == "class" else None
        if hit is None:
            by_key = vocab.term_by_key(term_key(c))
            if by_key is not None and (
                (role == "class" and by_key in vocab.classes)
                or (role == "individual" and by_key in vocab.individuals)
            ):
                hit = vocab.class_synonyms.get(by_key, by_key)
        if hit is not None:
            return hit
    return None


def normalise(
    axiom: str,
    vocab: Vocabulary,
    index: VocabularyIndex | None,
    *,
    declared_parents: Mapping[str, str] | None = None,
    threshold: float = DEFAULT_THRESHOLD,
    own_name: str | None = None,
) -> Normalised:
    """Match every name of ``axiom``; ``declared_parents`` are the drafter's
    ``subclassOf`` proposals for the classes it introduced."""
    declared_parents = dict(declared_parents or {})
    roles = manchester.names(axiom)
    choices: list[TermChoice] = []
    problems: list[CheckItem] = []
    new: list[str] = []
    for term, role in roles.items():
        if term == own_name:
            problems.append(
                CheckItem.error("normalisation", f"the definition of {term} uses {term} itself")
            )
            continue
        if role == "property" and term in vocab.data_properties:
            problems.append(
                CheckItem.error(
                    "normalisation",
                    f"'{term}' is a data property; a rule relates objects, states and "
                    "materials through object properties (hasState, hasMaterial, isNear...)",
                )
            )
            continue
        known = (
            vocab.classes
            if role == "class"
            else vocab.individuals
            if role == "individual"
            else vocab.object_properties
        )
        if term in known and term not in vocab.class_synonyms:
            choices.append(TermChoice(term=term, role=role, match="exact", chosen=term, score=1.0))
            continue
        variant = _variant(term, vocab, role)
        if variant is not None:
            choices.append(
                TermChoice(term=term, role=role, match="synonym", chosen=variant, score=1.0)
            )
            continue
        near = index.nearest(term, role) if index is not None else []
        if near and near[0][1] >= threshold:
            choices.append(
                TermChoice(
                    term=term,
                    role=role,
                    match="similar",
                    chosen=near[0][0],
                    score=near[0][1],
                    alternatives=tuple(near),
                )
            )
            continue
        if role != "class":
            hint = f"; closest known: {', '.join(n for n, _ in near)}" if near else ""
            what = "relation" if role == "property" else "individual"
            problems.append(
                CheckItem.error(
                    "normalisation",
                    f"unknown {what} '{term}': a new {what} has no meaning in the "
                    f"simulator; use a known one{hint}",
                )
            )
            choices.append(
                TermChoice(term=term, role=role, match="new", chosen=term, alternatives=tuple(near))
            )
            continue
        new.append(term)
        choices.append(
            TermChoice(
                term=term,
                role=role,
                match="new",
                chosen=term,
                score=near[0][1] if near else None,
                alternatives=tuple(near),
            )
        )
    rename = {c.term: c.chosen for c in choices}
    new_classes: list[tuple[str, str]] = []
    resolved: list[TermChoice] = []
    for choice in choices:
        if choice.match != "new" or choice.role != "class":
            resolved.append(choice)
            continue
        parent = _parent(choice, declared_parents, vocab, rename, set(new))
        new_classes.append((choice.term, parent))
        resolved.append(choice.model_copy(update={"parent": parent}))
    return Normalised(
        axiom=manchester.render(axiom, rename, prefix=":"),
        display=manchester.render(axiom, rename),
        terms=tuple(resolved),
        new_classes=tuple(new_classes),
        problems=tuple(problems),
    )


def _parent(
    choice: TermChoice,
    declared: Mapping[str, str],
    vocab: Vocabulary,
    rename: Mapping[str, str],
    new: set[str],
) -> str:
    proposed = declared.get(choice.term)
    if proposed:
        if proposed in new:
            return proposed
        hit = rename.get(proposed) or _variant(proposed, vocab, "class")
        if hit is not None and hit in vocab.classes:
            return hit
    # The nearest existing class is a sibling more often than a parent; its
    # own parent is the safer guess, shown to the reviewer either way.
    for name, _score in choice.alternatives:
        parents = [
            a
            for a in vocab.ancestors.get(name, frozenset())
            if vocab.is_a(a, FALLBACK_PARENT) and a not in vocab.catalogue_types
        ]
        if parents:
            # The most specific ancestor: the one with the most ancestors itself.
            return max(sorted(parents), key=lambda a: len(vocab.ancestors.get(a, ())))
    return FALLBACK_PARENT
