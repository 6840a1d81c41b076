"""How a passage is scored against a query: hybrid retrieval.

BM25 (``rank_bm25.BM25Okapi``) finds passages sharing the query's words, the
embeddings find paraphrases that share none.  Each score list is min-max
normalised over the corpus to [0, 1] and the two are averaged with weight 0.5
each (a list whose scores are all equal, such as BM25's when no query word
occurs anywhere, counts 0 for everyone).  This keeps the size of the gap
between passages, which reciprocal-rank fusion would throw away, and gives a
score a reader can compare across hits.  A passage is indexed with its
section title (or, for an introduction, body or PDF page, its document's
title) in front, because the corpus's paragraphs often leave the topic to
their heading.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np
import numpy.typing as npt

from virf.authoring.documents import BODY, INTRODUCTION, PAGE, Document, Passage

BM25_WEIGHT = 0.5
DENSE_WEIGHT = 0.5


def fused(bm25: npt.NDArray[np.float64], dense: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """The hybrid score of every passage, in [0, 1]."""
    return BM25_WEIGHT * min_max(bm25) + DENSE_WEIGHT * min_max(dense)


def min_max(scores: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    low, high = float(scores.min()), float(scores.max())
    if high - low <= 1e-12:
        return np.zeros_like(scores)
    return (scores - low) / (high - low)


def bm25_index(tokenized: list[list[str]]) -> Any:
    from rank_bm25 import BM25Okapi

    if not any(tokenized):
        return None  # BM25Okapi divides by the vocabulary size
    return BM25Okapi(tokenized)


_GENERIC_SECTION = re.compile(rf"{INTRODUCTION}|{BODY}|{PAGE} \d+")


def indexed_text(document: Document, passage: Passage) -> str:
    """The text a passage is indexed under: its section title (or, where the
    section has none of its own, the document's title), then its words."""
    context = document.title if _GENERIC_SECTION.fullmatch(passage.section) else passage.section
    return f"{context}. {passage.text}"


# English function words: they carry no topic, and with min-max fusion a
# passage matching only "while" would otherwise get BM25's full half of the
# score.  Negations and "off"/"without" stay: in safety advice they matter.
_STOP = frozenset({
    "a", "about", "above", "after", "again", "against", "all", "also", "am", "an", "and",
    "any", "are", "as", "at", "be", "because", "been", "before", "being", "below", "between",
    "both", "but", "by", "can", "could", "did", "do", "does", "doing", "down", "during",
    "each", "few", "for", "from", "further", "had", "has", "have", "having", "he", "her",
    "here", "hers", "herself", "him", "himself", "his", "how", "i", "if", "in", "into", "is",
    "it", "its", "itself", "just", "may", "me", "might", "more", "most", "must", "my",
    "myself", "nor", "now", "of", "on", "once", "only", "or", "other", "our", "ours",
    "ourselves", "out", "over", "own", "same", "shall", "she", "should", "so", "some", "such",
    "than", "that", "the", "their", "theirs", "them", "themselves", "then", "there", "these",
    "they", "this", "those", "through", "to", "too", "under", "until", "up", "very", "was",
    "we", "were", "what", "when", "where", "which", "while", "who", "whom", "why", "will",
    "with", "would", "you", "your", "yours", "yourself", "yourselves",
})  # fmt: skip


def tokens(text: str) -> list[str]:
    """Lowercase words for BM25, stop words dropped, plurals folded.

    Folding plurals by hand instead of a stemmer library (snowball, Porter):
    "fires"/"fire" and "pans"/"pan" are the mismatches household questions
    hit; deeper stemming would be a dependency for little, since the dense
    half already matches related forms."""
    return [_singular(w) for w in re.findall(r"[^\W_]+", text.lower()) if w not in _STOP]


def _singular(word: str) -> str:
    if len(word) <= 3:
        return word
    if word.endswith("ies") and len(word) > 4:
        return word[:-3] + "y"
    if word.endswith(("sses", "shes", "ches", "xes")):
        return word[:-2]
    if word.endswith("s") and not word.endswith(("ss", "us", "is")):
        return word[:-1]
    return word
