"""How names are compared when a user may write them several ways."""

from __future__ import annotations

import re

_SEPARATORS = re.compile(r"[\s_\-]+")


def term_key(term: str) -> str:
    """How a name is compared with types and instances: case, spaces,
    underscores and hyphens do not matter ('stove knob 2', 'StoveKnob_2')."""
    return _SEPARATORS.sub("", term).lower()
