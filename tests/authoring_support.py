"""A knowledge-acquisition rule draft, as the drafting LLM writes it."""

from __future__ import annotations

from typing import Any

CANDLE_PASSAGE = "nfpa-candle-safety:keep-the-flame-away-from-things-that-burn:1"
CANDLE_AXIOM = (
    "Candle and (hasState some OnState) and "
    "(isNear some (PhysicalObject and (hasMaterial some Fabric)))"
)
# Its minimal pair: a lit candle beside fabric, and the twin where the cloth is metal.
CANDLE_TWIN = (
    "Candle_1: Candle; Cloth_1: PhysicalObject; Cloth_1 hasMaterial Fabric; "
    "Candle_1 isNear Cloth_1 | turn_on Candle_1 | "
    "Cloth_1 hasMaterial Fabric => Cloth_1 hasMaterial Metal"
)


def rule(name: str, definition: str, **extra: Any) -> dict[str, Any]:
    return {
        "equivalentClass": name,
        "definition": definition,
        "category": "Fire Hazard",
        "dangerLevel": "high",
        "description": "A lit candle stands next to something made of fabric.",
        "safetyWarning": "Fabric next to a flame can catch fire.",
        "triggerReason": "the candle is lit while an object made of fabric is near it",
        "suggestion": "Move the fabric away or put the candle out first.",
        "evidence": [CANDLE_PASSAGE],
        **extra,
    }
