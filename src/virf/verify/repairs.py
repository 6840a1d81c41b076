"""Checked corrections: edits to an UNSAFE plan that the tutor has already verified SAFE.

A small model repairs a plan badly from a diagnostic report alone; given a
short list of corrected plans it can copy one.  Every correction offered here
comes from the finding's mechanism, never from the task's words:

* **supply**: a fact of the finding that holds before the dangerous step and
  that one action ends (an object not located: ``find``; a closed door:
  ``open``) gets that action inserted just before the step; the result is
  verified and the next such step supplied, up to ``MAX_CHAIN`` times;
* **insert**: the dangerous state a step left behind (an ``OnState``, an
  ``OpenState``) is undone by the verb of the same affordance whose result is
  the other state (``turn_off`` for ``turn_on``, ``close`` for ``open``), right
  after the step that made it or at the end of the plan;
* **substitute**: an object the finding involves, made of a material the
  finding relies on, is replaced by another instance of the scene of a
  related type that affords what the plan does with it and is not known to
  be made of that material ("use Bowl_1 (Ceramic) instead of Pot_1 (Metal)");
* **drop**: the dangerous step is left out (alone, or with the later steps
  that act on its objects).

Drafts are ordered by how much of the original plan they keep, then by kind,
then by the order they were made in; at most ``MAX_TRIED`` are verified and
at most ``MAX_OFFERED`` offered.  A draft is offered only when the same tutor
finds it SAFE.  Anything else (UNSAFE, UNKNOWN, ERROR, an exception, a line
that does not parse, the search's deadline passing) drops that draft or ends
the search: the list fails closed, towards offering nothing.  A draft that
only moves the robot around (every step a ``find``) is never offered.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol

from virf.ontology.tbox import Vocabulary
from virf.schema import Fact, Provenance, Report, Violation
from virf.world.actions import AFFORDANCE, RESULT_STATE, TOGGLE_STATE, lacks
from virf.world.plan import PlanStep, parse_plan
from virf.world.scene import Scene
from virf.world.simulate import Trace, simulate
from virf.world.simulator import Simulator
from virf.world.state import WorldState

MAX_OFFERED = 3
MAX_TRIED = 12
# Missing preconditions supplied one after another before a plan passes.
MAX_CHAIN = 8
# The verb whose effect is a data value an action needs: only the find
# handler sets isLocated (Change.located), so it is the one way to supply it.
SUPPLIES = {("isLocated", "false"): "find"}
# The search's time when neither the caller nor the tutor says otherwise.
DEFAULT_BUDGET_S = 30.0
# Substitutes tried per involved object: the closest types first.
_SUBSTITUTES_PER_OBJECT = 3

# What a substitute must afford if the object it replaces does: every action
# affordance, and holding things the way the object did.
_CAPABILITIES = frozenset(
    {*AFFORDANCE.values(), "Receptacle", "ContainerReceptacle", "SurfaceReceptacle"}
)

Kind = Literal["insert", "substitute", "drop"]
_KIND_ORDER: dict[str, int] = {"insert": 0, "substitute": 1, "drop": 2}


class Checker(Protocol):
    def verify(self, scene: Scene, plan: Sequence[PlanStep]) -> Report: ...


@dataclass(frozen=True)
class Candidate:
    """One corrected plan: the edit in words, every line of the plan, and why."""

    kind: Kind
    edit: str
    plan: tuple[str, ...]
    why: str
    # Lines of the original plan the correction keeps as they were.
    kept: int

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "edit": self.edit,
            "plan": list(self.plan),
            "why": self.why,
            "kept": self.kept,
        }


def _undo_verbs() -> dict[str, str]:
    """State -> the verb that leaves it: the other verb of the same affordance
    among those whose only effect is a state (open/close, turn_on/turn_off)."""
    made = {**RESULT_STATE, **TOGGLE_STATE}
    out: dict[str, str] = {}
    for verb, state in made.items():
        need = AFFORDANCE.get(verb)
        for other, other_state in made.items():
            if need is not None and AFFORDANCE.get(other) == need and other_state != state:
                out[state] = other
    return out


UNDO = _undo_verbs()


def candidates(
    scene: Scene,
    plan: Sequence[PlanStep],
    report: Report,
    tutor: Checker,
    vocab: Vocabulary,
    *,
    deadline: float | None = None,
    max_offered: int = MAX_OFFERED,
    max_tried: int = MAX_TRIED,
) -> tuple[Candidate, ...]:
    """Corrections of ``plan`` that ``tutor`` verifies SAFE in ``scene``.

    ``report`` is the tutor's UNSAFE report on ``plan``; any other verdict
    gets none.  ``deadline`` is a :func:`time.monotonic` instant after which
    no further draft is verified; the search never runs longer than one of
    the tutor's own verifications may (its ``timeout_s``) either."""
    if report.status != "UNSAFE" or not plan or max_offered < 1:
        return ()
    budget = getattr(tutor, "timeout_s", DEFAULT_BUDGET_S)
    limit = time.monotonic() + (budget if isinstance(budget, int | float) else DEFAULT_BUDGET_S)
    if deadline is not None:
        limit = min(limit, deadline)
    try:
        drafts = _drafts(plan, report, scene, vocab)
    except Exception:
        # A draft that cannot even be made is not offered: fail closed.
        return ()
    offered: list[Candidate] = []
    tried = 0
    # First the plan with what its steps lack supplied before them (the step
    # that finds the object, the door opened): it keeps every line, and a
    # small model's plans usually lack several such steps, so each draft is
    # verified and the next missing one supplied, up to MAX_CHAIN.
    chain, spent = _supplied(plan, report, scene, vocab, tutor, limit, max_tried)
    tried += spent
    if chain is not None:
        offered.append(chain)
    for draft in drafts:
        if chain is not None and draft.plan == chain.plan:
            continue
        if tried >= max_tried or len(offered) >= max_offered or time.monotonic() > limit:
            break
        try:
            steps = parse_plan(draft.plan)
        except Exception:
            continue
        if not steps or all(s.verb == "find" for s in steps):
            continue  # doing nothing is no correction
        tried += 1
        try:
            verdict = tutor.verify(scene, steps)
        except Exception:
            continue
        if verdict.status == "SAFE":
            offered.append(draft)
    return tuple(offered)


def _supplied(
    plan: Sequence[PlanStep],
    report: Report,
    scene: Scene,
    vocab: Vocabulary,
    tutor: Checker,
    limit: float,
    max_tried: int,
) -> tuple[Candidate | None, int]:
    """The plan with each missing precondition of its dangerous step supplied
    just before it, repeated while the next report names another; (the
    candidate if the tutor finds the result SAFE, verifications spent)."""
    steps = list(plan)
    edits: list[str] = []
    reasons: list[str] = []
    spent = 0
    sim = Simulator(vocab)
    for _ in range(MAX_CHAIN):
        if spent >= max_tried or time.monotonic() > limit:
            return None, spent
        try:
            trace = simulate(sim, sim.initial(scene), steps)
            supply = _supply(report, steps, trace, vocab)
            if supply is None:
                return None, spent
            at, line, why = supply
            before = steps[at - 1].text
            # Parsed whole again: a step's number is part of it.
            texts = [s.text for s in steps]
            steps = list(parse_plan([*texts[: at - 1], line, *texts[at - 1 :]]))
            spent += 1
            report = tutor.verify(scene, steps)
        except Exception:
            return None, spent  # fail closed: nothing offered from a draft that broke
        edits.append(f"insert `{line}` before `{before}`")
        reasons.append(why)
        if report.status == "SAFE":
            return (
                Candidate(
                    "insert",
                    "; ".join(edits),
                    tuple(s.text for s in steps),
                    "; ".join(reasons),
                    len(plan),
                ),
                spent,
            )
        if report.status != "UNSAFE":
            return None, spent
    return None, spent


def _supply(
    report: Report, steps: Sequence[PlanStep], trace: Trace, vocab: Vocabulary
) -> tuple[int, str, str] | None:
    """The first step the dangerous step lacks: (its 1-based place, the line,
    why), from the facts of the finding that hold before the step and that
    one action ends (a closed door: open; an object not located: find)."""
    k = report.dangerous_step
    if k is None or not 1 <= k <= len(steps) or k > len(trace.states):
        return None
    before = trace.states[k - 1]
    for v in report.violations:
        if not v.definite or v.step != k:
            continue
        for t in v.triggering_facts:
            verb = (
                UNDO.get(t.object)
                if t.predicate == "hasState"
                else SUPPLIES.get((t.predicate, t.object))
            )
            if verb is None or t.subject not in before.objects:
                continue
            if verb in AFFORDANCE and lacks(vocab, t.subject, before, AFFORDANCE[verb]):
                continue
            if t.predicate == "hasState" and not before.has(t.subject, "hasState", t.object):
                continue  # the step itself made the state: undoing it comes after
            line = f"{verb} {t.subject}"
            why = f"{v.id} holds at `{steps[k - 1].text}` ({v.trigger_reason}); `{line}` ends it"
            return k, line, why
    return None


# ---------------------------------------------------------------- drafts
def _drafts(
    plan: Sequence[PlanStep], report: Report, scene: Scene, vocab: Vocabulary
) -> list[Candidate]:
    sim = Simulator(vocab)
    trace = simulate(sim, sim.initial(scene), plan)
    step = report.dangerous_step
    lines = tuple(s.text for s in plan)
    violations = [v for v in report.violations if v.definite and v.step == step]
    made: list[Candidate] = []
    for v in violations:
        made += _inserts(v, plan, trace, vocab)
        made += _substitutes(v, plan, trace, sim)
    made += _drops(step, plan, trace, violations)
    unique: dict[tuple[str, ...], Candidate] = {}
    for c in made:
        if c.plan and c.plan != lines:
            unique.setdefault(c.plan, c)
    # A stable sort: among equals, the order the drafts were made in.
    return sorted(unique.values(), key=lambda c: (-c.kept, _KIND_ORDER[c.kind]))


def _state_at(trace: Trace, step: int | None) -> WorldState:
    states = trace.states
    return states[min(step if step is not None else len(states) - 1, len(states) - 1)]


def _resolved_objects(trace: Trace, k: int) -> set[str]:
    """The objects step ``k`` (1-based) acts on, as the simulator resolved them."""
    if k > len(trace.resolved):
        return set()
    r = trace.resolved[k - 1]
    return {o for o in (r.target, r.patient, r.instrument, r.named_held) if o}


def _inserts(
    v: Violation, plan: Sequence[PlanStep], trace: Trace, vocab: Vocabulary
) -> list[Candidate]:
    """Undo each dangerous state the finding rests on."""
    at = _state_at(trace, v.step)
    states = [(t.subject, t.object) for t in v.triggering_facts if t.predicate == "hasState"]
    if not states:
        # Without an explanation (a batch verifier) the subject's states stand in.
        states = [(v.subject, s) for s in at.objects_of(v.subject, "hasState")]
    out: list[Candidate] = []
    n = len(plan)
    for obj, state in dict.fromkeys(states):
        verb = UNDO.get(state)
        if verb is None or obj not in at.objects:
            continue
        creator = _creator(trace, obj, state, v.step)
        targets = [obj]
        if creator is not None and creator <= len(trace.resolved):
            made_on = trace.resolved[creator - 1].target
            if made_on is not None and made_on != obj:
                targets.insert(0, made_on)  # the knob that lit the burner
        places = [creator if creator is not None else 0, n]
        for target in targets:
            if lacks(vocab, target, at, AFFORDANCE[verb]):
                continue
            line = f"{verb} {target}"
            for place in dict.fromkeys(places):
                where = f"after step {place}" if place else "before step 1"
                if place == n:
                    where = f"at the end (after step {n})"
                lines = (*(s.text for s in plan[:place]), line, *(s.text for s in plan[place:]))
                made = f"step {creator}" if creator else "the scene"
                out.append(
                    Candidate(
                        "insert",
                        f"insert `{line}` {where}",
                        lines,
                        f"{made} leaves {obj} in {state}, which {v.id} needs "
                        f"({v.trigger_reason}); `{line}` ends it",
                        n,
                    )
                )
    return out


def _creator(trace: Trace, obj: str, state: str, step: int | None) -> int | None:
    """The latest step up to ``step`` that put ``obj`` in ``state`` (None: the scene did)."""
    states = trace.states
    last = min(step if step is not None else len(states) - 1, len(states) - 1)
    for k in range(last, 0, -1):
        if states[k].has(obj, "hasState", state) and not states[k - 1].has(obj, "hasState", state):
            return k
    return None


def _materials(vocab: Vocabulary, state: WorldState, obj: str) -> set[str]:
    """What ``obj`` is known to be made of: its types' materials and the
    scene's statements, not the open world's guesses."""
    stated = {
        m
        for m in state.objects_of(obj, "hasMaterial")
        if state.facts.get(Fact(obj, "hasMaterial", m)) is not Provenance.ASSUMED
    }
    return ({*vocab.materials_of(state.objects.get(obj, frozenset())), *stated}) - {
        "UnknownMaterial"
    }


def _capabilities(vocab: Vocabulary, classes: frozenset[str]) -> set[str]:
    """The action affordances (and receptacle kinds) a type has for sure."""
    return {c for c in _CAPABILITIES if vocab.any_is_a(classes, c)}


def _label(vocab: Vocabulary, term: str) -> str:
    return next(iter(vocab.annotation(term, "label")), term)


def _violation_words(v: Violation) -> set[str]:
    texts = [v.message, *(b.text for b in v.background)]
    texts += [f"{t.subject} {t.predicate} {t.object}" for t in v.triggering_facts]
    return {w.strip(".,;:()") for text in texts for w in text.split()}


def _substitutes(
    v: Violation, plan: Sequence[PlanStep], trace: Trace, sim: Simulator
) -> list[Candidate]:
    """Replace an involved object made of a material the finding names."""
    vocab = sim.vocab
    start = trace.states[0]
    words = _violation_words(v)
    involved = [v.subject]
    for t in v.triggering_facts:
        involved += [t.subject, *(t.members or (t.object,))]
    out: list[Candidate] = []
    for obj in dict.fromkeys(involved):
        if obj not in start.objects or obj == start.agent:
            continue
        matters = sorted(_materials(vocab, start, obj) & words)
        if not matters:
            continue
        uses = [k for k in range(1, len(trace.resolved) + 1) if obj in _resolved_objects(trace, k)]
        if not uses:
            continue
        for other in _substitutes_for(obj, uses, matters, trace, vocab):
            rewritten = _rewrite(plan, trace, sim, obj, other)
            if rewritten is None:
                continue
            lines, changed = rewritten
            has = sorted(_materials(vocab, start, other))
            described = ", ".join(_label(vocab, m) for m in has) or "not " + " or ".join(
                _label(vocab, m) for m in matters
            )
            was = ", ".join(_label(vocab, m) for m in matters)
            out.append(
                Candidate(
                    "substitute",
                    f"use {other} ({described}) instead of {obj} ({was})",
                    lines,
                    f"{v.id} needs {obj} to be {was} ({v.trigger_reason}); {other} is {described}",
                    len(plan) - changed,
                )
            )
    return out


def _substitutes_for(
    obj: str, uses: Sequence[int], matters: Sequence[str], trace: Trace, vocab: Vocabulary
) -> list[str]:
    """Scene instances of a related type that afford what the plan does with
    ``obj`` and are not known to be made of the materials that matter."""
    start = trace.states[0]
    mine = start.objects[obj]
    needs = _capabilities(vocab, mine) | {
        AFFORDANCE[trace.resolved[k - 1].step.verb]
        for k in uses
        if trace.resolved[k - 1].target == obj and trace.resolved[k - 1].step.verb in AFFORDANCE
    }
    generic = {"PhysicalObject", *vocab.ancestors.get("PhysicalObject", frozenset())}

    def family(classes: Iterable[str]) -> set[str]:
        return {a for c in classes for a in (c, *vocab.ancestors.get(c, frozenset()))} - generic

    own = family(mine)
    ranked: list[tuple[int, int, str]] = []
    for other in start.order:
        classes = start.objects.get(other, frozenset())
        if other == obj or other == start.agent or not vocab.any_is_a(classes, "PhysicalObject"):
            continue
        shared = own & family(classes)
        if not shared or not all(
            vocab.any_is_a(classes, need) or vocab.may_afford(classes, need) for need in needs
        ):
            continue
        if _materials(vocab, start, other) & set(matters):
            continue
        ranked.append((0 if classes == mine else 1, -len(shared), other))
    return [other for _, _, other in sorted(ranked)[:_SUBSTITUTES_PER_OBJECT]]


def _rewrite(
    plan: Sequence[PlanStep], trace: Trace, sim: Simulator, obj: str, other: str
) -> tuple[tuple[str, ...], int] | None:
    """The plan with every word that named ``obj`` naming ``other``, and how
    many lines changed (None when no line named it)."""
    lines: list[str] = []
    changed = 0
    for k, step in enumerate(plan):
        if k >= len(trace.states):  # not simulated: nothing resolved its words
            lines.append(step.text)
            continue
        state = trace.states[k]
        args = list(step.args)
        slots = range(1) if step.verb == "fillLiquid" else range(len(args))
        hit = False
        for i in slots:
            if sim.resolve_term(state, args[i]) == obj:
                args[i], hit = other, True
        if not hit:
            lines.append(step.text)
            continue
        changed += 1
        if step.verb == "put" and len(args) == 2:
            surface = sim.vocab.any_is_a(
                state.objects.get(args[1], frozenset()), "SurfaceReceptacle"
            )
            lines.append(f"put {args[0]} {'on' if surface else 'in'} {args[1]}")
        else:
            lines.append(" ".join((step.verb, *args)))
    return (tuple(lines), changed) if changed else None


def _drops(
    step: int | None, plan: Sequence[PlanStep], trace: Trace, violations: Sequence[Violation]
) -> list[Candidate]:
    """Leave out the dangerous step, alone or with the later steps on its objects."""
    n = len(plan)
    if step is None or not 1 <= step <= n or not violations:
        return []
    rule = violations[0].id
    text = plan[step - 1].text
    objects = _resolved_objects(trace, step)
    later = [k for k in range(step + 1, n + 1) if objects & _resolved_objects(trace, k)]
    out = []
    for left_out in dict.fromkeys([(step,), (step, *later)]):
        lines = tuple(s.text for k, s in enumerate(plan, start=1) if k not in left_out)
        edit = f"drop step {step} (`{text}`)"
        if len(left_out) > 1:
            edit += (
                " and the steps after it on the same objects ("
                + ", ".join(map(str, left_out[1:]))
                + ")"
            )
        out.append(
            Candidate(
                "drop",
                edit,
                lines,
                f"{rule} holds at step {step}; without it the plan passes verification",
                n - len(left_out),
            )
        )
    return out
