"""Worlds with open-world objects whose answers teach the knowledge base."""

from __future__ import annotations

from typing import Any

from conftest import inst, rel

ELECTRIC = "confirm:HairDryer_1 hasProperty ElectricallyPowered"
# A hair dryer switched on beside a basin of water: the hazard needs the
# guess that a hair dryer is electrical.
HAIR_DRYER: dict[str, Any] = {
    "instances": [
        inst("HairDryer", "HairDryer_1"),
        inst("SinkBasin", "SinkBasin_1"),
        inst("CounterTop", "CounterTop_1"),
    ],
    "assertions": [
        rel("SinkBasin_1", "hasState", "filled"),
        rel("HairDryer_1", "isOn", "CounterTop_1"),
        rel("HairDryer_1", "isNear", "SinkBasin_1"),
    ],
}
HAIR_DRYER_PLAN = ["find HairDryer_1", "turn_on HairDryer_1"]
TODDLER: dict[str, Any] = {
    "instances": [inst("Toddler", "Toddler_1"), inst("Toaster", "Toaster_1")],
    "assertions": [rel("Toddler_1", "isNear", "Toaster_1")],
}
