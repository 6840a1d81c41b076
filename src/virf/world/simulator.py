"""Sandbox simulator: deterministic preconditions and effects of the 17 actions.

States are immutable; ``apply`` returns a new state and never touches the
input scene.  The simulator decides only whether an action *can* run and what
it changes.  Whether the result is safe is the reasoner's business.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property
from types import MappingProxyType

from virf.names import term_key
from virf.ontology.tbox import Vocabulary
from virf.schema import Fact, FactKind, Provenance
from virf.world.plan import PlanStep, singular_forms
from virf.world.scene import Scene

# Actions whose only effect is one state of their target.
RESULT_STATE = {
    "open": "OpenState",
    "close": "ClosedState",
    "cook": "CookedState",
    "dirty": "DirtyState",
}
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


@dataclass(frozen=True)
class WorldState:
    objects: Mapping[str, frozenset[str]]
    order: tuple[str, ...]
    facts: Mapping[Fact, Provenance]
    agent: str
    closed_world: frozenset[str]
    unknown_contents: frozenset[str] = frozenset()
    found: tuple[str, ...] = ()  # objects found so far, most recent last
    # The user's answers to ambiguity questions: term_key(word) -> instance.
    referents: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))

    @property
    def last_found(self) -> str | None:
        return self.found[-1] if self.found else None

    def has(self, subject: str, predicate: str, obj: str) -> bool:
        return Fact(subject, predicate, obj) in self.facts

    # States are immutable, so the relation indexes are built once, on first
    # use; scanning every fact per lookup made big scenes quadratic.
    @cached_property
    def _forward(self) -> dict[tuple[str, str], list[str]]:
        index: dict[tuple[str, str], list[str]] = {}
        for f in self.facts:
            if f.kind is FactKind.OBJECT:
                index.setdefault((f.subject, f.predicate), []).append(f.object)
        return index

    @cached_property
    def _backward(self) -> dict[tuple[str, str], list[str]]:
        index: dict[tuple[str, str], list[str]] = {}
        for f in self.facts:
            if f.kind is FactKind.OBJECT:
                index.setdefault((f.predicate, f.object), []).append(f.subject)
        return index

    @cached_property
    def _by_lower(self) -> dict[str, str]:
        index: dict[str, str] = {}
        for ind in self.order + tuple(sorted(set(self.objects) - set(self.order))):
            index.setdefault(ind.lower(), ind)
        return index

    @cached_property
    def _by_key(self) -> dict[str, list[str]]:
        index: dict[str, list[str]] = {}
        for ind in self.order + tuple(sorted(set(self.objects) - set(self.order))):
            index.setdefault(term_key(ind), []).append(ind)
        return index

    def named(self, term: str) -> list[str]:
        """The individuals ``term`` spells: itself, else the first that differs
        only in case, else all that differ only in case and separators."""
        if term in self.objects:
            return [term]
        same_case = self._by_lower.get(term.lower())
        if same_case is not None:
            return [same_case]
        return list(self._by_key.get(term_key(term), ()))

    def objects_of(self, subject: str, predicate: str) -> list[str]:
        return sorted(self._forward.get((subject, predicate), ()))

    def subjects_of(self, predicate: str, obj: str) -> list[str]:
        return sorted(self._backward.get((predicate, obj), ()))

    def held(self) -> str | None:
        held = self.objects_of(self.agent, "isHolding")
        return held[0] if held else None


@dataclass(frozen=True)
class ResolvedStep:
    step: PlanStep
    target: str | None = None  # the object acted on / receptacle / pour destination
    patient: str | None = None  # the object moved or transformed besides the target
    liquid: str | None = None  # liquid individual created by fillLiquid
    instrument: str | None = None  # held tool used


@dataclass(frozen=True)
class MissingObject:
    """The plan names something the simulator cannot act on: absent from the
    scene, ambiguous between several instances, or a person or agent."""

    step: PlanStep
    term: str
    near: tuple[str, ...]
    ambiguous: bool = False
    agent: bool = False


@dataclass(frozen=True)
class PreconditionFailure:
    step: PlanStep
    precondition: str  # a PreconditionViolation class in the ontology
    subject: str
    message: str
    facts: tuple[Fact, ...] = field(default_factory=tuple)


class Simulator:
    def __init__(self, vocab: Vocabulary) -> None:
        self.vocab = vocab

    # ------------------------------------------------------------------ setup
    def initial(self, scene: Scene) -> WorldState:
        facts = dict(scene.facts)
        held = {f.object for f in facts if f.subject == scene.agent and f.predicate == "isHolding"}
        stated = {f.subject for f in facts if f.predicate == "isLocated"}
        for ind in scene.order:
            if self._is_physical(scene.objects[ind]) and ind not in stated:
                located = ind in held or not scene.unlocated_by_default
                facts[Fact(ind, "isLocated", "true" if located else "false", FactKind.DATA)] = (
                    Provenance.SCENE
                )
        return WorldState(
            objects=scene.objects,
            order=scene.order,
            facts=MappingProxyType(dict(sorted(facts.items()))),
            agent=scene.agent,
            closed_world=scene.closed_world,
            unknown_contents=scene.unknown_contents,
            referents=scene.referents,
        )

    def _is_physical(self, classes: frozenset[str]) -> bool:
        return self.vocab.any_is_a(classes, "PhysicalObject")

    def _is_catalogue_type(self, classes: frozenset[str]) -> bool:
        return any(
            self.vocab.annotation(c, "compatibleReceptacle")
            or self.vocab.is_a(c, "Receptacle")
            or c in self.vocab.catalogue_types
            for c in classes
        )

    def lacks(self, obj: str, state: WorldState, affordance: str) -> bool:
        classes = state.objects.get(obj, frozenset())
        return self._is_catalogue_type(classes) and not self.vocab.any_is_a(classes, affordance)

    # ------------------------------------------------------------------ resolution
    def class_named(self, term: str) -> str | None:
        """The class a plan term names, whatever its case and spacing
        ('dining table', 'stove-knob', 'DiningTable')."""
        # canonical_class ignores only case; plans also write "dining table".
        cls = self.vocab.canonical_class(term)
        if cls is not None:
            return cls
        hit = self.vocab.term_by_key(term_key(term))
        return self.vocab.canonical_class(hit) if hit else None

    def spelling(self, state: WorldState, term: str) -> str | None:
        """``term`` if it names an instance or a type; else its singular when
        exactly one singular reading names something ('apples' -> 'apple');
        else None.  A plural is read only when the word itself names nothing,
        so 'boots' stays the catalogue's Boots."""
        if state.named(term) or self.class_named(term):
            return term
        readings: dict[str, str] = {}
        for form in singular_forms(term):
            named = state.named(form)
            target = named[0] if len(named) == 1 else self.class_named(form)
            if target is not None or named:
                readings.setdefault(target or term_key(form), form)
        # Two singulars naming different things would be a guess.
        return next(iter(readings.values())) if len(readings) == 1 else None

    def resolve_term(self, state: WorldState, term: str) -> str | tuple[str, ...] | None:
        """The instance ``term`` names; None if none; the candidates if the
        choice is ambiguous (several equally plausible instances)."""
        spelled = self.spelling(state, term)
        if spelled is None:
            return None
        keys = (term_key(term), term_key(spelled))

        def choose(pool: list[str], among: list[str]) -> str | tuple[str, ...]:
            if len(pool) == 1:
                return pool[0]
            # Only a tie is settled by the user's earlier answer ("by 'bowl' I
            # mean Bowl_2"): it must never outrank what the plan itself says.
            for key in keys:
                meant = state.referents.get(key)
                if meant in among:
                    return meant
            # Sorted, so the question's options do not follow the file's order.
            return tuple(sorted(pool))

        named = state.named(spelled)
        if named:
            # Two instances spelled alike ('Mug_12', 'Mug1_2'): never guess.
            return choose(named, named)
        cls = self.class_named(spelled)
        if cls is None:
            return None
        candidates = [
            ind
            for ind in state.order + tuple(sorted(set(state.objects) - set(state.order)))
            if ind != state.agent and self.vocab.any_is_a(state.objects[ind], cls)
        ]
        if not candidates:
            return None
        # The object the agent dealt with most recently wins: a later 'put Fridge'
        # means the fridge just found, as in AI2-THOR where actions act on the
        # object in view.
        for ind in reversed(state.found):
            if ind in candidates:
                return ind
        held = state.held()
        if held in candidates:
            return held
        # Then the one the agent can see (located).  Several equally plausible
        # instances are ambiguous: guessing could pick the dangerous one.
        visible = [
            c for c in candidates if Fact(c, "isLocated", "true", FactKind.DATA) in state.facts
        ]
        return choose(visible or candidates, candidates)

    def _put_splits(self, state: WorldState, phrase: str) -> list[tuple[str, str]]:
        """The readings of 'put apple fridge' (no connector) as an object and a
        receptacle where both sides name something."""
        words = phrase.split()
        return [
            (" ".join(words[:i]), " ".join(words[i:]))
            for i in range(1, len(words))
            if self.spelling(state, " ".join(words[:i]))
            and self.spelling(state, " ".join(words[i:]))
        ]

    @staticmethod
    def near(term: str, pool: Iterable[str], n: int = 3) -> tuple[str, ...]:
        """The closest known names, compared in compacted form so that
        'dinning table' finds DiningTable."""
        by_key: dict[str, str] = {}
        for name in sorted(set(pool)):
            by_key.setdefault(term_key(name), name)
        hits = difflib.get_close_matches(term_key(term), list(by_key), n=n, cutoff=0.5)
        return tuple(by_key[h] for h in hits)

    def resolve(self, state: WorldState, step: PlanStep) -> ResolvedStep | MissingObject:
        def need(term: str) -> str | MissingObject:
            found = self.resolve_term(state, term)
            if found is None:
                pool = list(state.objects) + sorted(
                    {c for cs in state.objects.values() for c in cs}
                )
                return MissingObject(step, term, self.near(term, pool))
            if isinstance(found, tuple):
                return MissingObject(step, term, found, ambiguous=True)
            if (
                self.vocab.any_is_a(state.objects.get(found, frozenset()), "Agent")
                and step.verb != "find"
            ):
                return MissingObject(step, term, (found,), agent=True)
            return found

        verb, args = step.verb, step.args
        held = state.held()
        # The whole phrase names the receptacle if it can ("put dining table");
        # otherwise one object-receptacle split must work, since choosing
        # between several would be a guess.
        if verb == "put" and len(args) == 1 and self.spelling(state, args[0]) is None:
            splits = self._put_splits(state, args[0])
            if len(splits) == 1:
                args = splits[0]
            elif splits:
                sides = tuple(dict.fromkeys(side for split in splits for side in split))
                return MissingObject(step, args[0], sides)
        if verb == "put":
            dest = need(args[-1])
            if isinstance(dest, MissingObject):
                return dest
            patient = held
            if len(args) == 2:
                named = need(args[0])
                if isinstance(named, MissingObject):
                    return named
                patient = named
            return ResolvedStep(step, target=dest, patient=patient)
        if verb == "pour":
            dest_r = state.last_found
            if args:
                named = need(args[0])
                if isinstance(named, MissingObject):
                    return named
                dest_r = named
            if dest_r == held:
                dest_r = None
            return ResolvedStep(step, target=dest_r, patient=held)
        if verb in ("drop", "throw"):
            return ResolvedStep(step, patient=held)
        target = need(args[0])
        if isinstance(target, MissingObject):
            return target
        if verb == "fillLiquid":
            liquid = f"{LIQUID_CLASS[args[1]]}_in_{target}"
            if liquid in state.objects:  # a second fill is another portion
                liquid = f"{liquid}_step{step.index}"
            return ResolvedStep(step, target=target, liquid=liquid)
        if verb in ("slice", "clean", "break"):
            return ResolvedStep(step, target=target, instrument=held)
        return ResolvedStep(step, target=target)

    # ------------------------------------------------------------------ action individuals
    def action_facts(self, state: WorldState, r: ResolvedStep) -> dict[Fact, Provenance]:
        """The action as an individual of the state it starts in (lookahead)."""
        act = f"Step{r.step.index}_{r.step.verb}"
        out = {
            Fact(act, "type", r.step.action_class, FactKind.TYPE): Provenance.PLAN,
            Fact(act, "hasAgent", state.agent): Provenance.PLAN,
        }
        if r.target:
            out[Fact(act, "hasTarget", r.target)] = Provenance.PLAN
        if r.patient:
            out[Fact(act, "hasPatient", r.patient)] = Provenance.PLAN
        if r.instrument:
            out[Fact(act, "hasInstrument", r.instrument)] = Provenance.PLAN
        if r.liquid:
            out[Fact(act, "hasPatient", r.liquid)] = Provenance.PLAN
            out[Fact(r.liquid, "type", LIQUID_CLASS[r.step.args[1]], FactKind.TYPE)] = (
                Provenance.PLAN
            )
        return out

    @staticmethod
    def action_individual(step: PlanStep) -> str:
        return f"Step{step.index}_{step.verb}"

    # ------------------------------------------------------------------ closure
    def closure_facts(self, state: WorldState) -> dict[Fact, Provenance]:
        """What the simulator believes are the complete contents of things.

        Known for the robot's own hand; for receptacles only as far as the
        scene says its listing is complete (``closed_world``), otherwise an
        open-world assumption that a finding must ask about.
        """
        out: dict[Fact, Provenance] = {}
        held = state.objects_of(state.agent, "isHolding")
        out[Fact(state.agent, "isHolding", ",".join(held), FactKind.CLOSURE)] = Provenance.PLAN
        for ind in state.order + tuple(sorted(set(state.objects) - set(state.order))):
            classes = state.objects[ind]
            for rel, cls in (
                ("contains", "ContainerReceptacle"),
                ("supports", "SurfaceReceptacle"),
            ):
                if self.vocab.any_is_a(classes, cls):
                    members = state.objects_of(ind, rel)
                    known = (
                        rel in state.closed_world or f"{rel}:{ind}" in state.closed_world
                    ) and ind not in state.unknown_contents
                    prov = Provenance.SCENE if known else Provenance.ASSUMED
                    out[Fact(ind, rel, ",".join(members), FactKind.CLOSURE)] = prov
        return out

    # ------------------------------------------------------------------ effects
    def apply(self, state: WorldState, r: ResolvedStep) -> WorldState | PreconditionFailure:
        verb = r.step.verb
        held = state.held()
        facts = dict(state.facts)
        objects = dict(state.objects)
        found = list(state.found)
        agent = state.agent

        def fail(pre: str, subject: str, message: str, *why: Fact) -> PreconditionFailure:
            return PreconditionFailure(r.step, pre, subject, message, tuple(why))

        def add(f: Fact) -> None:
            facts[f] = Provenance.PLAN

        def drop(pred: Iterable[Fact]) -> None:
            for f in list(pred):
                facts.pop(f, None)

        def set_state(obj: str, new: str) -> None:
            # The ontology's disjoint states (and the markers a known state
            # settles) leave the object: the scene reader made every state
            # canonical, so the exclusive ones are found by name.
            for old in self.vocab.excluded_by(new):
                facts.pop(Fact(obj, "hasState", old), None)
            add(Fact(obj, "hasState", new))

        def located(obj: str) -> None:
            facts.pop(Fact(obj, "isLocated", "false", FactKind.DATA), None)
            add(Fact(obj, "isLocated", "true", FactKind.DATA))

        def unplace(obj: str) -> None:
            drop(
                f
                for f in facts
                if f.object == obj
                and f.predicate in ("contains", "supports")
                and f.kind is FactKind.OBJECT
            )

        target = r.target
        if verb in AFFORDANCE and target and self.lacks(target, state, AFFORDANCE[verb]):
            return fail(
                "Precondition_LacksAffordance",
                target,
                f"{target} cannot be used for '{verb}': its type is not {AFFORDANCE[verb]}",
                *(Fact(target, "type", c, FactKind.TYPE) for c in sorted(state.objects[target])),
            )

        if verb == "find":
            assert target is not None
            located(target)
            drop(f for f in facts if f.subject == agent and f.predicate == "isNear")
            add(Fact(agent, "isNear", target))
            if held is not None:  # what the robot carries comes along
                drop(f for f in facts if held in (f.subject, f.object) and f.predicate == "isNear")
                add(Fact(held, "isNear", target))
            found = [o for o in found if o != target] + [target]
        elif verb == "pick":
            assert target is not None
            if held is not None:
                return fail(
                    "Precondition_HandNotEmpty",
                    agent,
                    f"{agent} is already holding {held}",
                    Fact(agent, "isHolding", held),
                )
            # A closed receptacle anywhere above the target blocks the reach:
            # an apple on a plate in a closed fridge cannot be picked either.
            path: list[Fact] = []
            node, seen = target, {target}
            while True:
                outer = [
                    Fact(box, rel, node)
                    for rel in ("contains", "supports")
                    for box in state.subjects_of(rel, node)
                ]
                if not outer or outer[0].subject in seen:
                    break
                link = outer[0]
                path.append(link)
                if link.predicate == "contains" and state.has(
                    link.subject, "hasState", "ClosedState"
                ):
                    return fail(
                        "Precondition_ReceptacleClosed",
                        link.subject,
                        f"{target} is inside {link.subject}, which is closed",
                        *path,
                        Fact(link.subject, "hasState", "ClosedState"),
                    )
                node = link.subject
                seen.add(node)
            unplace(target)
            drop(f for f in facts if target in (f.subject, f.object) and f.predicate == "isNear")
            add(Fact(agent, "isHolding", target))
            located(target)
        elif verb == "put":
            assert target is not None
            obj = r.patient
            if held is None or obj is None:
                return fail("Precondition_NothingHeld", agent, f"{agent} is holding nothing to put")
            if obj != held:
                return fail(
                    "Precondition_NothingHeld",
                    agent,
                    f"{agent} is holding {held}, not {obj}",
                    Fact(agent, "isHolding", held),
                )
            classes = state.objects[target]
            if self._is_catalogue_type(classes) and not self.vocab.any_is_a(classes, "Receptacle"):
                return fail(
                    "Precondition_NotAReceptacle",
                    target,
                    f"{target} cannot hold objects",
                    *(Fact(target, "type", c, FactKind.TYPE) for c in sorted(classes)),
                )
            if state.has(target, "hasState", "ClosedState"):
                return fail(
                    "Precondition_ReceptacleClosed",
                    target,
                    f"{target} is closed",
                    Fact(target, "hasState", "ClosedState"),
                )
            drop([Fact(agent, "isHolding", held)])
            rel = "supports" if self.vocab.any_is_a(classes, "SurfaceReceptacle") else "contains"
            # Things on the same counter or in the same cabinet are near each
            # other, and near whoever is near that counter.
            drop(f for f in facts if held in (f.subject, f.object) and f.predicate == "isNear")
            for other in state.objects_of(target, rel):
                add(Fact(held, "isNear", other))
            for f in list(facts):
                if (
                    f.predicate == "isNear"
                    and target in (f.subject, f.object)
                    and f.kind is FactKind.OBJECT
                ):
                    other = f.object if f.subject == target else f.subject
                    if other not in (agent, held) and self.vocab.any_is_a(
                        state.objects.get(other, frozenset()), "Agent"
                    ):
                        add(Fact(held, "isNear", other))
            add(Fact(target, rel, held))
        elif verb in RESULT_STATE:
            assert target is not None
            set_state(target, RESULT_STATE[verb])
        elif verb in ("turn_on", "turn_off"):
            assert target is not None
            new = "OnState" if verb == "turn_on" else "OffState"
            set_state(target, new)
            # A stove knob switches the burners it controls.
            for device in state.objects_of(target, "controls"):
                set_state(device, new)
        elif verb == "slice":
            assert target is not None
            set_state(target, "SlicedState")
            if r.instrument and self.vocab.any_is_a(state.objects[r.instrument], "CuttingTool"):
                add(Fact(r.instrument, "touched", target))
            self._derive(state, target, "slicedType", objects, facts)
        elif verb == "break":
            assert target is not None
            set_state(target, "BrokenState")
            self._derive(state, target, "crackedType", objects, facts)
        elif verb == "clean":
            assert target is not None
            set_state(target, "CleanState")
            drop(f for f in facts if f.subject == target and f.predicate == "touched")
        elif verb == "fillLiquid":
            assert target is not None and r.liquid is not None
            liquid_cls = LIQUID_CLASS[r.step.args[1]]
            set_state(target, "FilledWithLiquidState")
            objects[r.liquid] = frozenset({liquid_cls})
            add(Fact(r.liquid, "type", liquid_cls, FactKind.TYPE))
            add(Fact(target, "contains", r.liquid))
        elif verb == "emptyLiquid":
            assert target is not None
            set_state(target, "EmptyState")
            self._remove_liquids(state, target, objects, facts)
        elif verb == "pour":
            if held is None:
                return fail(
                    "Precondition_NothingHeld", agent, f"{agent} is holding nothing to pour"
                )
            if target is None:
                return fail(
                    "Precondition_NoPourTarget",
                    agent,
                    "nothing has been found to pour into since the object was picked up",
                )
            liquids = [
                o
                for o in state.objects_of(held, "contains")
                if self.vocab.any_is_a(state.objects.get(o, frozenset()), "Liquid")
            ]
            filled = state.has(held, "hasState", "FilledWithLiquidState")
            for liquid in liquids:
                facts.pop(Fact(held, "contains", liquid), None)
                if self.vocab.any_is_a(
                    state.objects[target], "ContainerReceptacle"
                ) or self.vocab.any_is_a(state.objects[target], "LiquidContainer"):
                    add(Fact(target, "contains", liquid))
                else:
                    objects.pop(liquid, None)
                    drop(f for f in facts if liquid in (f.subject, f.object))
            if filled and not liquids:
                # Filled with something the scene does not name.
                portion = f"Liquid_from_{held}"
                objects[portion] = frozenset({"UnknownLiquid"})
                add(Fact(portion, "type", "UnknownLiquid", FactKind.TYPE))
                rel = (
                    "contains"
                    if self.vocab.any_is_a(state.objects[target], "ContainerReceptacle")
                    else "supports"
                )
                add(Fact(target, rel, portion))
            # A cleaner's chemical goes where it is poured.
            for chem in state.objects_of(held, "hasMaterial"):
                if chem in self.vocab.individuals and self.vocab.is_a(chem, "Chemical"):
                    portion = f"{chem}_from_{held}"
                    objects[portion] = frozenset({"PhysicalObject"})
                    add(Fact(portion, "type", "PhysicalObject", FactKind.TYPE))
                    add(Fact(portion, "hasMaterial", chem))
                    rel = (
                        "contains"
                        if self.vocab.any_is_a(state.objects[target], "ContainerReceptacle")
                        else "supports"
                    )
                    add(Fact(target, rel, portion))
            if liquids or filled:
                set_state(held, "EmptyState")
                if not self.vocab.any_is_a(
                    state.objects[target], "LiquidContainer"
                ) and not self.vocab.any_is_a(state.objects[target], "ContainerReceptacle"):
                    set_state(target, "WetState")
                elif self.vocab.any_is_a(state.objects[target], "LiquidContainer"):
                    set_state(target, "FilledWithLiquidState")
        elif verb in ("drop", "throw"):
            if held is None:
                return fail(
                    "Precondition_NothingHeld", agent, f"{agent} is holding nothing to {verb}"
                )
            drop([Fact(agent, "isHolding", held)])
            floors = [o for o in state.order if self.vocab.any_is_a(state.objects[o], "Floor")]
            if floors:
                add(Fact(floors[0], "supports", held))
        self._heat(objects, facts)
        return replace(
            state,
            objects=MappingProxyType(objects),
            facts=MappingProxyType(dict(sorted(facts.items()))),
            found=tuple(found),
        )

    def _heat(self, objects: Mapping[str, frozenset[str]], facts: dict[Fact, Provenance]) -> None:
        """A running heat source (microwave, lit burner, toaster) cooks the
        cookable things in or on it, and those in a pan or pot on it, as
        AI2-THOR does."""

        def holds(container: str) -> list[str]:
            return [
                f.object
                for f in facts
                if f.subject == container
                and f.kind is FactKind.OBJECT
                and f.predicate in ("contains", "supports")
            ]

        for source, classes in objects.items():
            if not self.vocab.any_is_a(classes, "HeatSourceObject"):
                continue
            if Fact(source, "hasState", "OnState") not in facts:
                continue
            reached = holds(source)
            reached += [inner for outer in reached for inner in holds(outer)]
            for obj in reached:
                facts.pop(Fact(obj, "hasState", "ColdState"), None)
                facts[Fact(obj, "hasState", "HotState")] = Provenance.PLAN
                if self.vocab.any_is_a(objects.get(obj, frozenset()), "Cookable"):
                    facts[Fact(obj, "hasState", "CookedState")] = Provenance.PLAN

    def _derive(
        self,
        state: WorldState,
        source: str,
        annotation: str,
        objects: dict[str, frozenset[str]],
        facts: dict[Fact, Provenance],
    ) -> None:
        """AI2-THOR replaces a sliced apple by AppleSliced pieces: add one piece
        of the derived type where the source was, visible to the agent."""
        for cls in sorted(state.objects[source]):
            derived = self.vocab.annotation(cls, annotation)
            if not derived or derived[0] not in self.vocab.classes:
                continue
            name = f"{derived[0]}_from_{source}"
            if name in objects:
                return
            objects[name] = frozenset({derived[0]})
            facts[Fact(name, "type", derived[0], FactKind.TYPE)] = Provenance.PLAN
            if annotation == "slicedType":
                facts[Fact(name, "hasState", "SlicedState")] = Provenance.PLAN
            facts[Fact(name, "isLocated", "true", FactKind.DATA)] = Provenance.PLAN
            for f in list(facts):
                if (
                    f.object == source
                    and f.predicate in ("contains", "supports")
                    and f.kind is FactKind.OBJECT
                ):
                    facts[Fact(f.subject, f.predicate, name)] = Provenance.PLAN
            return

    def _remove_liquids(
        self,
        state: WorldState,
        container: str,
        objects: dict[str, frozenset[str]],
        facts: dict[Fact, Provenance],
    ) -> None:
        for liquid in state.objects_of(container, "contains"):
            if self.vocab.any_is_a(state.objects.get(liquid, frozenset()), "Liquid"):
                objects.pop(liquid, None)
                for f in list(facts):
                    if liquid in (f.subject, f.object):
                        facts.pop(f, None)


def diff(before: WorldState, after: WorldState) -> tuple[tuple[str, ...], tuple[str, ...]]:
    added = tuple(f.render() for f in sorted(set(after.facts) - set(before.facts)))
    removed = tuple(f.render() for f in sorted(set(before.facts) - set(after.facts)))
    return added, removed
