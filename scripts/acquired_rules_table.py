"""Print the household rules (safety-acquired.omn) per hazard category and room.

A rule's rooms are the rooms its evidence documents say they cover (the
``rooms`` line of each starter-corpus document's front matter); a rule whose
evidence names "household" counts in every room.  Used for the table in
docs/knowledge-base.md:

    python scripts/acquired_rules_table.py
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from virf.authoring.corpus import Corpus
from virf.authoring.workspace import starter_corpus_dir
from virf.bench.safeagentbench import CATEGORIES
from virf.ontology.check import evidence_of
from virf.ontology.tbox import load_tbox

ROOMS = ("kitchen", "living room", "bedroom", "bathroom")


def main() -> None:
    vocab = load_tbox("household").vocabulary
    corpus = Corpus(starter_corpus_dir(), Path("/nonexistent-virf-cache"))
    counts: Counter[tuple[str, str]] = Counter()
    totals: Counter[str] = Counter()
    for usc in vocab.uscs.values():
        if usc.module != "safety-acquired":
            continue
        totals[usc.category] += 1
        rooms: set[str] = set()
        for pid in evidence_of(vocab, usc.name)[0]:
            passage = corpus.passage(pid)
            doc = corpus.document(passage.document) if passage else None
            named = {r.strip() for r in (doc.rooms if doc else ())}
            rooms |= set(ROOMS) if "household" in named else named & set(ROOMS)
        for room in rooms:
            counts[usc.category, room] += 1
    print("| category | rules | " + " | ".join(ROOMS) + " |")
    print("|---|---|" + "---|" * len(ROOMS))
    for cat in [*CATEGORIES, *sorted(set(totals) - set(CATEGORIES))]:
        cells = " | ".join(str(counts[cat, r]) for r in ROOMS)
        print(f"| {cat} | {totals[cat]} | {cells} |")
    cells = " | ".join(str(sum(counts[c, r] for c in totals)) for r in ROOMS)
    print(f"| all | {sum(totals.values())} | {cells} |")


if __name__ == "__main__":
    main()
