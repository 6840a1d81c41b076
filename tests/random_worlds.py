"""Random scenes and plans for property tests (a support module, not tests)."""

from __future__ import annotations

from hypothesis import strategies as st

from virf.world.language import ARITY, VERBS

KINDS = [
    "Apple",
    "Bread",
    "Egg",
    "Tomato",
    "Potato",
    "Mug",
    "Cup",
    "Bowl",
    "Plate",
    "Pot",
    "Pan",
    "Kettle",
    "Fork",
    "Knife",
    "ButterKnife",
    "Spatula",
    "SoapBottle",
    "DishSponge",
    "WineBottle",
    "Bottle",
    "Box",
    "CellPhone",
    "Book",
    "Vase",
    "Candle",
    "Fridge",
    "Microwave",
    "Toaster",
    "CoffeeMachine",
    "StoveBurner",
    "StoveKnob",
    "Sink",
    "Faucet",
    "CounterTop",
    "Cabinet",
    "Drawer",
    "DiningTable",
    "GarbageCan",
]
STATES = (
    "OnState",
    "OffState",
    "OpenState",
    "ClosedState",
    "EmptyState",
    "FilledWithLiquidState",
    "WetState",
    "DirtyState",
    "CleanState",
    "HotState",
)
RELATIONS = ("isOn", "isInside", "isNear")


@st.composite
def scenes_and_plans(draw: st.DrawFn) -> tuple[dict[str, object], list[str]]:
    kinds = draw(st.lists(st.sampled_from(KINDS), min_size=2, max_size=7))
    names = [f"{k}_{i}" for i, k in enumerate(kinds)]
    instances = [{"class_name": k, "instance_name": n} for k, n in zip(kinds, names, strict=True)]
    assertions = []
    for n in names:
        for s in draw(st.lists(st.sampled_from(STATES), max_size=2, unique=True)):
            assertions.append({"subject": n, "property": "hasState", "object": s})
    placed: set[str] = set()
    for _ in range(draw(st.integers(0, 5))):
        a, b = draw(st.sampled_from(names)), draw(st.sampled_from(names))
        rel = draw(st.sampled_from(RELATIONS))
        # Each thing in or on one place, and never inside itself (the scene
        # reader refuses impossible worlds): parents come earlier in the list.
        if rel != "isNear" and (a in placed or names.index(b) >= names.index(a)):
            continue
        if a != b:
            if rel != "isNear":
                placed.add(a)
            assertions.append({"subject": a, "property": rel, "object": b})
    scene: dict[str, object] = {"instances": instances, "assertions": assertions}
    if draw(st.booleans()):
        scene["closed_world"] = draw(
            st.lists(st.sampled_from(["contains", "supports"]), unique=True)
        )
    if draw(st.booleans()):
        scene["unlocated_by_default"] = draw(st.booleans())
    steps = []
    for _ in range(draw(st.integers(1, 6))):
        verb = draw(st.sampled_from(VERBS))
        lo, hi = ARITY[verb]
        args = [draw(st.sampled_from(names)) for _ in range(draw(st.integers(lo, hi)))]
        if verb == "fillLiquid":
            args = [args[0], "water"]
        steps.append(" ".join([verb, *args]))
    return scene, steps
