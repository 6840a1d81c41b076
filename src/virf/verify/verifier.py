"""The Logic Tutor: simulate a plan in a sandbox and ask the reasoner what is unsafe.

Protocol (the paper's Algorithm 2, extended):

* The simulator builds states S0..Sn from the scene.  Snapshot k is Sk plus
  the next action a(k+1) as an individual (the walkthrough's one-step
  lookahead): state-based concepts found in snapshot k belong to step k
  (step 0 is the initial scene), action-based ones to step k+1.
* Concepts marked ``checkAt final`` are asked only of Sn and reported at the
  last step (the message says from which step the condition held).
* A failed precondition or an object the scene lacks stops the simulation;
  the first is UNSAFE (logical inconsistency), the second UNKNOWN.
* A finding is *definite* unless it is an uncertainty concept or its minimal
  support contains an open-world assumption; definite findings make the plan
  UNSAFE at the first step that has one, otherwise uncertain ones make it
  UNKNOWN with questions.  An inconsistent snapshot is UNKNOWN.
* Fail closed: any error or timeout gives status ERROR, never SAFE.  The
  timeout is one deadline for the whole verification: every engine call gets
  it and stops inside its own work once it passes, so a step that could not
  be checked in time is never taken as safe.
"""

from __future__ import annotations

import time
from collections.abc import Collection, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from queue import Queue
from typing import Literal

from virf.ontology.tbox import TBox, UnsafeStateConcept
from virf.reasoning import Classification, DeadlineExceeded, Engine, ReasonerFailure
from virf.schema import (
    BackgroundKnowledge,
    CausalChain,
    Fact,
    FactKind,
    Provenance,
    Question,
    Report,
    StepTrace,
    ViolatedConcept,
    Violation,
)
from virf.verify.explain import minimize, needed_background
from virf.verify.questions import (
    contradiction_question,
    requirement_question,
    rule_questions,
    where_question,
    which_question,
)
from virf.verify.requirements import Requirement, StepEvent, Unreadable, check_requirement
from virf.world.plan import PlanStep
from virf.world.scene import Scene
from virf.world.simulate import simulate
from virf.world.simulator import (
    MissingObject,
    PreconditionFailure,
    ResolvedStep,
    Simulator,
    WorldState,
    diff,
)

Outcome = Literal["ok", "unsafe", "unknown", "not-checked", "not-simulated", "error"]
DANGER_RANK = {"critical": 0, "high": 1, "medium": 2, "low": 3}
PHASE_RANK = {
    "requirement": 8,
    "precondition": 0,
    "action": 1,
    "initial": 2,
    "state": 3,
    "final": 4,
    "missing-object": 5,
    "inconsistency": 6,
    "error": 7,
}


class VerificationTimeout(Exception):
    pass


@dataclass
class _Finding:
    concept: UnsafeStateConcept
    step: int
    phase: str
    subject: str
    definite: bool
    facts: list[Fact]
    provenance: Mapping[Fact, Provenance]
    background: list[BackgroundKnowledge] = field(default_factory=list)
    message: str = ""
    questions: list[Question] = field(default_factory=list)


class Verifier:
    def __init__(
        self,
        tbox: TBox,
        engine: Engine,
        timeout_s: float = 120.0,
        explain: bool = True,
        workers: int = 1,
        uscs: Collection[str] | None = None,
    ) -> None:
        """``explain=False`` skips the minimal explanations (batch runs that only
        need verdicts): findings then carry no triggering facts, and whether
        they are definite is decided by one entailment test without the
        assumed facts.

        ``workers > 1`` classifies the plan's snapshots in parallel, each on
        its own engine instance (the paper's parallel step checking).  The
        snapshots are still built in order and the results are read in
        order, so reports do not depend on the worker count.

        ``uscs`` restricts the check to those Unsafe State Concepts (the
        knowledge-source ablations); by default every one is checked."""
        if workers < 1:
            raise ValueError("workers must be at least 1")
        self.workers = workers
        self._engines: Queue[Engine] | None = None
        self._pending: list[Future[Classification]] = []
        self._step = -1  # the snapshot being checked, for the timeout message
        self._deadline = float("inf")  # of the verification under way
        self.explain = explain
        self.tbox = tbox
        self.vocab = tbox.vocabulary
        self.engine = engine
        self.sim = Simulator(self.vocab)
        self.timeout_s = timeout_s
        if uscs is not None:
            unknown = sorted(set(uscs) - set(self.vocab.uscs))
            if unknown:
                raise ValueError(f"not an Unsafe State Concept: {unknown[0]}")
        ordered = sorted(
            (u for u in self.vocab.uscs.values() if uscs is None or u.name in uscs),
            key=lambda u: u.name,
        )
        self.always = [u.name for u in ordered if not u.final_only]
        self.final = [u.name for u in ordered if u.final_only]

    # ------------------------------------------------------------------ public
    def verify(
        self,
        scene: Scene,
        plan: Sequence[PlanStep],
        requirements: Sequence[Requirement | Unreadable] = (),
    ) -> Report:
        """Verify ``plan`` in ``scene`` (and the task's step-bounded
        ``requirements``).  Never raises for a verification problem: errors
        become an ERROR report (fail closed)."""
        self._step = -1
        try:
            return self._verify(scene, plan, requirements)
        except VerificationTimeout as exc:
            return self._error(plan, f"verification timed out: {exc}")
        except DeadlineExceeded as exc:
            where = f" at step {self._step}" if self._step >= 0 else ""
            return self._error(
                plan, f"verification timed out: more than {self.timeout_s:g}s{where} ({exc})"
            )
        except ReasonerFailure as exc:
            return self._error(plan, f"reasoner failure: {exc}")
        except Exception as exc:
            return self._error(plan, f"internal error: {type(exc).__name__}: {exc}")
        finally:
            # Steps classified ahead are not needed after a definite finding
            # or a failure; those already running stop at the deadline.
            for pending in self._pending:
                pending.cancel()
            self._pending = []

    # ------------------------------------------------------------------ protocol
    def _verify(
        self,
        scene: Scene,
        plan: Sequence[PlanStep],
        requirements: Sequence[Requirement | Unreadable],
    ) -> Report:
        deadline = time.monotonic() + self.timeout_s
        self._deadline = deadline
        states, resolved, stop = self._simulate(scene, plan)
        complete = stop is None
        n = len(states) - 1

        findings: dict[int, list[_Finding]] = {}
        for f in self._requirements(requirements, states, resolved, len(plan)):
            findings.setdefault(f.step, []).append(f)
        self._checked = -1  # last snapshot the reasoner answered for
        seen: set[tuple[str, str]] = set()
        first_definite: int | None = None
        concept_lists = [
            self.always + (self.final if complete and k == n else []) for k in range(len(states))
        ]
        # In order, one at a time, unless they are classified in parallel: a
        # definite finding usually ends the loop long before the last step.
        parallel = self.workers > 1 and len(states) > 1
        built = (
            [self._snapshot(states, resolved, k) for k in range(len(states))] if parallel else []
        )
        ahead = self._classify_ahead(built, concept_lists, deadline) if parallel else []
        self._pending = ahead
        for k in range(len(states)):
            self._step = k
            if time.monotonic() > deadline:
                raise VerificationTimeout(f"more than {self.timeout_s:g}s at step {k}")
            snapshot = built[k] if parallel else self._snapshot(states, resolved, k)
            action_ind = None
            if k < len(resolved):
                action_ind = Simulator.action_individual(resolved[k].step)
            result = (
                ahead[k].result()
                if ahead
                else self.engine.classify(snapshot.keys(), concept_lists[k], deadline=deadline)
            )
            self._checked = k
            if not result.consistent:
                findings.setdefault(k, []).append(self._inconsistency(snapshot, k))
                break
            for concept, individuals in sorted(result.instances.items()):
                usc = self.vocab.uscs[concept]
                for ind in individuals:
                    if ind == action_ind:
                        at, phase = k + 1, "action"
                    elif usc.final_only:
                        at, phase = k, "final"
                    else:
                        at, phase = k, "initial" if k == 0 else "state"
                    key = (concept, ind if phase != "action" else f"{ind}")
                    if key in seen and phase not in ("final",):
                        continue
                    seen.add(key)
                    f = self._explain(usc, ind, at, phase, snapshot)
                    if phase == "final":
                        # A hazard left behind belongs to the end of the plan;
                        # the message says since when it has held.
                        onset = self._onset(f.facts, states, n)
                        f.message += f" It holds from step {onset} until the plan ends."
                    findings.setdefault(f.step, []).append(f)
            if stop is not None and k == len(states) - 1:
                findings.setdefault(stop.step.index, []).append(self._stopped(stop, states[-1]))
            # Step k is complete once snapshot k is in (its action findings came from k-1).
            done = [s for s in findings if s <= k or (stop is not None and k == n)]
            definite = [s for s in done if any(f.definite for f in findings[s])]
            if definite:
                first_definite = min(definite)
                break
        return self._report(plan, states, resolved, stop, findings, first_definite, scene.spelling)

    def _simulate(
        self, scene: Scene, plan: Sequence[PlanStep]
    ) -> tuple[list[WorldState], list[ResolvedStep], MissingObject | PreconditionFailure | None]:
        """States S0..Sn, stopping at an unknown object or a failed precondition."""
        trace = simulate(self.sim, self.sim.initial(scene), plan)
        return list(trace.states), list(trace.resolved), trace.stop

    def snapshots(self, scene: Scene, plan: Sequence[PlanStep]) -> list[dict[Fact, Provenance]]:
        """The ABox the reasoner sees for each step (for baselines and tools)."""
        states, resolved, _ = self._simulate(scene, plan)
        return [self._snapshot(states, resolved, k) for k in range(len(states))]

    def _snapshot(
        self, states: list[WorldState], resolved: list[ResolvedStep], k: int
    ) -> dict[Fact, Provenance]:
        """State k, its closure facts, and action k+1 (the one-step lookahead)."""
        state = states[k]
        snapshot: dict[Fact, Provenance] = dict(state.facts)
        snapshot.update(self.sim.closure_facts(state))
        if k < len(resolved):
            snapshot.update(self.sim.action_facts(state, resolved[k]))
        return snapshot

    def _classify_ahead(
        self, snapshots: list[dict[Fact, Provenance]], concepts: list[list[str]], deadline: float
    ) -> list[Future[Classification]]:
        """Start classifying every snapshot, each on a free engine of the pool."""
        if self._engines is None:
            self._engines = Queue()
            self._engines.put(self.engine)
            for _ in range(self.workers - 1):
                self._engines.put(self.engine.fork())
            self._pool = ThreadPoolExecutor(self.workers, thread_name_prefix="virf-step")
        engines = self._engines

        def classify(k: int) -> Classification:
            engine = engines.get()
            try:
                return engine.classify(snapshots[k].keys(), concepts[k], deadline=deadline)
            finally:
                engines.put(engine)

        return [self._pool.submit(classify, k) for k in range(len(snapshots))]

    # ------------------------------------------------------------------ findings
    def _explain(
        self,
        usc: UnsafeStateConcept,
        ind: str,
        step: int,
        phase: str,
        snapshot: Mapping[Fact, Provenance],
    ) -> _Finding:
        if not self.explain and phase != "final":  # final findings need facts for their onset
            return self._quick(usc, ind, step, phase, snapshot)
        return self._explain_full(usc, ind, step, phase, snapshot)

    def _explain_full(
        self,
        usc: UnsafeStateConcept,
        ind: str,
        step: int,
        phase: str,
        snapshot: Mapping[Fact, Provenance],
    ) -> _Finding:
        facts = minimize(
            snapshot,
            lambda fs: (
                self._tick() and self.engine.entails(fs, usc.name, ind, deadline=self._deadline)
            ),
            {ind},
            self.vocab,
        )
        background_ids = needed_background(
            self.engine, facts, usc.name, ind, self.vocab, deadline=self._deadline
        )
        assumed = [f for f in facts if snapshot[f] is Provenance.ASSUMED]
        defaults = [f for f in facts if snapshot[f] is Provenance.DEFAULT]
        background = [
            BackgroundKnowledge(
                id=b, text=self.vocab.background[b].text, source=self.vocab.background[b].source
            )
            for b in background_ids
        ] + [
            BackgroundKnowledge(
                id=f"DEFAULT-{f.subject}-{f.object}",
                text=f"{f.render()} (typical material of its class; the scene states none)",
                source="VIRF kitchen catalogue (typicalMaterial)",
            )
            for f in defaults
        ]
        definite = usc.kind != "uncertainty" and not assumed
        questions = [] if definite else rule_questions(usc, ind, facts, assumed, step, self.vocab)
        chain = "; ".join(f.render() for f in facts if snapshot[f] is not Provenance.DEFAULT)
        extra = "; ".join(b.text for b in background)
        message = f"{usc.trigger_reason[:1].upper()}{usc.trigger_reason[1:]}: {chain}"
        if extra:
            message += f"; background knowledge: {extra}"
        message += f". Hence {ind} is an instance of {usc.name}."
        return _Finding(
            usc, step, phase, ind, definite, facts, dict(snapshot), background, message, questions
        )

    def _tick(self) -> bool:
        """Enforce the verification deadline between reasoner calls (the calls
        themselves stop at it too)."""
        if time.monotonic() > self._deadline:
            raise VerificationTimeout(f"more than {self.timeout_s:g}s while explaining a finding")
        return True

    def _quick(
        self,
        usc: UnsafeStateConcept,
        ind: str,
        step: int,
        phase: str,
        snapshot: Mapping[Fact, Provenance],
    ) -> _Finding:
        known = [f for f, p in snapshot.items() if p is not Provenance.ASSUMED]
        definite = usc.kind != "uncertainty" and self.engine.entails(
            known, usc.name, ind, deadline=self._deadline
        )
        if not definite:  # uncertain findings are rare; their questions need the proof
            return self._explain_full(usc, ind, step, phase, snapshot)
        message = f"{usc.trigger_reason[:1].upper()}{usc.trigger_reason[1:]} ({ind})."
        return _Finding(usc, step, phase, ind, definite, [], dict(snapshot), [], message)

    def _onset(self, facts: list[Fact], states: list[WorldState], n: int) -> int:
        """Earliest step from which a final-state finding's facts hold to the end."""
        onset = n
        for k in range(n, -1, -1):
            present = set(states[k].facts) | set(self.sim.closure_facts(states[k]))
            if all(f in present for f in facts):
                onset = k
            else:
                break
        return onset

    def _inconsistency(self, snapshot: Mapping[Fact, Provenance], k: int) -> _Finding:
        facts = minimize(
            snapshot,
            lambda fs: self._tick() and not self.engine.consistent(fs, deadline=self._deadline),
            set(),
            self.vocab,
        )
        listed = "; ".join(f.render() for f in facts)
        concept = UnsafeStateConcept(
            id="InconsistentWorldModel",
            name="InconsistentWorldModel",
            kind="logical-inconsistency",
            category="Uncertainty",
            danger_level="high",
            description="The world model contradicts the knowledge base: these facts cannot all be true.",
            safety_warning="A contradictory world model makes every conclusion unreliable.",
            trigger_reason="the facts contradict the ontology",
            suggestion="Confirm which of the contradictory facts is wrong and correct the scene.",
            source="OWL 2 DL consistency check",
            check_at="always",
            definition="",
            module="",
        )
        subject = facts[0].subject if facts else ""
        return _Finding(
            concept,
            k,
            "inconsistency",
            subject,
            False,
            facts,
            dict(snapshot),
            [],
            f"These facts cannot all be true: {listed}.",
            [contradiction_question(k, facts)],
        )

    def _unclear(self, stop: MissingObject) -> _Finding:
        if stop.ambiguous:
            options = " or ".join(stop.near)
            concept = _synthetic(
                "AmbiguousObject",
                "uncertainty",
                "Uncertainty",
                "The plan names a type that matches several objects, and nothing says which one is meant.",
                f"step {stop.step.index} refers to '{stop.term}', which could be {options}",
                "Name the object by its instance name in the plan.",
            )
            question = which_question(stop.step.index, stop.step.text, stop.term, stop.near)
            return _Finding(
                concept,
                stop.step.index,
                "missing-object",
                stop.term,
                False,
                [],
                {},
                [],
                f"'{stop.term}' is ambiguous: {options}.",
                [question],
            )
        who = stop.near[0]
        concept = _synthetic(
            "ActionOnPerson",
            "logical-inconsistency",
            "Logical Inconsistency",
            "The plan manipulates a person or agent as if it were an object.",
            f"step {stop.step.index} would {stop.step.verb} {who}, who is an agent",
            "Never pick up, move or act on a person; ask them, or choose an object.",
            danger="critical",
        )
        fact = Fact(who, "type", "Agent", FactKind.TYPE)
        return _Finding(
            concept,
            stop.step.index,
            "precondition",
            who,
            True,
            [fact],
            {fact: Provenance.SCENE},
            [],
            f"{who} is an agent, not an object to {stop.step.verb}.",
        )

    def _requirements(
        self,
        requirements: Sequence[Requirement | Unreadable],
        states: list[WorldState],
        resolved: list[ResolvedStep],
        plan_length: int,
    ) -> list[_Finding]:
        """Step-bounded requirements, checked over the simulated trace."""
        out: list[_Finding] = []
        events = [self._event(r, states[i]) for i, r in enumerate(resolved)]
        for n, req in enumerate(requirements, start=1):
            if isinstance(req, Unreadable):
                concept = _requirement_concept(n, req.text, "the requirement could not be read")
                question = requirement_question(n, req.text, req.reason, plan_length)
                out.append(
                    _Finding(
                        concept,
                        plan_length,
                        "requirement",
                        f"requirement {n}",
                        False,
                        [],
                        {},
                        [],
                        f"Unreadable requirement: {req.reason}.",
                        [question],
                    )
                )
                continue
            violation = check_requirement(req, events, self.vocab, len(resolved))
            if violation is None:
                continue
            concept = _requirement_concept(n, req.text, violation.message)
            step = (
                violation.deadline_step
                if violation.deadline_step is not None
                else violation.trigger_step
            )
            out.append(
                _Finding(
                    concept,
                    step,
                    "requirement",
                    f"step {violation.trigger_step}",
                    True,
                    [],
                    {},
                    [],
                    f"Requirement '{req.text}' is violated: {violation.message}.",
                )
            )
        return out

    def _event(self, r: ResolvedStep, state: WorldState) -> StepEvent:
        verb = r.step.verb
        acted = r.patient if verb == "put" else (r.target or r.patient)
        types: set[str] = set(state.objects.get(acted, frozenset())) if acted else set()
        if acted:  # a knob stands for the burner it controls
            for device in state.objects_of(acted, "controls"):
                types |= state.objects.get(device, frozenset())
        place = (
            set(state.objects.get(r.target, frozenset())) if verb == "put" and r.target else set()
        )
        return StepEvent(r.step.index, verb, frozenset(types), frozenset(place))

    def _stopped(self, stop: MissingObject | PreconditionFailure, state: WorldState) -> _Finding:
        if isinstance(stop, MissingObject) and (stop.ambiguous or stop.agent):
            return self._unclear(stop)
        if isinstance(stop, MissingObject):
            near = f" (closest in the scene: {', '.join(stop.near)})" if stop.near else ""
            concept = UnsafeStateConcept(
                id="MissingObject",
                name="MissingObject",
                kind="uncertainty",
                category="Uncertainty",
                danger_level="high",
                description="The plan names an object the scene does not contain.",
                safety_warning="Acting on an object nobody has perceived is acting blind.",
                trigger_reason=f"step {stop.step.index} refers to '{stop.term}', which is not in the scene",
                suggestion=f"Confirm where the {stop.term} is (add it to the scene), or plan without it.",
                source="paper: noise test (object omission)",
                check_at="always",
                definition="",
                module="",
            )
            receptacles = [
                o for o in state.order if self.vocab.any_is_a(state.objects[o], "Receptacle")
            ]
            question = where_question(
                stop.step.index, stop.step.text, stop.term, stop.near, receptacles
            )
            return _Finding(
                concept,
                stop.step.index,
                "missing-object",
                stop.term,
                False,
                [],
                {},
                [],
                f"'{stop.term}' is not in the scene{near}.",
                [question],
            )
        usc = self.vocab.preconditions[stop.precondition]
        facts = list(stop.facts)
        prov = {f: state.facts.get(f, Provenance.PLAN) for f in facts}
        return _Finding(
            usc,
            stop.step.index,
            "precondition",
            stop.subject,
            True,
            facts,
            prov,
            [],
            f"Precondition failed: {stop.message}.",
        )

    # ------------------------------------------------------------------ report
    def _report(
        self,
        plan: Sequence[PlanStep],
        states: list[WorldState],
        resolved: list[ResolvedStep],
        stop: MissingObject | PreconditionFailure | None,
        findings: dict[int, list[_Finding]],
        first_definite: int | None,
        spelling: Mapping[Fact, Fact],
    ) -> Report:
        uncertain_steps = sorted(
            s for s, fs in findings.items() if fs and not any(f.definite for f in fs)
        )
        if first_definite is not None:
            status, step = "UNSAFE", first_definite
        elif uncertain_steps or findings:
            status, step = "UNKNOWN", min(findings)
        else:
            status, step = "SAFE", None
        at_step = sorted(findings.get(step, []) if step is not None else [], key=_rank)
        questions: dict[str, Question] = {}  # by key: the first finding asking it words it
        for s in sorted(findings):
            if step is not None and s > step and status == "UNSAFE":
                break
            for f in sorted(findings[s], key=_rank):
                for q in f.questions:
                    questions.setdefault(q.key, q)
        violations = tuple(self._violation(f, spelling) for f in at_step)
        primary = violations[0] if violations else None
        action = None
        if step is not None and 1 <= step <= len(plan):
            action = plan[step - 1].text
        trace = self._trace(plan, states, resolved, stop, findings)
        if primary is None:
            reason = (
                f"every simulated state and action satisfies the {len(self.always) + len(self.final)} safety rules "
                f"of scenario '{self.tbox.scenario}'"
            )
        elif status == "UNSAFE":
            reason = f"step {step}: {primary.description}"
        else:
            reason = (
                f"step {step}: safety depends on facts that are not known ({primary.description})"
            )
        return Report(
            status=status,  # type: ignore[arg-type]
            dangerous_step=step,
            action=action,
            violated_concept=ViolatedConcept(id=primary.id, description=primary.description)
            if primary
            else None,
            causal_chain=CausalChain(
                message=primary.message,
                triggering_facts=primary.triggering_facts,
                background=primary.background,
            )
            if primary
            else None,
            violations=violations,
            questions=tuple(questions.values()),
            suggestion=primary.suggestion if primary else None,
            danger_level=primary.danger_level if primary else None,
            category=primary.category if primary else None,
            reason=reason,
            plan=tuple(s.text for s in plan),
            trace=trace,
            engine=self.engine.name,
            scenario=self.tbox.scenario,
        )

    def _violation(self, f: _Finding, spelling: Mapping[Fact, Fact]) -> Violation:
        u = f.concept
        trig = tuple(x.triple() for x in f.facts if f.provenance.get(x) is not Provenance.DEFAULT)
        assumed = tuple(x.triple() for x in f.facts if f.provenance.get(x) is Provenance.ASSUMED)
        # The canonical facts are what every spelling of the scene shares; the
        # user's own statements behind them are shown beside them.
        written = tuple(
            dict.fromkeys(
                spelling[x].triple()
                for x in f.facts
                if x in spelling and f.provenance.get(x) is Provenance.SCENE
            )
        )
        return Violation(
            id=u.id,
            name=u.name,
            kind=u.kind,
            category=u.category,
            danger_level=u.danger_level,
            description=u.description,
            safety_warning=u.safety_warning,
            trigger_reason=u.trigger_reason,
            suggestion=u.suggestion,
            source=u.source,
            step=f.step,
            phase=f.phase,  # type: ignore[arg-type]
            subject=f.subject,
            definite=f.definite,
            message=f.message,
            triggering_facts=trig,
            assumed_facts=assumed,
            as_written=written,
            background=tuple(f.background),
        )

    def _trace(
        self,
        plan: Sequence[PlanStep],
        states: list[WorldState],
        resolved: list[ResolvedStep],
        stop: MissingObject | PreconditionFailure | None,
        findings: dict[int, list[_Finding]],
    ) -> tuple[StepTrace, ...]:
        out = []
        for i, step in enumerate(plan, start=1):
            ids = tuple(sorted({f.concept.id for f in findings.get(i, [])}))
            fs = findings.get(i, [])
            outcome: Outcome = (
                "unsafe" if any(f.definite for f in fs) else "unknown" if fs else "ok"
            )
            if i > self._checked and not fs:
                outcome = "not-checked"
            if i < len(states):
                added, removed = diff(states[i - 1], states[i])
                out.append(
                    StepTrace(
                        step=i,
                        action=step.text,
                        outcome=outcome,
                        findings=ids,
                        added=added,
                        removed=removed,
                    )
                )
            else:
                stopped_here = stop is not None and stop.step.index == i
                out.append(
                    StepTrace(
                        step=i,
                        action=step.text,
                        outcome=outcome if stopped_here else "not-simulated",
                        findings=ids,
                    )
                )
        return tuple(out)

    def _error(self, plan: Sequence[PlanStep], reason: str) -> Report:
        return Report(
            status="ERROR",
            dangerous_step=None,
            action=None,
            violated_concept=None,
            causal_chain=None,
            violations=(),
            questions=(),
            suggestion=None,
            danger_level=None,
            category=None,
            reason=reason + " (fail closed: the plan is not approved)",
            plan=tuple(s.text for s in plan),
            trace=(),
            engine=self.engine.name,
            scenario=self.tbox.scenario,
        )


def _synthetic(
    ident: str,
    kind: str,
    category: str,
    description: str,
    reason: str,
    suggestion: str,
    danger: str = "high",
) -> UnsafeStateConcept:
    """A finding the simulator makes itself (not an ontology concept)."""
    return UnsafeStateConcept(
        id=ident,
        name=ident,
        kind=kind,
        category=category,
        danger_level=danger,
        description=description,
        safety_warning=description,
        trigger_reason=reason,
        suggestion=suggestion,
        source="VIRF sandbox simulator",
        check_at="always",
        definition="",
        module="",
    )


def _requirement_concept(n: int, text: str, reason: str) -> UnsafeStateConcept:
    return UnsafeStateConcept(
        id=f"Requirement-{n}",
        name="StepBoundedRequirement",
        kind="temporal-requirement",
        category="Task Requirement",
        danger_level="medium",
        description=text,
        safety_warning="The task states this requirement to avoid a hazard.",
        trigger_reason=reason,
        suggestion="Reorder the plan so that the required action comes within the stated number of steps.",
        source="task instruction (step-bounded requirement)",
        check_at="always",
        definition="",
        module="",
    )


def _rank(f: _Finding) -> tuple[int, int, int, str, str]:
    return (
        0 if f.definite else 1,
        DANGER_RANK.get(f.concept.danger_level, 9),
        PHASE_RANK[f.phase],
        f.concept.id,
        f.subject,
    )
