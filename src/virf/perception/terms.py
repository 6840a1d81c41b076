"""What the vision model's words mean in the ontology: a relationship word
as a scene property (parent-first words turned round), a material word as a
material individual, a state word as a state individual.  Words are compared
by :func:`virf.names.term_key`, so spelling and case do not matter.
"""

from __future__ import annotations

from typing import Final

from virf.names import term_key
from virf.ontology.tbox import Vocabulary
from virf.verify.questions import materials
from virf.world.values import VALUE_WORDS

# The model's relationship words (compared by term_key), as the scene's
# properties.  Parent-first words are turned round into child-first ones.
RELATIONS: Final = {
    **dict.fromkeys(("ison", "on", "ontopof", "ontop", "sitson", "restson"), "isOn"),
    **dict.fromkeys(("isinside", "inside", "in", "isin", "within", "containedin"), "isInside"),
    **dict.fromkeys(("isnear", "near", "nextto", "isnextto", "beside", "closeto"), "isNear"),
    **dict.fromkeys(("isheldby", "heldby", "held", "inhand"), "isHeldBy"),
    "supports": "supports",
    "contains": "contains",
    "isholding": "isHolding",
}
CHILD_FIRST: Final = {"supports": "isOn", "contains": "isInside", "isHolding": "isHeldBy"}
MATERIAL_WORDS: Final = {
    **dict.fromkeys(
        (
            "steel",
            "stainlesssteel",
            "iron",
            "castiron",
            "aluminum",
            "aluminium",
            "copper",
            "tin",
            "brass",
            "metallic",
            "chrome",
            "silver",
        ),
        "Metal",
    ),
    **dict.fromkeys(("porcelain", "stoneware", "earthenware", "clay", "terracotta"), "Ceramic"),
    **dict.fromkeys(("wooden", "bamboo", "timber"), "Wood"),
    **dict.fromkeys(
        ("cloth", "cotton", "textile", "linen", "wool", "polyester", "fabrics"), "Fabric"
    ),
    **dict.fromkeys(("cardboard", "paperboard", "carton"), "Paper"),
    **dict.fromkeys(("silicone", "latex"), "Rubber"),
    **dict.fromkeys(("marble", "granite", "concrete"), "Stone"),
    **dict.fromkeys(("plastics", "melamine", "acrylic", "polypropylene", "vinyl"), "Plastic"),
    **dict.fromkeys(("crystal", "glassware"), "Glass"),
}


def material_term(word: str, vocab: Vocabulary) -> str | None:
    """The material a word names: ``UnknownMaterial`` for unknown, None for no material."""
    key = term_key(word)
    if key in ("unknown", "unsure", "unclear", "none", "na"):
        return "UnknownMaterial"
    for m in materials(vocab):
        if key in (m.lower(), m.lower() + "s"):
            return m
    return MATERIAL_WORDS.get(key)


STATE_SYNONYMS: Final = {
    **dict.fromkeys(
        ("lit", "burning", "running", "switchedon", "turnedon", "active", "operating", "powered"),
        "OnState",
    ),
    **dict.fromkeys(("unlit", "switchedoff", "turnedoff", "inactive", "unpowered"), "OffState"),
    **dict.fromkeys(("boiling", "steaming", "heated", "warm"), "HotState"),
    **dict.fromkeys(("ajar",), "OpenState"),
    **dict.fromkeys(("shut",), "ClosedState"),
    **dict.fromkeys(("halffull", "partiallyfilled", "filledwithwater"), "FilledWithLiquidState"),
    **dict.fromkeys(("cracked", "shattered"), "BrokenState"),
}


def state_term(word: str, vocab: Vocabulary) -> str | None:
    """The state individual a word names (``closed`` -> ClosedState, ``lit``
    -> OnState), else None."""
    key = term_key(word)
    if key in STATE_SYNONYMS:
        return STATE_SYNONYMS[key]
    if key.startswith("is") and key[2:] in VALUE_WORDS:
        key = key[2:]
    if key in VALUE_WORDS:
        found = VALUE_WORDS[key]
        return found if vocab.is_a(found, "State") and found != "UnknownFillState" else None
    for ind in sorted(vocab.individuals):
        if vocab.is_a(ind, "State") and key in (ind.lower(), ind.lower().removesuffix("state")):
            return ind
    return None
