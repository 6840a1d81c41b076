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

This module is the protocol only: findings are built in
:mod:`virf.verify.findings` and explained in :mod:`virf.verify.explain`, and
:mod:`virf.verify.report` assembles the report.
"""

from __future__ import annotations

import time
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from virf.ontology.tbox import TBox
from virf.reasoning import Classification, DeadlineExceeded, Engine, ReasonerFailure
from virf.schema import Fact, Phase, Provenance, Report
from virf.verify.explain import Explainer, note_onset
from virf.verify.findings import Finding, requirement_findings, stopped
from virf.verify.report import build_report, error_report
from virf.verify.requirements import Requirement, Unreadable
from virf.world.plan import PlanStep
from virf.world.scene import Scene
from virf.world.simulate import Trace, simulate
from virf.world.simulator import Simulator
from virf.world.state import WorldState, facts_copy

if TYPE_CHECKING:
    from concurrent.futures import Future
    from queue import Queue


class VerificationTimeout(Exception):
    pass


@dataclass(frozen=True)
class Walk:
    """What the protocol's loop found: the trace, the findings by step, the
    first step with a definite finding, and the last snapshot classified."""

    trace: Trace
    findings: dict[int, list[Finding]]
    first_definite: int | None
    checked: int


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
        assumed facts.  Findings that still need their facts (a hazard left
        at the end of the plan, for its onset; an uncertain one, for its
        questions) get them, but not the background axioms.

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

    def snapshots(self, scene: Scene, plan: Sequence[PlanStep]) -> list[dict[Fact, Provenance]]:
        """The ABox the reasoner sees for each step (for baselines and tools)."""
        trace = simulate(self.sim, self.sim.initial(scene), plan)
        return self._snapshots(trace)[0]

    def findings(self, scene: Scene, plan: Sequence[PlanStep]) -> Walk:
        """Every finding of the plan, at every step, not only up to the first
        definite one (rule coverage and other tools).  Findings carry no
        explanation unless they are uncertain or left at the end; raises
        when the engine cannot answer, instead of making an ERROR report."""
        self._step = -1
        deadline = time.monotonic() + self.timeout_s
        self._deadline = deadline
        try:
            return self._walk(scene, plan, (), deadline, explain=False, until_definite=False)
        finally:
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
        walk = self._walk(
            scene, plan, requirements, deadline, explain=self.explain, until_definite=True
        )
        return build_report(
            plan,
            walk.trace,
            walk.findings,
            walk.first_definite,
            scene.spelling,
            checked=walk.checked,
            rules=len(self.always) + len(self.final),
            scenario=self.tbox.scenario,
            engine=self.engine.name,
            notes=(*(s.note for s in plan if s.note), *scene.notes),
        )

    def _walk(
        self,
        scene: Scene,
        plan: Sequence[PlanStep],
        requirements: Sequence[Requirement | Unreadable],
        deadline: float,
        *,
        explain: bool,
        until_definite: bool,
    ) -> Walk:
        """The protocol's one loop: simulate the plan, classify each step's
        snapshot, place each finding at its step (an action's at the action),
        and stop at the first definite finding when ``until_definite``."""
        explainer = Explainer(self.engine, self.vocab, deadline, self._tick, background=explain)
        trace = simulate(self.sim, self.sim.initial(scene), plan)
        snapshots, closed = self._snapshots(trace)
        # What no step changes is reasoned about once, not at every step:
        # closures and all.  Sets built from the snapshots' dicts reuse their
        # hashes, so this costs no Python call per fact; a dict given to the
        # intersection as it is would be hashed fact by fact.
        first, *rest = snapshots
        unchanged = frozenset(set(first).intersection(*map(set, rest)))
        with self.engine.sharing(unchanged, deadline=deadline):
            return self._classify_steps(
                trace,
                snapshots,
                closed,
                unchanged,
                len(plan),
                requirements,
                deadline,
                explainer,
                explain=explain,
                until_definite=until_definite,
            )

    def _classify_steps(
        self,
        trace: Trace,
        snapshots: list[dict[Fact, Provenance]],
        closed: list[dict[Fact, Provenance]],
        unchanged: frozenset[Fact],
        plan_length: int,
        requirements: Sequence[Requirement | Unreadable],
        deadline: float,
        explainer: Explainer,
        *,
        explain: bool,
        until_definite: bool,
    ) -> Walk:
        states, resolved, stop = trace.states, trace.resolved, trace.stop
        n = len(states) - 1
        findings: dict[int, list[Finding]] = {}
        for f in requirement_findings(requirements, states, resolved, plan_length, self.vocab):
            findings.setdefault(f.step, []).append(f)
        checked = -1  # last snapshot the reasoner answered for
        seen: set[tuple[str, str]] = set()
        first_definite: int | None = None
        concept_lists = [
            self.always + (self.final if trace.complete and k == n else [])
            for k in range(len(states))
        ]
        # In order, one at a time, unless they are classified in parallel: a
        # definite finding usually ends the loop long before the last step.
        parallel = self.workers > 1 and len(states) > 1
        ahead = self._classify_ahead(snapshots, concept_lists, deadline) if parallel else []
        self._pending = ahead
        for k in range(len(states)):
            self._step = k
            if time.monotonic() > deadline:
                raise VerificationTimeout(f"more than {self.timeout_s:g}s at step {k}")
            snapshot = snapshots[k]
            action_ind = None
            if k < len(resolved):
                action_ind = Simulator.action_individual(resolved[k].step)
            result = (
                ahead[k].result()
                if ahead
                # Only what this step adds to the shared facts is new to the engine.
                else self.engine.classify_shared(
                    unchanged, set(snapshot) - unchanged, concept_lists[k], deadline=deadline
                )
            )
            checked = k
            if not result.consistent:
                findings.setdefault(k, []).append(explainer.inconsistency(snapshot, k))
                break
            for concept, individuals in sorted(result.instances.items()):
                usc = self.vocab.uscs[concept]
                for ind in individuals:
                    phase: Phase
                    if ind == action_ind:
                        at, phase = k + 1, "action"
                    elif usc.final_only:
                        at, phase = k, "final"
                    else:
                        at, phase = k, "initial" if k == 0 else "state"
                    key = (concept, ind)
                    if key in seen and phase != "final":
                        continue
                    seen.add(key)
                    # Final findings need their facts for the onset, even in batch runs.
                    full = explain or phase == "final"
                    f = explainer.finding(usc, ind, at, phase, snapshot, full=full)
                    if phase == "final":
                        # A hazard left behind belongs to the end of the plan.
                        note_onset(f, states, closed)
                    findings.setdefault(f.step, []).append(f)
            if stop is not None and k == n:
                findings.setdefault(stop.step.index, []).append(
                    stopped(stop, states[-1], self.vocab)
                )
            # Step k is complete once snapshot k is in (its action findings came from k-1).
            done = [s for s in findings if s <= k or (stop is not None and k == n)]
            definite = [s for s in done if any(f.definite for f in findings[s])]
            if definite and first_definite is None:
                first_definite = min(definite)
            if first_definite is not None and until_definite:
                break
        return Walk(trace, findings, first_definite, checked)

    def _snapshots(
        self, trace: Trace
    ) -> tuple[list[dict[Fact, Provenance]], list[dict[Fact, Provenance]]]:
        """Each state, its closure facts, and the next action (the one-step
        lookahead); and each state's closure facts alone.  A state's
        closures are those of the state before it, read again only where
        the step changed something."""
        out: list[dict[Fact, Provenance]] = []
        closed: list[dict[Fact, Provenance]] = []
        since: tuple[WorldState, dict[Fact, Provenance]] | None = None
        for k, state in enumerate(trace.states):
            snapshot = facts_copy(state.facts)
            closures = self.sim.closure_facts(state, since)
            since = (state, closures)
            closed.append(closures)
            snapshot.update(closures)
            if k < len(trace.resolved):
                snapshot.update(self.sim.action_facts(state, trace.resolved[k]))
            out.append(snapshot)
        return out, closed

    def _classify_ahead(
        self, snapshots: list[dict[Fact, Provenance]], concepts: list[list[str]], deadline: float
    ) -> list[Future[Classification]]:
        """Start classifying every snapshot, each on a free engine of the pool."""
        if self._engines is None:
            # Imported here: one worker, the default, starts no threads.
            from concurrent.futures import ThreadPoolExecutor
            from queue import Queue

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

    def _tick(self) -> None:
        """Enforce the verification deadline between reasoner calls (the calls
        themselves stop at it too)."""
        if time.monotonic() > self._deadline:
            raise VerificationTimeout(f"more than {self.timeout_s:g}s while explaining a finding")

    def _error(self, plan: Sequence[PlanStep], reason: str) -> Report:
        return error_report(plan, reason, engine=self.engine.name, scenario=self.tbox.scenario)
