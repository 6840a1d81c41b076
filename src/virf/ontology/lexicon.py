"""Where a word the knowledge base lacks might sit in it: a proposal read from
WordNet 3.0, never a fact.

A scene may name an object by any class name (``HairDryer``, ``Toddler``,
``Cardboard``). The reader keeps such an object as an open-world
``PhysicalObject`` and asks this module what the word probably is. WordNet's
hypernyms say what kind of thing it is (hair dryer -> dryer -> appliance;
toddler -> child -> person; cardboard -> paper), and a few kinds matter for
safety: electrical, a heat source, an open flame, flammable, fragile, toxic,
sharp, a person or a child, food, or made of a material the knowledge base
knows. Each becomes a *hypothesis* the reader adds as an assumed fact, so a
hazard that needs it is UNKNOWN with a question, never SAFE and never
UNSAFE on the strength of a dictionary.

WordNet comes from Debian (``wordnet-base`` and ``wordnet-sense-index``,
installed by ``make wordnet``). nltk reads it offline from an
``nltk_data/corpora/wordnet`` folder that also holds a ``lexnames`` file;
Debian ships that file only as the lexnames(5WN) manual page, so
:func:`wordnet_root` builds the folder once from the Debian files (copies:
nltk refuses to follow links out of its data folder).
"""

from __future__ import annotations

import gzip
import os
import re
import shutil
import sys
import tempfile
import threading
from collections.abc import Iterable
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

DEBIAN_WORDNET = Path("/usr/share/wordnet")
DEBIAN_LEXNAMES = Path("/usr/share/man/man5/lexnames.5WN.gz")
WORDNET_FILES = (
    "adj.exc",
    "adv.exc",
    "cntlist.rev",
    "data.adj",
    "data.adv",
    "data.noun",
    "data.verb",
    "index.adj",
    "index.adv",
    "index.noun",
    "index.sense",
    "index.verb",
    "noun.exc",
    "verb.exc",
)
# WordNet 3.0's lexicographer files in number order (lexnames(5WN)).
LEXNAMES = [
    "adj.all",
    "adj.pert",
    "adv.all",
    "noun.Tops",
    "noun.act",
    "noun.animal",
    "noun.artifact",
    "noun.attribute",
    "noun.body",
    "noun.cognition",
    "noun.communication",
    "noun.event",
    "noun.feeling",
    "noun.food",
    "noun.group",
    "noun.location",
    "noun.motive",
    "noun.object",
    "noun.person",
    "noun.phenomenon",
    "noun.plant",
    "noun.possession",
    "noun.process",
    "noun.quantity",
    "noun.relation",
    "noun.shape",
    "noun.state",
    "noun.substance",
    "noun.time",
    "verb.body",
    "verb.change",
    "verb.cognition",
    "verb.communication",
    "verb.competition",
    "verb.consumption",
    "verb.contact",
    "verb.creation",
    "verb.emotion",
    "verb.motion",
    "verb.perception",
    "verb.possession",
    "verb.social",
    "verb.stative",
    "verb.weather",
    "adj.ppl",
]
INSTALL_HINT = (
    "install WordNet with 'make wordnet' (Debian packages wordnet-base, wordnet-sense-index)"
)

# What a sense's hypernyms say that matters for safety. Keys are WordNet
# synsets; a sense matches when the synset is the sense itself or one of its
# hypernyms. Values are (kind, term): 'property' terms are attribute
# individuals (hasProperty), 'material' terms material individuals
# (hasMaterial), 'type' terms classes.
CUES: dict[str, tuple[tuple[str, str], ...]] = {
    # electricity
    "appliance.n.01": (("property", "ElectricallyPowered"),),
    "appliance.n.02": (("property", "ElectricallyPowered"),),
    "electrical_device.n.01": (("property", "ElectricallyPowered"),),
    "electronic_device.n.01": (("property", "ElectricallyPowered"),),
    "electronic_equipment.n.01": (("property", "ElectricallyPowered"),),
    "electric_lamp.n.01": (("property", "ElectricallyPowered"),),
    "lighting_fixture.n.01": (("property", "ElectricallyPowered"),),
    "machine.n.01": (("property", "ElectricallyPowered"),),
    "power_tool.n.01": (("property", "ElectricallyPowered"),),
    "computer.n.01": (("property", "ElectricallyPowered"),),
    "conductor.n.04": (("property", "ElectricallyPowered"),),
    # heat and flame
    "heater.n.01": (("property", "HeatSource"), ("property", "ElectricallyPowered")),
    "heating_element.n.01": (("property", "HeatSource"),),
    "stove.n.01": (("property", "HeatSource"),),
    "stove.n.02": (("property", "HeatSource"),),
    "oven.n.01": (("property", "HeatSource"),),
    "dryer.n.01": (("property", "HeatSource"),),
    "iron.n.04": (("property", "HeatSource"), ("property", "ElectricallyPowered")),
    "curling_iron.n.01": (("property", "HeatSource"),),
    "fireplace.n.01": (("property", "HeatSource"), ("property", "OpenFlame")),
    "fire.n.01": (("property", "HeatSource"), ("property", "OpenFlame")),
    "lamp.n.01": (("property", "HeatSource"), ("property", "OpenFlame")),
    "lamp.n.02": (("property", "HeatSource"),),
    "lighter.n.02": (("property", "HeatSource"), ("property", "OpenFlame")),
    "igniter.n.01": (("property", "HeatSource"), ("property", "OpenFlame")),
    "match.n.01": (("property", "HeatSource"), ("property", "OpenFlame")),
    "torch.n.01": (("property", "HeatSource"), ("property", "OpenFlame")),
    "candle.n.01": (("property", "OpenFlame"), ("material", "Wax")),
    # fuel
    "paper.n.01": (("property", "Flammable"), ("material", "Paper")),
    "fabric.n.01": (("property", "Flammable"), ("material", "Fabric")),
    "bedclothes.n.01": (("property", "Flammable"), ("material", "Fabric")),
    "clothing.n.01": (("property", "Flammable"), ("material", "Fabric")),
    "floor_cover.n.01": (("property", "Flammable"), ("material", "Fabric")),
    "curtain.n.01": (("property", "Flammable"), ("material", "Fabric")),
    "drygoods.n.01": (("property", "Flammable"), ("material", "Fabric")),
    "towel.n.01": (("property", "Flammable"), ("material", "Fabric")),
    "wood.n.01": (("property", "Flammable"), ("material", "Wood")),
    "book.n.02": (("property", "Flammable"), ("material", "Paper")),
    "fuel.n.01": (("property", "Flammable"),),
    "alcohol.n.01": (("property", "Flammable"), ("property", "Toxic")),
    "solvent.n.01": (("property", "Flammable"), ("property", "Toxic"), ("material", "Chemical")),
    "oil.n.01": (("property", "Flammable"),),
    "gasoline.n.01": (("property", "Flammable"), ("property", "Toxic")),
    "aerosol.n.01": (("property", "Pressurised"), ("property", "Flammable")),
    "aerosol.n.02": (("property", "Pressurised"), ("property", "Flammable")),
    "antifreeze.n.01": (("property", "Toxic"), ("material", "Chemical")),
    "pill.n.01": (("property", "Toxic"),),
    "wax.n.01": (("property", "Flammable"), ("material", "Wax")),
    # fragile
    "glass.n.01": (("property", "Fragile"), ("material", "Glass")),
    "glass.n.02": (("property", "Fragile"), ("material", "Glass")),
    "glassware.n.01": (("property", "Fragile"), ("material", "Glass")),
    "mirror.n.01": (("property", "Fragile"), ("material", "Glass")),
    "ceramic.n.01": (("property", "Fragile"), ("material", "Ceramic")),
    "crockery.n.01": (("property", "Fragile"), ("material", "Ceramic")),
    "vase.n.01": (("property", "Fragile"),),
    "light_bulb.n.01": (("property", "Fragile"), ("material", "Glass")),
    # chemicals and poisons
    "chemical.n.01": (("property", "Toxic"), ("material", "Chemical")),
    "compound.n.02": (("material", "Chemical"),),
    "acid.n.01": (("property", "Toxic"), ("material", "Acid")),
    "caustic.n.01": (("property", "Toxic"), ("material", "Chemical")),
    "bleaching_agent.n.01": (("property", "Toxic"), ("material", "Bleach")),
    "ammonia.n.02": (("property", "Toxic"), ("material", "Ammonia")),
    "ammonia_water.n.01": (("property", "Toxic"), ("material", "Ammonia")),
    "cleansing_agent.n.01": (("property", "Toxic"), ("material", "Chemical")),
    "detergent.n.01": (("property", "Toxic"), ("material", "Soap")),
    "poison.n.01": (("property", "Toxic"),),
    "pesticide.n.01": (("property", "Toxic"), ("material", "Chemical")),
    "drug.n.01": (("property", "Toxic"),),
    "medicine.n.02": (("property", "Toxic"),),
    "remover.n.01": (("property", "Toxic"), ("material", "Chemical")),
    "dilutant.n.01": (("property", "Toxic"), ("property", "Flammable"), ("material", "Chemical")),
    # sharp
    "edge_tool.n.01": (("property", "Sharp"),),
    "cutting_implement.n.01": (("property", "Sharp"),),
    "knife.n.01": (("property", "Sharp"),),
    "knife.n.02": (("property", "Sharp"),),
    "blade.n.01": (("property", "Sharp"),),
    "blade.n.09": (("property", "Sharp"),),
    "needle.n.03": (("property", "Sharp"),),
    "saw.n.02": (("property", "Sharp"),),
    "razor.n.01": (("property", "Sharp"),),
    # metal
    "metallic_element.n.01": (("material", "Metal"),),
    "metal.n.01": (("material", "Metal"),),
    "plastic.n.01": (("material", "Plastic"),),
    "rubber.n.01": (("material", "Rubber"),),
    "leather.n.01": (("material", "Leather"),),
    # people and food
    "person.n.01": (("type", "Person"),),
    "child.n.01": (("type", "Child"),),
    "child.n.02": (("type", "Child"),),
    "juvenile.n.01": (("type", "Child"),),
    "food.n.01": (("type", "FoodItem"),),
    "food.n.02": (("type", "FoodItem"),),
}
# A device may run on mains power (a fan, a router): asking costs a question
# only where a hazard would follow. It is a weak cue, read only when nothing
# more specific is known of the sense and the sense is not a device of a
# kind that never is (a shelf is a 'support', a hammer a 'mechanical device').
WEAK_CUE = ("device.n.01", ("property", "ElectricallyPowered"))
NOT_POWERED = frozenset({"support.n.10", "mechanical_device.n.01", "lever.n.01"})
# What a sense's gloss or the term's own words say when no hypernym does
# ('an electrically powered mixer'; a 'power strip'; a 'deep fryer').
GLOSS_CUES: tuple[tuple[re.Pattern[str], tuple[str, str]], ...] = (
    (
        re.compile(r"\b(electric\w*|battery|batteries|motor|motorized|plugs? into)\b"),
        ("property", "ElectricallyPowered"),
    ),
    (
        re.compile(r"\b(heats|heating element|gives off heat|produces heat)\b"),
        ("property", "HeatSource"),
    ),
    (re.compile(r"\bflames?\b"), ("property", "OpenFlame")),
    (re.compile(r"\b(sharp|blades?|cutting edges?)\b"), ("property", "Sharp")),
    (re.compile(r"\b(poison\w*|toxic|caustic|corrosive|medicated)\b"), ("property", "Toxic")),
    (re.compile(r"\b(flammable|inflammable|combustible)\b"), ("property", "Flammable")),
)
TERM_CUES: dict[str, tuple[tuple[str, str], ...]] = {
    "electric": (("property", "ElectricallyPowered"),),
    "electrical": (("property", "ElectricallyPowered"),),
    "power": (("property", "ElectricallyPowered"),),
    "battery": (("property", "ElectricallyPowered"),),
    "charger": (("property", "ElectricallyPowered"),),
    "cable": (("property", "ElectricallyPowered"),),
    "plug": (("property", "ElectricallyPowered"),),
    "heater": (("property", "HeatSource"), ("property", "ElectricallyPowered")),
    "heated": (("property", "HeatSource"), ("property", "ElectricallyPowered")),
    "fryer": (("property", "HeatSource"), ("property", "ElectricallyPowered")),
    "cooker": (("property", "HeatSource"), ("property", "ElectricallyPowered")),
    "light": (("property", "ElectricallyPowered"), ("property", "HotBulb")),
    "lamp": (("property", "ElectricallyPowered"), ("property", "HotBulb")),
    "bleach": (("property", "Toxic"), ("material", "Bleach")),
    "ammonia": (("property", "Toxic"), ("material", "Ammonia")),
    "cleaner": (("property", "Toxic"), ("material", "Chemical")),
    "sanitizer": (("property", "Toxic"), ("property", "Flammable")),
    "gas": (("property", "Flammable"),),
    "hot": (("property", "HeatSource"),),
    "iron": (("property", "HeatSource"), ("property", "ElectricallyPowered")),
}
# What a word is assumed to possibly be when WordNet is not installed.
UNREAD_PROPERTIES = (
    "ElectricallyPowered",
    "HeatSource",
    "OpenFlame",
    "Flammable",
    "Fragile",
    "Toxic",
    "Sharp",
)
# Senses about things (not acts, feelings or quantities).
PHYSICAL_LEXNAMES = frozenset(
    {
        "noun.artifact",
        "noun.substance",
        "noun.food",
        "noun.person",
        "noun.animal",
        "noun.plant",
        "noun.object",
        "noun.body",
    }
)
MAX_SENSES = 4

_lock = threading.Lock()


def _words(term: str) -> list[str]:
    """'HairDryer', 'hair_dryer', 'hair-dryer' and 'hair dryer' -> ['hair', 'dryer']."""
    spaced = re.sub(r"(?<=[a-z0-9])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])", " ", term)
    return [w.lower() for w in re.split(r"[\s_\-.]+", spaced) if w and not w.isdigit()]


def _lexnames_text(manpage: Path) -> str:
    """The lexnames file (number, name, syntactic category) from its manual
    page; from WordNet 3.0's fixed list when an image strips manual pages."""
    names: list[str] = []
    if manpage.is_file():
        with gzip.open(manpage, "rt", encoding="utf-8", errors="replace") as fh:
            text = fh.read()
        names = [m.group(2) for m in re.finditer(r"^(\d\d)\t(\S+)\s*\t", text, re.MULTILINE)]
    if len(names) != len(LEXNAMES):
        names = list(LEXNAMES)
    category = {"noun": 1, "verb": 2, "adj": 3, "adv": 4}
    return "".join(
        f"{n:02d}\t{name}\t{category[name.split('.')[0]]}\n" for n, name in enumerate(names)
    )


def _data_roots() -> list[Path]:
    env = os.environ.get("VIRF_WORDNET")
    if env:
        return [Path(env)]
    cache_home = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return [Path(sys.prefix) / "nltk_data", cache_home / "virf" / "nltk_data"]


def _ready(root: Path) -> bool:
    folder = root / "corpora" / "wordnet"
    return (folder / "lexnames").is_file() and all((folder / f).is_file() for f in WORDNET_FILES)


def wordnet_root() -> Path | None:
    """An nltk_data folder holding WordNet, built from Debian's files on first
    use; None when WordNet is not installed."""
    roots = _data_roots()
    for root in roots:
        if _ready(root):
            return root
    if not all((DEBIAN_WORDNET / f).is_file() for f in WORDNET_FILES):
        return None
    with _lock:
        for root in roots:
            if _ready(root):
                return root
            try:
                root.mkdir(parents=True, exist_ok=True)
                # Built beside its final place and renamed, so that a reader
                # never sees half a folder.
                staging = Path(tempfile.mkdtemp(prefix=".wordnet-", dir=root))
                for name in WORDNET_FILES:
                    shutil.copyfile(DEBIAN_WORDNET / name, staging / name)
                (staging / "lexnames").write_text(_lexnames_text(DEBIAN_LEXNAMES))
                (root / "corpora").mkdir(exist_ok=True)
                target = root / "corpora" / "wordnet"
                if not _ready(root):
                    shutil.rmtree(target, ignore_errors=True)
                    staging.rename(target)
                else:
                    shutil.rmtree(staging, ignore_errors=True)
                return root
            except OSError:
                continue  # not writable (a system-wide install): try the next
    return None


@cache
def _wordnet() -> Any:
    root = wordnet_root()
    if root is None:
        return None
    import warnings

    import nltk
    from nltk.corpus.reader.wordnet import WordNetCorpusReader

    # nltk reads corpora only from folders on its data path.
    if str(root) not in nltk.data.path:
        nltk.data.path.insert(0, str(root))
    with warnings.catch_warnings():
        # Debian's WordNet has no Open Multilingual Wordnet, which VIRF does not use.
        warnings.simplefilter("ignore", UserWarning)
        return WordNetCorpusReader(str(root / "corpora" / "wordnet"), None)


def wordnet_available() -> bool:
    return _wordnet() is not None


@dataclass(frozen=True)
class Proposal:
    """What a word probably names, with the WordNet senses it was read from."""

    word: str  # the term in words: 'hair dryer'
    senses: tuple[str, ...]  # WordNet synsets read ('hand_blower.n.01')
    path: tuple[str, ...]  # the first sense's hypernyms, nearest first, as words
    properties: tuple[str, ...]  # attribute individuals to hypothesise
    materials: tuple[str, ...]  # material individuals to hypothesise
    types: tuple[str, ...]  # classes to hypothesise (Child, Person, FoodItem)
    found: bool  # WordNet knows the word (or its last word)
    dictionary: bool = True  # WordNet was available to ask

    @property
    def person(self) -> bool:
        return bool({"Person", "Child"} & set(self.types))

    def describe(self) -> str:
        if not self.dictionary:
            return (
                "WordNet is not installed, so every hazard it could take part in is asked "
                f"about: {INSTALL_HINT}"
            )
        if not self.found:
            return f"'{self.word}' is not in WordNet"
        chain = " -> ".join((self.word, *self.path[:3]))
        return f"WordNet reads {chain}"


def _lemma_count(synset: Any) -> int:
    return int(sum(lemma.count() for lemma in synset.lemmas()))


def _senses(wn: Any, words: list[str]) -> tuple[list[Any], str]:
    """The physical noun senses of the whole term, else of its last words."""
    for start in range(len(words)):
        phrase = "_".join(words[start:])
        synsets = [s for s in wn.synsets(phrase, pos="n") if s.lexname() in PHYSICAL_LEXNAMES]
        if synsets:
            return synsets, phrase.replace("_", " ")
    return [], ""


def _keep(synsets: list[Any], modifiers: list[str]) -> list[Any]:
    """The senses a hypothesis may come from: up to MAX_SENSES of the common
    ones (a sense tagged far less often than the first is a rare reading: a
    'dog' is not asked about as a hot dog). When only the last word was
    found, a sense whose gloss names an earlier word comes first ('clothes
    iron' is the appliance that smooths cloth, not the metal)."""
    if modifiers:
        stems = [m[:5] for m in modifiers if len(m) > 2]
        named = [s for s in synsets if any(st in s.definition().lower() for st in stems)]
        if named:
            return named[:MAX_SENSES]
    top = _lemma_count(synsets[0])
    kept = [synsets[0]]
    for s in synsets[1:]:
        if len(kept) == MAX_SENSES:
            break
        # A person or an animal only as the first reading ('fan' is not asked
        # about as a person); a substance always (vinegar is also an acid);
        # another thing when it is not much rarer than the first.
        if s.lexname() in ("noun.person", "noun.animal"):
            continue
        if s.lexname() != "noun.substance" and 4 * _lemma_count(s) < top:
            continue
        kept.append(s)
    return kept


def _cues(sense: Any) -> list[tuple[str, str]]:
    nodes = [sense, *sense.closure(lambda x: x.hypernyms())]
    found = [cue for node in nodes for cue in CUES.get(node.name(), ())]
    gloss = sense.definition().lower()
    found += [cue for pattern, cue in GLOSS_CUES if pattern.search(gloss)]
    names = {node.name() for node in nodes}
    if WEAK_CUE[0] in names and not found and not names & NOT_POWERED:
        found.append(WEAK_CUE[1])
    return found


@cache
def propose(term: str) -> Proposal:
    """The proposal for a class name or word (deterministic: WordNet's sense
    order and the cue table decide)."""
    words = _words(term)
    word = " ".join(words)
    cues: dict[tuple[str, str], None] = {}
    for w in words:
        for ending, said in TERM_CUES.items():
            if w == ending or (len(w) > len(ending) + 2 and w.endswith(ending)):
                for cue in said:
                    cues.setdefault(cue, None)
    wn = _wordnet()
    synsets, read = _senses(wn, words) if wn is not None and words else ([], "")
    modifiers = words[: len(words) - len(read.split())] if synsets else []
    kept = _keep(synsets, modifiers) if synsets else []
    # A word before the name that names a stuff says what the thing is made
    # of: a 'cardboard box', an 'oil lamp', a 'paper bag' (WordNet knows the
    # whole name, and says it is a bag).
    for m in words[:-1]:
        first = wn.synsets(m, pos="n")[:1] if wn is not None else []
        if first and first[0].lexname() == "noun.substance":
            kept.append(first[0])
    for s in kept:
        for cue in _cues(s):
            cues.setdefault(cue, None)
    # The shortest hypernym path of the first sense (ties by name), nearest
    # first: closure() walks a set, whose order changes between runs.
    chains = (
        sorted(kept[0].hypernym_paths(), key=lambda c: (len(c), [n.name() for n in c]))
        if kept
        else []
    )
    path = (
        tuple(n.lemmas()[0].name().replace("_", " ") for n in reversed(chains[0][:-1]))
        if chains
        else ()
    )

    if wn is None:
        # Nothing can say what the word is: every hazard it could take part
        # in is asked about where one would follow (fail closed).
        for prop in UNREAD_PROPERTIES:
            cues.setdefault(("property", prop), None)

    def of(kind: str) -> tuple[str, ...]:
        return tuple(sorted(term for k, term in cues if k == kind))

    types = of("type")
    if "Child" in types:  # a child is a person: the narrower hypothesis says both
        types = tuple(t for t in types if t != "Person")
    return Proposal(
        word=word,
        senses=tuple(s.name() for s in kept),
        path=path,
        properties=of("property"),
        materials=of("material"),
        types=types,
        found=bool(kept),
        dictionary=wn is not None,
    )


def proposals(terms: Iterable[str]) -> dict[str, Proposal]:
    return {t: propose(t) for t in terms}


if __name__ == "__main__":  # pragma: no cover - `python -m virf.ontology.lexicon WORD...`
    root = wordnet_root()
    if root is None:
        print(f"WordNet not found: {INSTALL_HINT}", file=sys.stderr)
        sys.exit(1)
    print(f"WordNet ready in {root / 'corpora' / 'wordnet'}")
    for arg in sys.argv[1:]:
        print(arg, propose(arg))
