"""Objects of classes the knowledge base does not name ('HairDryer',
'Toddler'): which names may be read that way, what the dictionary suggests
about them (assumed facts, asked about where a hazard depends on one), and
where in the ontology they might belong.  docs/scenes.md describes it.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Mapping

from virf.errors import EnvironmentProblem, InputError, clip, closest
from virf.names import term_key
from virf.ontology.lexicon import Proposal, propose
from virf.ontology.tbox import Vocabulary
from virf.schema import Fact, FactKind, Provenance

# A class name the knowledge base lacks is read as an open-world object when
# it looks like a name of a kind of thing ('HairDryer', 'space heater').
OPEN_CLASS_RE = re.compile(r"[A-Za-z][A-Za-z0-9]*(?:[ _\-][A-Za-z0-9]+)*")
MAX_OPEN_CLASS = 64
# How close in spelling an unknown name must be to a known class to be read
# as a misspelling of it ('Mircowave') rather than as a new kind of thing.
TYPO_CUTOFF = 0.8
# How near in meaning (cosine of the sentence embeddings) a class must be to
# be proposed as the place of a word WordNet lacks ('nightlight'); below it
# the neighbours are noise ('zorblax' -> PepperShaker at 0.45).
PROPOSAL_FLOOR = 0.5


def check_open_class(cname: str, vocab: Vocabulary, strict: bool) -> None:
    """Refuse a class name that cannot be an open-world object: under
    ``strict``, one that does not look like a name, or a misspelling of a
    known class that the dictionary does not know either ('Mircowave' is a
    microwave, and reading it as an unknown thing would lose its hazards)."""
    if strict or len(cname) > MAX_OPEN_CLASS or not OPEN_CLASS_RE.fullmatch(cname):
        vocab.require_class(cname)  # raises, naming the closest classes
    if propose(cname).found:
        return
    near = closest(cname, vocab.classes)
    typo = [
        c
        for c in near
        if difflib.SequenceMatcher(None, cname.lower(), c.lower()).ratio() >= TYPO_CUTOFF
    ]
    if typo:
        raise InputError(
            f"unknown class '{clip(cname)}' (neither the knowledge base nor the dictionary "
            f"knows it, and it is spelled like a known class); closest known: {', '.join(typo)}"
        )


# What a hypothesis asks, in words (questions and notes).
HYPOTHESIS_WORDS = {
    "ElectricallyPowered": "an electrical appliance",
    "HeatSource": "a heat source",
    "OpenFlame": "an open flame",
    "HotBulb": "a lamp with a hot bulb",
    "Flammable": "flammable",
    "Fragile": "fragile",
    "Toxic": "toxic",
    "Sharp": "sharp",
}


def hypothesise(
    proposals: Mapping[str, Proposal],
    open_world: Mapping[str, str],
    facts: dict[Fact, Provenance],
    vocab: Vocabulary,
) -> tuple[str, ...]:
    """Add each open-world object's proposal as assumed facts (a hazard that
    needs one is UNKNOWN, asking about it) and say what was read."""
    stated_material = {
        f.subject
        for f, p in facts.items()
        if f.predicate == "hasMaterial" and p is Provenance.SCENE
    }
    notes = []
    for ind in sorted(proposals):
        p = proposals[ind]
        said = []
        for prop in p.properties:
            if prop in vocab.individuals:
                facts.setdefault(Fact(ind, "hasProperty", prop), Provenance.ASSUMED)
                said.append(HYPOTHESIS_WORDS.get(prop, prop))
        if ind not in stated_material:
            for m in p.materials:
                if m in vocab.individuals:
                    facts.setdefault(Fact(ind, "hasMaterial", m), Provenance.ASSUMED)
                    said.append(f"made of {m}")
        for t in p.types:
            if vocab.canonical_class(t) is not None:
                facts.setdefault(Fact(ind, "type", t, FactKind.TYPE), Provenance.ASSUMED)
                said.append(f"a {t}")
        base = "a person (MaterialEntity)" if p.person else "a PhysicalObject"
        parent = _proposed_parent(open_world[ind], p, vocab)
        place = f"; proposed place: under {parent}" if parent else ""
        hypotheses = (
            f"it may be {', '.join(said)}, which is asked only where a hazard depends on it"
            if said
            else "nothing suggests a hazard of its own; its material is unknown"
        )
        notes.append(
            f"{ind}: '{open_world[ind]}' is not a class of the knowledge base; read as {base} "
            f"of the open world ({p.describe()}{place}); {hypotheses}"
        )
    return tuple(notes)


def _proposed_parent(word: str, p: Proposal, vocab: Vocabulary) -> str | None:
    """Where the object might sit in the ontology, for the user and for
    learning: the nearest WordNet hypernym the knowledge base names (a
    bookshelf is a kind of shelf), else, for a word WordNet lacks, the class
    closest in meaning (the bundled sentence embedder)."""
    for hypernym in p.path[:6]:
        cls = vocab.canonical_class(term_key(hypernym))
        if cls is not None and cls not in ("PhysicalObject", "Entity", "Agent"):
            return f"{cls} (WordNet)"
    if p.found or not p.dictionary:
        return None
    from virf.ontology.suggest import rank_classes  # loads the embedder: only here

    try:
        ranked = rank_classes(word, vocab, "object")
    except (EnvironmentProblem, OSError):  # a missing model only loses the proposal
        return None
    best = max(ranked, key=lambda r: (r.meaning, r.name), default=None)
    if best is None or best.meaning < PROPOSAL_FLOOR:
        return None
    return f"{best.name} (closest in meaning)"
