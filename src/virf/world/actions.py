"""What each of the 17 SafeAgentBench actions requires and changes.

One handler per verb (or per family of verbs that behave alike), registered in
:data:`HANDLERS`.  A handler reads the state the step starts in and edits a
:class:`Change`, the working copy of the next state; it returns a
:class:`PreconditionFailure` when the step cannot run.  Whether the result is
safe is the reasoner's business, not the handlers'.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import replace
from types import MappingProxyType

from virf.ontology.tbox import Vocabulary
from virf.schema import Fact, FactKind, Provenance
from virf.world.state import (
    PreconditionFailure,
    ResolvedStep,
    WorldState,
    facts_copy,
    remember_change,
)

# Actions whose only effect is one state of their target.
RESULT_STATE = {
    "open": "OpenState",
    "close": "ClosedState",
    "cook": "CookedState",
    "dirty": "DirtyState",
}
TOGGLE_STATE = {"turn_on": "OnState", "turn_off": "OffState"}
LIQUID_CLASS = {"water": "Water", "coffee": "Coffee", "wine": "Wine"}
# Affordance an action needs of its target (checked only for catalogue types).
AFFORDANCE = {
    "pick": "Pickupable",
    "open": "Openable",
    "close": "Openable",
    "turn_on": "Toggleable",
    "turn_off": "Toggleable",
    "slice": "Sliceable",
    "break": "Breakable",
    "dirty": "Dirtyable",
    "clean": "Dirtyable",
    "fillLiquid": "LiquidContainer",
    "emptyLiquid": "LiquidContainer",
}


def is_catalogue_type(vocab: Vocabulary, classes: frozenset[str]) -> bool:
    return any(
        vocab.annotation(c, "compatibleReceptacle")
        or vocab.is_a(c, "Receptacle")
        or c in vocab.catalogue_types
        for c in classes
    )


def lacks(vocab: Vocabulary, obj: str, state: WorldState, affordance: str) -> bool:
    return type_lacks(vocab, state.objects.get(obj, frozenset()), affordance)


def type_lacks(vocab: Vocabulary, classes: frozenset[str], affordance: str) -> bool:
    """Whether an object of ``classes`` certainly lacks ``affordance``; the
    rule :func:`lacks` applies, for callers that hold a scene rather than a
    state (the planner's constrained decoding)."""
    # Only catalogue types declare their affordances: for any other type a
    # missing one says nothing, and neither does one only some instances of
    # the type have (AI2-THOR's bowls break unless they are plastic).
    return (
        is_catalogue_type(vocab, classes)
        and not vocab.any_is_a(classes, affordance)
        and not vocab.may_afford(classes, affordance)
    )


def cannot_receive(vocab: Vocabulary, classes: frozenset[str]) -> bool:
    """Whether ``put`` certainly refuses an object of ``classes`` as the
    place: a catalogue type that is no receptacle.  An open-world type might
    be one, so it is not refused."""
    return is_catalogue_type(vocab, classes) and not vocab.any_is_a(classes, "Receptacle")


def portion_name(kind: str, source: str) -> str:
    """The individual the plan makes from ``source`` (what is poured out of
    it, its slices): ``Acid_from_Vinegar_1``."""
    return f"{kind}_from_{source}"


def portion_source(name: str, objects: Iterable[str]) -> str | None:
    """The object a plan-made portion came from, if ``name`` is one."""
    kind, sep, source = name.partition("_from_")
    return source if sep and kind and source in set(objects) else None


class Change:
    """One step being applied: the state it starts in and working copies of
    the facts, objects and finds that become the next state.

    Every edit of the facts goes through :meth:`put` and :meth:`remove`,
    which note the fact: the next state's change, its indexes and what the
    effects look for are found from those notes and the start state's
    indexes, so a step costs what it touches, not what the scene holds."""

    def __init__(
        self,
        vocab: Vocabulary,
        state: WorldState,
        r: ResolvedStep,
        heaters: dict[frozenset[str], bool] | None = None,
    ) -> None:
        """``heaters`` remembers, per set of classes, whether things of them
        heat what they hold (see :func:`heat`); a simulator keeps it for
        every step, since a scene of a thousand objects has a few dozen."""
        self.vocab = vocab
        self.heaters = {} if heaters is None else heaters
        self.state = state
        self.r = r
        self.verb = r.step.verb
        self.agent = state.agent
        self.held = state.held()
        self.facts = facts_copy(state.facts)
        # Every fact put or removed, in order (a dict as an ordered set).
        self.touched: dict[Fact, None] = {}
        self.objects = dict(state.objects)
        self.found = list(state.found)

    def put(self, f: Fact, provenance: Provenance) -> None:
        self.facts[f] = provenance
        self.touched[f] = None

    def remove(self, f: Fact) -> None:
        if self.facts.pop(f, None) is not None:
            self.touched[f] = None

    def mentioning(self, name: str) -> list[Fact]:
        """The facts now held with ``name`` as subject or object, those of
        the start state first (a list: the caller may edit the facts)."""
        facts, start = self.facts, self.state.facts
        found = [f for f in self.state.mentioning(name) if f in facts]
        found += [
            f
            for f in self.touched
            if f not in start and f in facts and name in (f.subject, f.object)
        ]
        return found

    def is_a(self, obj: str, cls: str) -> bool:
        """Whether ``obj`` was of class ``cls`` when the step started."""
        return self.vocab.any_is_a(self.state.objects[obj], cls)

    def fail(self, pre: str, subject: str, message: str, *why: Fact) -> PreconditionFailure:
        return PreconditionFailure(self.r.step, pre, subject, message, tuple(why))

    def add(self, f: Fact) -> None:
        self.put(f, Provenance.PLAN)

    def add_following(self, f: Fact, source: Fact) -> None:
        """Add ``f``, which the plan makes from ``source``: it is only as sure
        as ``source`` (a portion poured from a bottle that may hold an acid
        may be an acid)."""
        sure = self.state.facts.get(source) is not Provenance.ASSUMED
        self.put(f, Provenance.PLAN if sure else Provenance.ASSUMED)

    def drop(self, pred: Iterable[Fact]) -> None:
        # Materialised first: ``pred`` is usually a generator over the facts.
        for f in list(pred):
            self.remove(f)

    def set_state(self, obj: str, new: str) -> None:
        # The ontology's disjoint states (and the markers a known state
        # settles) leave the object: the scene reader made every state
        # canonical, so the exclusive ones are found by name.
        for old in self.vocab.excluded_by(new):
            self.remove(Fact(obj, "hasState", old))
        self.add(Fact(obj, "hasState", new))

    def located(self, obj: str) -> None:
        self.remove(Fact(obj, "isLocated", "false", FactKind.DATA))
        self.add(Fact(obj, "isLocated", "true", FactKind.DATA))

    def unplace(self, obj: str) -> None:
        self.drop(
            f
            for f in self.mentioning(obj)
            if f.object == obj
            and f.predicate in ("contains", "supports")
            and f.kind is FactKind.OBJECT
        )

    def drop_near(self, obj: str) -> None:
        self.drop(f for f in self.mentioning(obj) if f.predicate == "isNear")

    def result(self) -> WorldState:
        """The next state.  Its facts keep the order of the state before,
        with what the step added after them: nothing reads a state's facts
        in their order, and sorting them again made a step cost what the
        scene holds."""
        before = self.state
        order = before.order
        if not before.objects.keys() <= self.objects.keys():
            # A liquid the scene declared can be poured or emptied away.
            order = tuple(o for o in order if o in self.objects)
        after = replace(
            before,
            objects=MappingProxyType(self.objects),
            order=order,
            facts=MappingProxyType(self.facts),
            found=tuple(self.found),
        )
        start, facts = before.facts, self.facts
        remember_change(
            before, after, frozenset(f for f in self.touched if (f in start) != (f in facts))
        )
        return after


Handler = Callable[[Change], PreconditionFailure | None]


# ---------------------------------------------------------------- preconditions
def lacking_affordance(c: Change) -> PreconditionFailure | None:
    """The target's type does not afford the verb (checked before any handler)."""
    target = c.r.target
    if c.verb in AFFORDANCE and target and lacks(c.vocab, target, c.state, AFFORDANCE[c.verb]):
        return c.fail(
            "Precondition_LacksAffordance",
            target,
            f"{target} cannot be used for '{c.verb}': its type is not {AFFORDANCE[c.verb]}",
            *(Fact(target, "type", cls, FactKind.TYPE) for cls in sorted(c.state.objects[target])),
        )
    return None


def _nothing_held(c: Change, purpose: str) -> PreconditionFailure:
    return c.fail("Precondition_NothingHeld", c.agent, f"{c.agent} is holding nothing to {purpose}")


def _not_the_held(c: Change) -> PreconditionFailure | None:
    """The line names the object in the hand ('throw AlarmClock'): it must be
    the one held, never silently another."""
    named, agent = c.r.named_held, c.agent
    if named is None or named == c.held:
        return None
    if c.held is None:
        return c.fail("Precondition_NothingHeld", agent, f"{agent} is holding nothing, not {named}")
    return c.fail(
        "Precondition_NothingHeld",
        agent,
        f"{agent} is holding {c.held}, not {named}",
        Fact(agent, "isHolding", c.held),
    )


def _closed_above(c: Change, target: str) -> PreconditionFailure | None:
    """A closed receptacle anywhere above the target blocks the reach: an
    apple on a plate in a closed fridge cannot be picked either."""
    state = c.state
    path: list[Fact] = []
    node, seen = target, {target}
    while True:
        outer = [
            Fact(box, rel, node)
            for rel in ("contains", "supports")
            for box in state.subjects_of(rel, node)
        ]
        if not outer or outer[0].subject in seen:
            return None
        link = outer[0]
        path.append(link)
        if link.predicate == "contains" and state.has(link.subject, "hasState", "ClosedState"):
            return c.fail(
                "Precondition_ReceptacleClosed",
                link.subject,
                f"{target} is inside {link.subject}, which is closed",
                *path,
                Fact(link.subject, "hasState", "ClosedState"),
            )
        node = link.subject
        seen.add(node)


# ---------------------------------------------------------------- handlers
def _find(c: Change) -> None:
    target = c.r.target
    assert target is not None
    c.located(target)
    c.drop(f for f in c.mentioning(c.agent) if f.subject == c.agent and f.predicate == "isNear")
    c.add(Fact(c.agent, "isNear", target))
    if c.held is not None:  # what the robot carries comes along
        c.drop_near(c.held)
        c.add(Fact(c.held, "isNear", target))
    c.found = [o for o in c.found if o != target] + [target]


def _pick(c: Change) -> PreconditionFailure | None:
    target = c.r.target
    assert target is not None
    if c.held is not None:
        return c.fail(
            "Precondition_HandNotEmpty",
            c.agent,
            f"{c.agent} is already holding {c.held}",
            Fact(c.agent, "isHolding", c.held),
        )
    blocked = _closed_above(c, target)
    if blocked is not None:
        return blocked
    c.unplace(target)
    c.drop_near(target)
    c.add(Fact(c.agent, "isHolding", target))
    c.located(target)
    return None


def _put(c: Change) -> PreconditionFailure | None:
    target, obj, held, agent = c.r.target, c.r.patient, c.held, c.agent
    assert target is not None
    if held is None or obj is None:
        return _nothing_held(c, "put")
    if obj != held:
        return c.fail(
            "Precondition_NothingHeld",
            agent,
            f"{agent} is holding {held}, not {obj}",
            Fact(agent, "isHolding", held),
        )
    classes = c.state.objects[target]
    if cannot_receive(c.vocab, classes):
        return c.fail(
            "Precondition_NotAReceptacle",
            target,
            f"{target} cannot hold objects",
            *(Fact(target, "type", cls, FactKind.TYPE) for cls in sorted(classes)),
        )
    if c.state.has(target, "hasState", "ClosedState"):
        return c.fail(
            "Precondition_ReceptacleClosed",
            target,
            f"{target} is closed",
            Fact(target, "hasState", "ClosedState"),
        )
    c.drop([Fact(agent, "isHolding", held)])
    rel = "supports" if c.vocab.any_is_a(classes, "SurfaceReceptacle") else "contains"
    # Things on the same counter or in the same cabinet are near each
    # other, and near whoever is near that counter.
    c.drop_near(held)
    for other in c.state.objects_of(target, rel):
        c.add(Fact(held, "isNear", other))
    for f in c.mentioning(target):
        if (
            f.predicate == "isNear"
            and target in (f.subject, f.object)
            and f.kind is FactKind.OBJECT
        ):
            other = f.object if f.subject == target else f.subject
            if other not in (agent, held) and c.vocab.any_is_a(
                c.state.objects.get(other, frozenset()), "Agent"
            ):
                c.add(Fact(held, "isNear", other))
    c.add(Fact(target, rel, held))
    return None


def _result_state(c: Change) -> None:
    assert c.r.target is not None
    c.set_state(c.r.target, RESULT_STATE[c.verb])


def _toggle(c: Change) -> None:
    target = c.r.target
    assert target is not None
    new = TOGGLE_STATE[c.verb]
    c.set_state(target, new)
    # A stove knob switches the burners it controls.
    for device in c.state.objects_of(target, "controls"):
        c.set_state(device, new)


def _slice(c: Change) -> None:
    target, knife = c.r.target, c.r.instrument
    assert target is not None
    c.set_state(target, "SlicedState")
    if knife and c.is_a(knife, "CuttingTool"):
        c.add(Fact(knife, "touched", target))
    _derive(c, target, "slicedType")


def _break(c: Change) -> None:
    target = c.r.target
    assert target is not None
    c.set_state(target, "BrokenState")
    _derive(c, target, "crackedType")


def _clean(c: Change) -> None:
    target = c.r.target
    assert target is not None
    c.set_state(target, "CleanState")
    c.drop(f for f in c.mentioning(target) if f.subject == target and f.predicate == "touched")


def _fill_liquid(c: Change) -> None:
    target, liquid = c.r.target, c.r.liquid
    assert target is not None and liquid is not None
    liquid_cls = LIQUID_CLASS[c.r.step.args[1]]
    c.set_state(target, "FilledWithLiquidState")
    c.objects[liquid] = frozenset({liquid_cls})
    c.add(Fact(liquid, "type", liquid_cls, FactKind.TYPE))
    c.add(Fact(target, "contains", liquid))


def _empty_liquid(c: Change) -> None:
    target = c.r.target
    assert target is not None
    c.set_state(target, "EmptyState")
    _remove_liquids(c, target)


def _pour(c: Change) -> PreconditionFailure | None:
    held, target = c.held, c.r.target
    wrong = _not_the_held(c)
    if wrong is not None:
        return wrong
    if held is None:
        return _nothing_held(c, "pour")
    if target is None:
        return c.fail(
            "Precondition_NoPourTarget",
            c.agent,
            "nothing has been found to pour into since the object was picked up",
        )
    liquids = [
        o
        for o in c.state.objects_of(held, "contains")
        if c.vocab.any_is_a(c.state.objects.get(o, frozenset()), "Liquid")
    ]
    filled = c.state.has(held, "hasState", "FilledWithLiquidState")
    for liquid in liquids:
        c.remove(Fact(held, "contains", liquid))
        if c.is_a(target, "ContainerReceptacle") or c.is_a(target, "LiquidContainer"):
            c.add(Fact(target, "contains", liquid))
        else:
            c.objects.pop(liquid, None)
            c.drop(c.mentioning(liquid))

    def lands_in(portion: str) -> None:
        # Looked up only when something lands: a target the plan removed
        # earlier must not fail a pour that moves nothing.
        rel = "contains" if c.is_a(target, "ContainerReceptacle") else "supports"
        c.add(Fact(target, rel, portion))

    if filled and not liquids:
        # Filled with something the scene does not name.
        portion = portion_name("Liquid", held)
        c.objects[portion] = frozenset({"UnknownLiquid"})
        c.add(Fact(portion, "type", "UnknownLiquid", FactKind.TYPE))
        lands_in(portion)
    # A cleaner's chemical goes where it is poured, as a substance out of its
    # bottle: what it meets there is what it reacts with.
    # Something poured that is not a vessel (an open-world 'OvenCleaner') is
    # its own stuff: when nobody knows what it is made of, nobody knows what
    # lands where it is poured either.
    unknown_stuff = not c.is_a(held, "LiquidContainer")
    for chem in c.state.objects_of(held, "hasMaterial"):
        if chem in c.vocab.individuals and (
            c.vocab.is_a(chem, "Chemical") or (unknown_stuff and chem == "UnknownMaterial")
        ):
            portion = portion_name(chem, held)
            c.objects[portion] = frozenset({"Substance"})
            c.add(Fact(portion, "type", "Substance", FactKind.TYPE))
            c.add_following(Fact(portion, "hasMaterial", chem), Fact(held, "hasMaterial", chem))
            lands_in(portion)
    if liquids or filled:
        c.set_state(held, "EmptyState")
        if not c.is_a(target, "LiquidContainer") and not c.is_a(target, "ContainerReceptacle"):
            c.set_state(target, "WetState")
        elif c.is_a(target, "LiquidContainer"):
            c.set_state(target, "FilledWithLiquidState")
    return None


def _drop_held(c: Change) -> PreconditionFailure | None:
    held = c.held
    wrong = _not_the_held(c)
    if wrong is not None:
        return wrong
    if held is None:
        return _nothing_held(c, c.verb)
    c.drop([Fact(c.agent, "isHolding", held)])
    floors = [o for o in c.state.order if c.is_a(o, "Floor")]
    if floors:
        c.add(Fact(floors[0], "supports", held))
    # AI2-THOR breaks a breakable object on an impact above its threshold,
    # and a fall from the hand or a throw is one (SafeAgentBench's "Drop the
    # Plate" expects the plate broken; a dropped egg cracks).
    if c.is_a(held, "Breakable"):
        c.set_state(held, "BrokenState")
        _derive(c, held, "crackedType")
    return None


HANDLERS: dict[str, Handler] = {
    "find": _find,
    "pick": _pick,
    "put": _put,
    "open": _result_state,
    "close": _result_state,
    "cook": _result_state,
    "dirty": _result_state,
    "turn_on": _toggle,
    "turn_off": _toggle,
    "slice": _slice,
    "break": _break,
    "clean": _clean,
    "fillLiquid": _fill_liquid,
    "emptyLiquid": _empty_liquid,
    "pour": _pour,
    "drop": _drop_held,
    "throw": _drop_held,
}


# ---------------------------------------------------------------- shared effects
def heat(c: Change) -> None:
    """A running heat source (lit burner, toaster) or microwave cooks the
    cookable things in or on it, and those in a pan or pot on it, as
    AI2-THOR does.  Runs after every step, whatever its verb."""
    objects = c.objects

    def holds(container: str) -> list[str]:
        return [
            f.object
            for f in c.mentioning(container)
            if f.subject == container
            and f.kind is FactKind.OBJECT
            and f.predicate in ("contains", "supports")
        ]

    # Only what is on can heat: the objects in the facts that say so, not
    # every object of the scene.  Heating edits no fact these read, so the
    # order they are taken in changes nothing.
    running = [
        f.subject
        for f in c.mentioning("OnState")
        if f.predicate == "hasState" and f.object == "OnState" and f.kind is FactKind.OBJECT
    ]
    for source in dict.fromkeys(running):
        classes = objects.get(source)
        if classes is None:
            continue
        heater = c.heaters.get(classes)
        if heater is None:
            heater = c.heaters[classes] = c.vocab.any_is_a(
                classes, "HeatSourceObject"
            ) or c.vocab.any_is_a(classes, "MicrowaveEmitterObject")
        if not heater:
            continue
        reached = holds(source)
        reached += [inner for outer in reached for inner in holds(outer)]
        for obj in reached:
            c.remove(Fact(obj, "hasState", "ColdState"))
            c.add(Fact(obj, "hasState", "HotState"))
            if c.vocab.any_is_a(objects.get(obj, frozenset()), "Cookable"):
                c.add(Fact(obj, "hasState", "CookedState"))


def _derive(c: Change, source: str, annotation: str) -> None:
    """AI2-THOR replaces a sliced apple by AppleSliced pieces: add one piece
    of the derived type where the source was, visible to the agent."""
    objects = c.objects
    for cls in sorted(c.state.objects[source]):
        derived = c.vocab.annotation(cls, annotation)
        if not derived or derived[0] not in c.vocab.classes:
            continue
        name = portion_name(derived[0], source)
        if name in objects:
            return
        objects[name] = frozenset({derived[0]})
        c.add(Fact(name, "type", derived[0], FactKind.TYPE))
        if annotation == "slicedType":
            c.add(Fact(name, "hasState", "SlicedState"))
        c.add(Fact(name, "isLocated", "true", FactKind.DATA))
        for f in c.mentioning(source):
            if (
                f.object == source
                and f.predicate in ("contains", "supports")
                and f.kind is FactKind.OBJECT
            ):
                c.add(Fact(f.subject, f.predicate, name))
        return


def _remove_liquids(c: Change, container: str) -> None:
    for liquid in c.state.objects_of(container, "contains"):
        if c.vocab.any_is_a(c.state.objects.get(liquid, frozenset()), "Liquid"):
            c.objects.pop(liquid, None)
            c.drop(c.mentioning(liquid))
