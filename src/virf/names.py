"""How names are compared when a user may write them several ways."""

from __future__ import annotations

import re
from functools import lru_cache

_SEPARATORS = re.compile(r"[\s_\-]+")


# Kept: every new state indexes its objects' names again, and a verification
# compares the same few dozen names many times.
@lru_cache(maxsize=8192)
def term_key(term: str) -> str:
    """How a name is compared with types and instances: case, spaces,
    underscores and hyphens do not matter ('stove knob 2', 'StoveKnob_2')."""
    return _SEPARATORS.sub("", term).lower()


_WORD_BREAK = re.compile(r"(?<=[a-z0-9])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])|[_\-]+")


def name_words(name: str) -> str:
    """A term's name as the words a sentence embedding compares:
    ``CoffeeMachine`` -> "coffee machine", ``TVStand`` -> "tv stand",
    ``Precondition_NothingHeld`` -> "precondition nothing held"."""
    return " ".join(_WORD_BREAK.sub(" ", name).split()).lower()
