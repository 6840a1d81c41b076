"""Sandbox simulator: deterministic preconditions and effects of the 17 actions.

States are immutable; ``apply`` returns a new state and never touches the
input scene.  The simulator decides only whether an action *can* run and what
it changes.  Whether the result is safe is the reasoner's business.  The
states live in :mod:`virf.world.state`, each verb's preconditions and effects
in :mod:`virf.world.actions`; this module reads the scene, resolves plan words
to instances and runs one step.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Any

from virf.errors import EnvironmentProblem
from virf.names import name_words, term_key
from virf.ontology.tbox import Vocabulary
from virf.schema import Fact, FactKind, Provenance
from virf.world.actions import (
    AFFORDANCE,
    HANDLERS,
    LIQUID_CLASS,
    RESULT_STATE,
    Change,
    heat,
    lacking_affordance,
    lacks,
)
from virf.world.language import STATE_ADJECTIVES
from virf.world.plan import PlanStep, singular_forms
from virf.world.scene import Scene
from virf.world.state import (
    MissingObject,
    PreconditionFailure,
    ResolvedStep,
    WorldState,
    changed,
    diff,
)

# What importers of this module have always found here.
__all__ = [
    "AFFORDANCE",
    "LIQUID_CLASS",
    "RESULT_STATE",
    "MissingObject",
    "PreconditionFailure",
    "ResolvedStep",
    "Simulator",
    "WorldState",
    "diff",
]


class Simulator:
    def __init__(self, vocab: Vocabulary) -> None:
        self.vocab = vocab
        self._holders: dict[frozenset[str], tuple[bool, tuple[bool, ...]]] = {}
        self._heaters: dict[frozenset[str], bool] = {}  # see Change
        # The last scene started from, and its state: a scene is read-only and
        # a state immutable, so verifying another plan in it (the planner's
        # next attempt) starts from the same state, with its indexes and
        # closures already built.
        self._start: tuple[Scene, WorldState] | None = None
        # The last state whose closures were all read, and those closures.
        self._closures: tuple[WorldState, dict[Fact, Provenance]] | None = None

    # ------------------------------------------------------------------ setup
    def initial(self, scene: Scene) -> WorldState:
        start = self._start
        if start is not None and start[0] is scene:
            return start[1]
        facts = dict(scene.facts)
        held = {f.object for f in facts if f.subject == scene.agent and f.predicate == "isHolding"}
        stated = {f.subject for f in facts if f.predicate == "isLocated"}
        for ind in scene.order:
            if self._is_physical(scene.objects[ind]) and ind not in stated:
                located = ind in held or not scene.unlocated_by_default
                facts[Fact(ind, "isLocated", "true" if located else "false", FactKind.DATA)] = (
                    Provenance.SCENE
                )
        state = WorldState(
            objects=scene.objects,
            order=scene.order,
            # By the facts' kept sort keys: a Python ``__lt__`` per comparison
            # cost a thousand objects' scene more than the rest of its start.
            facts=MappingProxyType({f: facts[f] for f in Fact.sorted(facts)}),
            agent=scene.agent,
            closed_world=scene.closed_world,
            unknown_contents=scene.unknown_contents,
            referents=scene.referents,
            open_world=scene.open_world,
        )
        self._start = (scene, state)
        return state

    def _is_physical(self, classes: frozenset[str]) -> bool:
        return self.vocab.any_is_a(classes, "PhysicalObject")

    def lacks(self, obj: str, state: WorldState, affordance: str) -> bool:
        return lacks(self.vocab, obj, state, affordance)

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
        if state.named(term) or state.named_stem(term) or self.class_named(term):
            return term
        readings: dict[str, str] = {}
        for form in singular_forms(term):
            named = state.named(form) or state.named_stem(form)
            target = named[0] if len(named) == 1 else self.class_named(form)
            if target is not None or named:
                readings.setdefault(target or term_key(form), form)
        # Two singulars naming different things would be a guess.
        return next(iter(readings.values())) if len(readings) == 1 else None

    def read_term(self, state: WorldState, term: str) -> tuple[str | None, tuple[str, ...]]:
        """The spelling of the name in ``term`` and the states its leading
        adjectives ask for: 'lit candle' -> ('candle', ('OnState',)).  The
        words are read as adjectives only when the whole term names nothing,
        so a name that starts like one stays a name."""
        spelled = self.spelling(state, term)
        if spelled is not None:
            return spelled, ()
        words = term.split()
        wanted: list[str] = []
        while len(words) > 1 and words[0].lower() in STATE_ADJECTIVES:
            wanted.append(STATE_ADJECTIVES[words.pop(0).lower()])
        if not wanted:
            return None, ()
        spelled = self.spelling(state, " ".join(words))
        return spelled, (tuple(dict.fromkeys(wanted)) if spelled is not None else ())

    def resolve_term(
        self, state: WorldState, term: str, prefer: str | None = None
    ) -> str | tuple[str, ...] | None:
        """The instance ``term`` names; None if none; the candidates if the
        choice is ambiguous (several equally plausible instances).
        ``prefer`` wins among the candidates (the held object, for a line that
        says it is held: 'throw the mug')."""
        spelled, wanted = self.read_term(state, term)
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
        everything = state.order + tuple(sorted(set(state.objects) - set(state.order)))
        # Instances of the type the words name, and those whose name without
        # its number the words spell (HairDryer_1 for 'hair dryer', typed only
        # PhysicalObject).
        stems = set(state.named_stem(spelled))
        candidates = [
            ind
            for ind in everything
            if ind != state.agent
            and (ind in stems or (cls is not None and self.vocab.any_is_a(state.objects[ind], cls)))
        ]
        if not candidates:
            return None
        if wanted and len(candidates) > 1:
            # 'the lit candle': the state chooses among the candles.  When it
            # fits none of them, which one is meant is a question.
            fitting = [c for c in candidates if all(state.has(c, "hasState", s) for s in wanted)]
            if not fitting:
                return tuple(sorted(candidates))
            candidates = fitting
        if prefer in candidates:
            return prefer
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
            if self.read_term(state, " ".join(words[:i]))[0]
            and self.read_term(state, " ".join(words[i:]))[0]
        ]

    @staticmethod
    def near(term: str, pool: Iterable[str], n: int = 3) -> tuple[str, ...]:
        """The closest known names, compared in compacted form so that
        'dinning table' finds DiningTable."""
        by_key: dict[str, str] = {}
        for name in sorted(set(pool)):
            by_key.setdefault(term_key(name), name)
        hits = difflib.get_close_matches(term_key(term), list(by_key), n=n, cutoff=0.5)
        found = [by_key[h] for h in hits]
        if len(found) < n:
            found += [m for m in _by_meaning(term, by_key.values()) if m not in found]
        return tuple(found[:n])

    def resolve(self, state: WorldState, step: PlanStep) -> ResolvedStep | MissingObject:
        def need(term: str, prefer: str | None = None) -> str | MissingObject:
            found = self.resolve_term(state, term, prefer)
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
        # The object the line says is in the hand ('throw AlarmClock'): among
        # the instances its words name, the held one; the action's handler
        # refuses the step when the hand holds another object or nothing.
        named_held: str | None = None
        if step.held_term is not None:
            found_held = need(step.held_term, prefer=held)
            if isinstance(found_held, MissingObject):
                return found_held
            named_held = found_held
        # What the step acts on as held: nothing when the line names another
        # object, so a step that cannot run claims no action on either.
        patient_held = held if named_held in (None, held) else None
        # The whole phrase names the receptacle if it can ("put dining table");
        # otherwise one object-receptacle split must work, since choosing
        # between several would be a guess.
        if verb == "put" and len(args) == 1 and self.read_term(state, args[0])[0] is None:
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
                named = need(args[0], prefer=held)
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
            return ResolvedStep(step, target=dest_r, patient=patient_held, named_held=named_held)
        if verb in ("drop", "throw"):
            return ResolvedStep(step, patient=patient_held, named_held=named_held)
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
    def closure_facts(
        self,
        state: WorldState,
        since: tuple[WorldState, Mapping[Fact, Provenance]] | None = None,
    ) -> dict[Fact, Provenance]:
        """What the simulator believes are the complete contents of things.

        Known for the robot's own hand; for receptacles only as far as the
        scene says its listing is complete (``closed_world``), otherwise an
        open-world assumption that a finding must ask about.

        ``since`` is an earlier state and its closure facts: only the holders
        whose contents or states differ between the two are read again (a
        step moves a few of a thousand objects).  The result is the same
        dict, in the same order.
        """
        touched = self._touched(since[0], state) if since is not None else None
        if since is None or touched is None:
            # Read once per state: the first state of every verification in a
            # scene is the same one (see initial).
            kept = self._closures
            if kept is not None and kept[0] is state:
                return dict(kept[1])
            out = self._all_closures(state)
            self._closures = (state, out)
            return dict(out)
        out = self._hand_closure(state)
        done: set[str] = set()
        for f, prov in since[1].items():
            ind = f.subject
            if ind == state.agent and f.predicate == "isHolding":
                continue
            if ind not in touched:
                out[f] = prov
            elif ind not in done:
                # The holder's closures keep their place: which relations it
                # has closures for depends only on its classes.
                done.add(ind)
                out.update(self._holder_closures(state, ind))
        return out

    def _all_closures(self, state: WorldState) -> dict[Fact, Provenance]:
        out = self._hand_closure(state)
        for ind in state.order + tuple(sorted(set(state.objects) - set(state.order))):
            out.update(self._holder_closures(state, ind))
        return out

    @staticmethod
    def _hand_closure(state: WorldState) -> dict[Fact, Provenance]:
        held = state.objects_of(state.agent, "isHolding")
        return {Fact.closure(state.agent, "isHolding", held): Provenance.PLAN}

    @staticmethod
    def _touched(before: WorldState, after: WorldState) -> set[str] | None:
        """The objects whose closures may differ from ``before`` to ``after``;
        None when anything else they depend on changed."""
        if (
            before.agent != after.agent
            or before.order != after.order
            or before.closed_world != after.closed_world
            or before.unknown_contents != after.unknown_contents
            or before.objects != after.objects
        ):
            return None
        return {f.subject for f in changed(before, after) if f.predicate in _CLOSURE_INPUTS}

    def _holder_closures(self, state: WorldState, ind: str) -> dict[Fact, Provenance]:
        """The closure facts of one object (none unless it holds things)."""
        out: dict[Fact, Provenance] = {}
        vessel, kinds = self._holder_kinds(state.objects[ind])
        if not (vessel or any(kinds)):
            return out
        unknown_fill = state.has(ind, "hasState", "UnknownFillState")
        for (rel, _), receptacle in zip(_HOLDERS, kinds, strict=True):
            if receptacle or (rel == "contains" and vessel):
                members = state.objects_of(ind, rel)
                listed = (
                    rel in state.closed_world or f"{rel}:{ind}" in state.closed_world
                ) or not receptacle
                known = (
                    listed
                    and ind not in state.unknown_contents
                    and not (rel == "contains" and unknown_fill)
                )
                prov = Provenance.SCENE if known else Provenance.ASSUMED
                out[Fact.closure(ind, rel, members)] = prov
        return out

    def _holder_kinds(self, classes: frozenset[str]) -> tuple[bool, tuple[bool, ...]]:
        """Whether things of ``classes`` are vessels, and receptacles of each
        kind of :data:`_HOLDERS`; remembered per set of classes (a scene of
        a thousand objects has a few dozen), as every state asks them all."""
        found = self._holders.get(classes)
        if found is None:
            # A vessel nothing can be put into (a bottle, a kettle) holds only
            # the liquid the state gives it; while its fill is unknown, so is
            # what it holds.
            vessel = self.vocab.any_is_a(classes, "LiquidContainer")
            kinds = tuple(self.vocab.any_is_a(classes, cls) for _, cls in _HOLDERS)
            found = self._holders[classes] = (vessel, kinds)
        return found

    # ------------------------------------------------------------------ effects
    def apply(self, state: WorldState, r: ResolvedStep) -> WorldState | PreconditionFailure:
        change = self.change(state, r)
        return change if isinstance(change, PreconditionFailure) else change.result()

    def change(self, state: WorldState, r: ResolvedStep) -> Change | PreconditionFailure:
        """What the step does to ``state``, as the working copy of its facts
        before it becomes the next state (a test reads what its effects found)."""
        change = Change(self.vocab, state, r, self._heaters)
        failure = lacking_affordance(change)
        if failure is None:
            # A verb without a handler changes nothing itself; running heat
            # sources still do their work below.
            handler = HANDLERS.get(r.step.verb)
            failure = handler(change) if handler is not None else None
        if failure is not None:
            return failure
        heat(change)
        return change


# How near in meaning a scene's name must be to a plan's word to be offered
# ('the sink' -> SinkBasin_1; 'hob' -> StoveBurner_1).
MEANING_FLOOR = 0.5
# What a receptacle holds, by relation and the class that makes one.
_HOLDERS = (("contains", "ContainerReceptacle"), ("supports", "SurfaceReceptacle"))
# The predicates of the facts a holder's closures are read from.
_CLOSURE_INPUTS = frozenset({"contains", "supports", "hasState"})


# Sentence vectors of name words, by text: the model and its input are fixed,
# so a vector never goes stale; the bound only caps memory (384 floats each).
_VECTORS: dict[str, Any] = {}  # text -> float32 vector (numpy)
_VECTORS_KEPT = 20_000


def _by_meaning(term: str, names: Iterable[str]) -> list[str]:
    """Names of the scene nearest ``term`` in meaning (the bundled sentence
    embedder), for a word neither spelling nor the catalogue resolves. Only
    asked on that path: it loads the model."""
    from virf.embed import default_embedder

    pool = sorted(set(names))
    if not pool or not re.search(r"[A-Za-z]{2}", term):
        return []
    texts = [name_words(n) for n in pool]
    query_text = name_words(term)
    try:
        embedder = default_embedder()
        # A scene's names are asked about again and again (every plan that
        # names a missing object, every iteration of the loop); encoding
        # them is most of a verification's time on this path, so each text
        # is encoded once per process.  Alone, not in a batch: a batch pads
        # its texts to one width, and a vector must not depend on which
        # scene first asked for it (the same input, the same report).
        new = [t for t in dict.fromkeys([*texts, query_text]) if t not in _VECTORS]
        if len(_VECTORS) + len(new) > _VECTORS_KEPT:
            _VECTORS.clear()
        for text in new:
            _VECTORS[text] = embedder.encode([text])[0]
    except (EnvironmentProblem, OSError):  # no model: spelling alone
        return []
    query = _VECTORS[query_text]
    scores = [round(float(_VECTORS[t] @ query), 4) for t in texts]
    ranked = sorted(zip(scores, pool, strict=True), key=lambda sp: (-sp[0], sp[1]))
    return [name for score, name in ranked if score >= MEANING_FLOOR]
