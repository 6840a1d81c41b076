"""``virf bench perception``: how well perception recovers a scene, and
whether the tutor's verdict survives it.

A case is a folder::

    case.json           {"description": ..., "threshold": 0.5}   (optional)
    view1.png ...       the camera images (view*.png/jpg/jpeg/webp, sorted)
    gold.json           the true scene, in the scene format
    plan.txt            a plan to verify on both scenes (optional)
    replay.jsonl        recorded replies of the cascade
    detections.json     a detector's boxes (COCO), for the hybrid baseline
    replay-hybrid.jsonl recorded replies of the hybrid's stages 2 and 3

Figures per case and in total (micro-averaged):

* objects, attributes (states and materials) and relations: precision,
  recall and F1 against the gold scene, after the perceived objects are
  aligned with the gold ones (same type: same name first, then left-to-right
  order);
* safety facts: the share of the gold facts the tutor's findings rest on
  (the minimal triggering facts of each finding on the gold scene) that the
  perceived scene holds;
* the verdict on the plan with the perceived scene against the one with the
  gold scene, and the cases where perception turned a hazard into SAFE.

Facts are compared in the canonical world the scene reader builds, so two
spellings of one fact are one fact, and catalogue defaults count on both
sides.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from virf.bench.metrics import percent
from virf.errors import InputError, read_json_file
from virf.ontology.tbox import Vocabulary
from virf.perception import Catalogue, perceive
from virf.planner import Apprentice, ReplayApprentice
from virf.render.tables import TextTable, to_markdown
from virf.schema import Fact, FactKind, Provenance
from virf.verify.verifier import Verifier
from virf.world.plan import load_plan_file
from virf.world.scene import Scene, build_scene

IMAGE_SUFFIXES: Final = (".png", ".jpg", ".jpeg", ".webp")
ATTRIBUTES: Final = frozenset({"hasState", "hasMaterial"})
RELATIONS: Final = frozenset({"contains", "supports", "isHolding", "isNear"})
MARKERS: Final = frozenset({"UnknownMaterial", "UnknownFillState"})


@dataclass(frozen=True)
class PerceptionCase:
    """A case folder (see the module docstring); not a :class:`virf.bench.case.Case`,
    which is a plan already in its scene."""

    name: str
    folder: Path
    description: str
    images: tuple[Path, ...]
    gold: Path
    plan: Path | None
    replay: Path | None
    detections: Path | None
    hybrid_replay: Path | None
    threshold: float


@dataclass(frozen=True)
class Counts:
    """True positives, false positives and false negatives of one kind of fact."""

    tp: int = 0
    fp: int = 0
    fn: int = 0

    def __add__(self, other: Counts) -> Counts:
        return Counts(self.tp + other.tp, self.fp + other.fp, self.fn + other.fn)

    @property
    def precision(self) -> float | None:
        return self.tp / (self.tp + self.fp) if self.tp + self.fp else None

    @property
    def recall(self) -> float | None:
        return self.tp / (self.tp + self.fn) if self.tp + self.fn else None

    @property
    def f1(self) -> float | None:
        p, r = self.precision, self.recall
        return 2 * p * r / (p + r) if p is not None and r is not None and p + r else None

    def public(self) -> dict[str, int | float | None]:
        return {
            "tp": self.tp,
            "fp": self.fp,
            "fn": self.fn,
            "precision": self.precision,
            "recall": self.recall,
            "f1": self.f1,
        }


@dataclass(frozen=True)
class CaseScore:
    case: str
    mode: str  # cascade or hybrid
    objects: Counts
    attributes: Counts
    relations: Counts
    disagreements: int
    safety_facts: int = 0
    safety_recovered: int = 0
    gold_verdict: str | None = None
    perceived_verdict: str | None = None
    missing: tuple[str, ...] = ()  # gold facts the tutor needed that perception lacked

    @property
    def hazard_lost(self) -> bool:
        return self.gold_verdict not in (None, "SAFE") and self.perceived_verdict == "SAFE"

    def public(self) -> dict[str, object]:
        return {
            "case": self.case,
            "mode": self.mode,
            "objects": self.objects.public(),
            "attributes": self.attributes.public(),
            "relations": self.relations.public(),
            "safety_facts": self.safety_facts,
            "safety_recovered": self.safety_recovered,
            "gold_verdict": self.gold_verdict,
            "perceived_verdict": self.perceived_verdict,
            "same_verdict": self.gold_verdict == self.perceived_verdict,
            "hazard_lost": self.hazard_lost,
            "disagreements": self.disagreements,
            "missing_safety_facts": list(self.missing),
        }


@dataclass(frozen=True)
class Totals:
    """One mode's cases summed (micro-averaged)."""

    mode: str
    cases: int
    objects: Counts
    attributes: Counts
    relations: Counts
    safety_facts: int
    safety_recovered: int
    verdicts_compared: int
    same_verdict: int
    hazards_lost: int

    @classmethod
    def of(cls, mode: str, scores: Iterable[CaseScore]) -> Totals:
        picked = [s for s in scores if s.mode == mode]
        with_plan = [s for s in picked if s.gold_verdict is not None]
        return cls(
            mode=mode,
            cases=len(picked),
            objects=sum((s.objects for s in picked), Counts()),
            attributes=sum((s.attributes for s in picked), Counts()),
            relations=sum((s.relations for s in picked), Counts()),
            safety_facts=sum(s.safety_facts for s in picked),
            safety_recovered=sum(s.safety_recovered for s in picked),
            verdicts_compared=len(with_plan),
            same_verdict=sum(s.gold_verdict == s.perceived_verdict for s in with_plan),
            hazards_lost=sum(s.hazard_lost for s in with_plan),
        )

    def public(self) -> dict[str, object]:
        return {
            "mode": self.mode,
            "cases": self.cases,
            "objects": self.objects.public(),
            "attributes": self.attributes.public(),
            "relations": self.relations.public(),
            "safety_facts": self.safety_facts,
            "safety_recovered": self.safety_recovered,
            "verdicts_compared": self.verdicts_compared,
            "same_verdict": self.same_verdict,
            "hazards_lost": self.hazards_lost,
        }


def load_cases(folder: str | Path) -> list[PerceptionCase]:
    root = Path(folder)
    if not root.is_dir():
        raise InputError(f"cases folder not found: {root}")
    cases = []
    for sub in sorted(p for p in root.iterdir() if p.is_dir()):
        gold = sub / "gold.json"
        if not gold.is_file():
            continue
        meta: object = (
            read_json_file(sub / "case.json", "case") if (sub / "case.json").is_file() else {}
        )
        if not isinstance(meta, dict):
            raise InputError(f"{sub / 'case.json'} must be a JSON object")
        images = tuple(
            sorted(
                p
                for p in sub.iterdir()
                if p.name.startswith("view") and p.suffix.lower() in IMAGE_SUFFIXES
            )
        )
        if not images:
            raise InputError(f"case {sub.name} has no images (view1.png ...)")
        threshold = meta.get("threshold", 0.5)
        if isinstance(threshold, bool) or not isinstance(threshold, int | float):
            raise InputError(f"{sub / 'case.json'}: threshold must be a number")

        def optional(name: str, sub: Path = sub) -> Path | None:
            path = sub / name
            return path if path.is_file() else None

        cases.append(
            PerceptionCase(
                name=sub.name,
                folder=sub,
                description=str(meta.get("description", "")),
                images=images,
                gold=gold,
                plan=optional("plan.txt"),
                replay=optional("replay.jsonl"),
                detections=optional("detections.json"),
                hybrid_replay=optional("replay-hybrid.jsonl"),
                threshold=float(threshold),
            )
        )
    if not cases:
        raise InputError(f"no cases in {root}: a case is a folder with gold.json and images")
    return cases


def _compatible(a: frozenset[str], b: frozenset[str], vocab: Vocabulary) -> bool:
    # An object no type fitted is a PhysicalObject, an ancestor of every
    # type; it may stand only for a gold object typed no better.
    if (a == {"PhysicalObject"}) != (b == {"PhysicalObject"}):
        return False
    return any(vocab.is_a(x, y) or vocab.is_a(y, x) for x in a for y in b)


def align(perceived: Scene, gold: Scene, vocab: Vocabulary) -> dict[str, str]:
    """Perceived instance -> gold instance, one to one, types compatible:
    the same name first, then in scene order (perception names objects left
    to right)."""
    robots = {perceived.agent, gold.agent}
    p_objs = [o for o in perceived.order if o not in robots]
    g_objs = [o for o in gold.order if o not in robots]
    pairs: dict[str, str] = {}
    for o in p_objs:
        if o in g_objs and _compatible(perceived.objects[o], gold.objects[o], vocab):
            pairs[o] = o
    taken = set(pairs.values())
    for o in p_objs:
        if o in pairs:
            continue
        for g in g_objs:
            if g not in taken and _compatible(perceived.objects[o], gold.objects[g], vocab):
                pairs[o] = g
                taken.add(g)
                break
    pairs[perceived.agent] = gold.agent
    return pairs


def _facts(scene: Scene, predicates: frozenset[str], rename: Mapping[str, str]) -> set[Fact]:
    out = set()
    for f, prov in scene.facts.items():
        if f.kind is not FactKind.OBJECT or f.predicate not in predicates:
            continue
        if prov is Provenance.PLAN or f.object in MARKERS:
            continue
        subject = rename.get(f.subject, f"?{f.subject}")
        obj = rename.get(f.object, f.object if f.object not in scene.objects else f"?{f.object}")
        if f.predicate == "isNear":
            subject, obj = sorted((subject, obj))
        out.add(Fact(subject, f.predicate, obj))
    return out


def _count(found: set[Fact], gold: set[Fact]) -> Counts:
    return Counts(len(found & gold), len(found - gold), len(gold - found))


def score_case(
    case: PerceptionCase,
    mode: str,
    vlm: Apprentice,
    vocab: Vocabulary,
    verifier: Verifier,
    catalogue: Catalogue,
) -> CaseScore:
    gold = build_scene(read_json_file(case.gold, "gold scene"), vocab, name=case.name)
    result = perceive(
        case.images,
        vlm,
        vocab,
        detections=case.detections if mode == "hybrid" else None,
        threshold=case.threshold,
        catalogue=catalogue,
    )
    perceived = build_scene(result.scene, vocab, name=case.name)
    rename = align(perceived, gold, vocab)
    identity = {g: g for g in gold.objects}
    matched = len([p for p in rename if p != perceived.agent])
    score = CaseScore(
        case.name,
        mode,
        objects=Counts(
            matched, len(perceived.objects) - 1 - matched, len(gold.objects) - 1 - matched
        ),
        attributes=_count(
            _facts(perceived, ATTRIBUTES, rename), _facts(gold, ATTRIBUTES, identity)
        ),
        relations=_count(_facts(perceived, RELATIONS, rename), _facts(gold, RELATIONS, identity)),
        disagreements=len(result.graph.disagreements),
    )
    if case.plan is None:
        return score
    plan = load_plan_file(case.plan)
    gold_report = verifier.verify(gold, plan)
    perceived_verdict = verifier.verify(perceived, plan).status
    used = {Fact.from_triple(t) for v in gold_report.violations for t in v.triggering_facts}
    # The scene's own facts, not the ones the plan's simulation produced.
    needed = {f for f in used if gold.facts.get(f, Provenance.PLAN) is not Provenance.PLAN}
    inverse = {g: p for p, g in rename.items()}
    have = set(perceived.facts)
    missing = []
    for f in sorted(needed):
        subject = inverse.get(f.subject)
        obj = inverse.get(f.object, f.object if f.object not in gold.objects else None)
        if f.kind is FactKind.TYPE:
            ok = subject is not None and _compatible(
                perceived.objects.get(subject, frozenset()), frozenset({f.object}), vocab
            )
        else:
            ok = (
                subject is not None
                and obj is not None
                and Fact(subject, f.predicate, obj, f.kind, f.members) in have
            )
        if not ok:
            missing.append(f.render())
    return dataclasses.replace(
        score,
        safety_facts=len(needed),
        safety_recovered=len(needed) - len(missing),
        gold_verdict=gold_report.status,
        perceived_verdict=perceived_verdict,
        missing=tuple(missing),
    )


@dataclass(frozen=True)
class PerceptionRun:
    scores: tuple[CaseScore, ...]

    @property
    def totals(self) -> tuple[Totals, ...]:
        """One row per mode, in name order."""
        return tuple(Totals.of(m, self.scores) for m in sorted({s.mode for s in self.scores}))

    def public(self) -> dict[str, object]:
        return {
            "cases": [s.public() for s in self.scores],
            "totals": [t.public() for t in self.totals],
        }


def run_cases(
    cases: Iterable[PerceptionCase],
    vocab: Vocabulary,
    verifier: Verifier,
    *,
    vlm: Callable[[PerceptionCase, str], Apprentice] | None = None,
    modes: tuple[str, ...] = ("cascade", "hybrid"),
    progress: Callable[[str], None] | None = None,
) -> PerceptionRun:
    """Score every case in each mode it has replies for (or, with ``vlm``, a
    live model for every case and mode)."""
    catalogue = Catalogue(vocab)
    scores = []
    for case in cases:
        for mode in modes:
            if mode == "hybrid" and case.detections is None:
                continue
            if vlm is not None:
                model = vlm(case, mode)
            else:
                replay = case.replay if mode == "cascade" else case.hybrid_replay
                if replay is None:
                    continue
                model = ReplayApprentice(replay)
            if progress is not None:
                progress(f"{case.name} ({mode})")
            with model:
                scores.append(score_case(case, mode, model, vocab, verifier, catalogue))
    if not scores:
        raise InputError("no case has recorded replies (replay.jsonl); pass --vlm to use a model")
    return PerceptionRun(tuple(scores))


# ---------------------------------------------------------------------- tables
def _share(value: float | None) -> str:
    return percent(value, missing="-")


def _precision_recall(counts: Counts) -> str:
    return f"{_share(counts.precision)} / {_share(counts.recall)}"


def case_table(run: PerceptionRun, *, terminal: bool) -> TextTable:
    """Every case in every mode; the terminal words the headers shorter."""
    if terminal:
        pr, gold, perceived = "P/R", "gold", "perceived"
    else:
        pr, gold, perceived = "P / R", "gold verdict", "perceived verdict"
    return TextTable.of(
        (
            "case",
            "mode",
            f"objects {pr}",
            f"attributes {pr}",
            f"relations {pr}",
            "safety facts",
            gold,
            perceived,
        ),
        [
            (
                s.case,
                s.mode,
                _precision_recall(s.objects),
                _precision_recall(s.attributes),
                _precision_recall(s.relations),
                f"{s.safety_recovered}/{s.safety_facts}",
                s.gold_verdict or "-",
                (s.perceived_verdict or "-") + (" (hazard lost)" if s.hazard_lost else ""),
            )
            for s in run.scores
        ],
        title="Perception, case by case" if terminal else None,
    )


def totals_table(run: PerceptionRun, *, terminal: bool) -> TextTable:
    return TextTable.of(
        (
            "mode",
            "objects F1",
            "attributes F1",
            "relations F1",
            "safety facts recovered" if terminal else "safety facts",
            "same verdict",
            "hazards lost",
        ),
        [
            (
                t.mode,
                _share(t.objects.f1),
                _share(t.attributes.f1),
                _share(t.relations.f1),
                f"{t.safety_recovered}/{t.safety_facts}",
                f"{t.same_verdict}/{t.verdicts_compared}",
                str(t.hazards_lost),
            )
            for t in run.totals
        ],
        title="Totals" if terminal else None,
    )


def missing_lines(run: PerceptionRun) -> list[str]:
    """The gold facts each case's verdict needed that perception did not recover."""
    return [
        f"{s.case} ({s.mode}): the tutor needed {', '.join(s.missing)}"
        for s in run.scores
        if s.missing
    ]


def markdown(run: PerceptionRun) -> str:
    lines = [
        *to_markdown(case_table(run, terminal=False)),
        "",
        *to_markdown(totals_table(run, terminal=False)),
    ]
    return "\n".join(lines) + "\n"


def to_json(run: PerceptionRun) -> str:
    return json.dumps(run.public(), indent=2)
