"""``virf kb test``: rules tested like code.

Two kinds of test, both run by the verifier itself (the one simulation loop,
the engine the user chose):

* **Minimal pairs.**  Every Unsafe State Concept carries at least one
  ``:twin`` (see :mod:`virf.verify.twins`): a world where the rule must hold
  and a twin, differing in one statement, where it must not.  A pair fails
  when the rule stays quiet in its world, fires in its twin, or either plan
  cannot run to its end (a twin that passes only because its plan stopped
  would be a test that cannot fail).
* **Sweeps** over the catalogue (:mod:`virf.verify.sweeps`): the same plan
  with every type in turn, whose verdicts must follow each type's
  properties, not its name.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

from virf.errors import InputError
from virf.ontology.tbox import TBox
from virf.reasoning import Engine
from virf.verify.sweeps import SweepFailure, run_sweeps
from virf.verify.twins import MinimalPair, read_pair, scene_data
from virf.verify.verifier import Verifier
from virf.world.plan import parse_plan
from virf.world.scene import build_scene


@dataclass(frozen=True)
class PairResult:
    rule: str
    index: int  # 1-based among the rule's pairs; 0 when the rule has none
    ok: bool
    problem: str = ""
    change: str = ""


@dataclass(frozen=True)
class KbTestResult:
    scenario: str
    rules: int
    pairs: tuple[PairResult, ...]
    sweeps: tuple[SweepFailure, ...] = field(default_factory=tuple)
    sweep_cases: int = 0

    @property
    def failures(self) -> list[PairResult]:
        return [p for p in self.pairs if not p.ok]

    @property
    def passed(self) -> bool:
        return not self.failures and not self.sweeps


def _fires(
    verifier: Verifier, rule: str, statements: tuple[str, ...], plan: Sequence[str]
) -> tuple[bool, bool, str]:
    """Whether ``rule`` holds anywhere in the run (and definitely somewhere),
    or why the run could not be made."""
    vocab = verifier.vocab
    scene = build_scene(scene_data(statements), vocab, name="twin")
    steps = parse_plan(list(plan))
    walk = verifier.findings(scene, steps)
    if walk.trace.stop is not None:
        return False, False, f"the plan stops: {walk.trace.stop_reason()}"
    found = [f for fs in walk.findings.values() for f in fs if f.concept.name == rule]
    return bool(found), any(f.definite for f in found), ""


def check_pair(verifier: Verifier, pair: MinimalPair, index: int, kind: str) -> PairResult:
    def fail(problem: str) -> PairResult:
        return PairResult(pair.rule, index, False, problem, pair.change)

    try:
        holds, definite, stop = _fires(verifier, pair.rule, pair.world, pair.plan)
    except InputError as exc:
        return fail(f"its world cannot be read: {exc}")
    if stop:
        return fail(f"in its world {stop}")
    if not holds:
        return fail("the rule does not hold in its world")
    if kind != "uncertainty" and not definite:
        return fail("the rule holds in its world only on an assumption (UNKNOWN, not UNSAFE)")
    try:
        holds, _, stop = _fires(verifier, pair.rule, pair.twin, pair.twin_plan)
    except InputError as exc:
        return fail(f"its twin cannot be read: {exc}")
    if stop:
        return fail(f"in its twin {stop}")
    if holds:
        return fail("the rule still holds in its twin")
    return PairResult(pair.rule, index, True, "", pair.change)


def run_pairs(
    tbox: TBox,
    engine: Engine,
    rules: Iterable[str] | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> list[PairResult]:
    """Check the minimal pairs of ``rules`` (by default every USC)."""
    vocab = tbox.vocabulary
    names = sorted(vocab.uscs if rules is None else rules)
    out: list[PairResult] = []
    for n, name in enumerate(names, start=1):
        usc = vocab.uscs[name]
        texts = vocab.annotation(name, "twin")
        if not texts:
            out.append(PairResult(name, 0, False, "has no minimal pair (a ':twin' annotation)"))
        verifier = Verifier(tbox, engine, explain=False, uscs=[name])
        for i, text in enumerate(texts, start=1):
            try:
                pair = read_pair(name, text)
            except InputError as exc:
                out.append(PairResult(name, i, False, str(exc)))
                continue
            out.append(check_pair(verifier, pair, i, usc.kind))
        if progress is not None:
            progress(n, len(names))
    return out


def run_kb_test(
    tbox: TBox,
    engine: Engine,
    *,
    sweeps: bool = True,
    progress: Callable[[str, int, int], None] | None = None,
) -> KbTestResult:
    """Every rule's minimal pairs, then (unless ``sweeps`` is false) the sweeps."""

    def step(what: str) -> Callable[[int, int], None] | None:
        if progress is None:
            return None
        return lambda done, total: progress(what, done, total)

    pairs = run_pairs(tbox, engine, progress=step("minimal pairs"))
    cases, failures = run_sweeps(tbox, engine, progress=step("sweeps")) if sweeps else (0, [])
    return KbTestResult(
        scenario=tbox.scenario,
        rules=len(tbox.vocabulary.uscs),
        pairs=tuple(pairs),
        sweeps=tuple(failures),
        sweep_cases=cases,
    )
