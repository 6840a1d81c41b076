"""From the vision model's words to the catalogue's object types.

A label is matched by name first (``coffee machine``, ``CoffeeMachine``,
``Mug 2``), then by meaning: the all-MiniLM-L6-v2 sentence embedding of the
label against those of the type names (``frying pan`` is a Pan).  A match by
meaning must be clear, well above the next type, because a wrong type is
worse than none: an unmatched label stays in the scene as a PhysicalObject
named after it (its material still asked about), never dropped.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import cached_property
from typing import Final, Literal

import numpy as np

from virf.embed import Embedder, default_embedder
from virf.names import name_words, term_key
from virf.ontology.tbox import Vocabulary

# Chosen on labels of kitchen objects: 'frying pan' (Pan, 0.76) and 'tea
# towel' (Towel, 0.74) pass; 'oven' (Microwave, 0.62), 'cutting board'
# (CuttingTool, 0.69) and 'wine glass' (WineBottle 0.83, Wine 0.81: no clear
# winner) do not.
MIN_SIMILARITY: Final = 0.7
MIN_MARGIN: Final = 0.05
_TRAILING_NUMBER: Final = re.compile(r"[\s_#-]*\d+$")


@dataclass(frozen=True)
class Match:
    type: str | None  # None: no catalogue type fits
    how: Literal["name", "embedding", "none"]
    score: float | None = None  # cosine similarity, for an embedding match
    runner_up: str | None = None


class Catalogue:
    """The object types perception may name, and the matcher onto them."""

    def __init__(self, vocab: Vocabulary, embedder: Embedder | None = None) -> None:
        self.vocab = vocab
        self._embedder = embedder
        excluded = set(vocab.uscs) | set(vocab.preconditions) | set(vocab.material_classes)
        # Things and people a camera can see; the robot is the one looking.
        seeable = {
            c
            for c in vocab.classes
            if c not in excluded
            and c not in ("PhysicalObject", "Agent")
            and (vocab.is_a(c, "PhysicalObject") or vocab.is_a(c, "Agent"))
            and not vocab.is_a(c, "Robot")
        }
        has_sub = {a for c in seeable for a in vocab.ancestors.get(c, ()) if a != c}
        # The catalogue's object types, and the most specific classes of the
        # scenarios (a Child, an Adult).
        self.types: tuple[str, ...] = tuple(
            sorted(vocab.catalogue_types | {c for c in seeable if c not in has_sub})
        )
        self._by_key = {term_key(c): c for c in sorted(seeable)}

    def by_name(self, label: str) -> str | None:
        text = _TRAILING_NUMBER.sub("", label.strip())
        # Plurals only ('mugs', 'boxes'): cutting letters off any word would
        # make a 'panel' a Pan.
        plural = [text[:-2]] if text.endswith("es") else []
        for form in (text, text[:-1] if text.endswith("s") else "", *plural):
            if not form:
                continue
            found = self._by_key.get(term_key(form))
            if found is not None:
                return self.vocab.class_synonyms.get(found, found)
        return None

    @cached_property
    def _vectors(self) -> np.ndarray:
        return self.embedder.encode([name_words(t) for t in self.types])

    @property
    def embedder(self) -> Embedder:
        if self._embedder is None:
            self._embedder = default_embedder()
        return self._embedder

    def match(self, label: str) -> Match:
        named = self.by_name(label)
        if named is not None:
            return Match(named, "name")
        text = _TRAILING_NUMBER.sub("", label.strip()) or label
        scores = self._vectors @ self.embedder.encode([text.lower()])[0]
        order = np.argsort(-scores, kind="stable")
        best, second = int(order[0]), int(order[1])
        score, gap = float(scores[best]), float(scores[best] - scores[second])
        runner_up = self.types[second]
        if score >= MIN_SIMILARITY and gap >= MIN_MARGIN:
            return Match(self.types[best], "embedding", round(score, 3), runner_up)
        return Match(None, "none", round(score, 3), self.types[best])
