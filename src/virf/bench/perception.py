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

import json
from collections.abc import Callable, Iterable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Final

from virf.errors import InputError, read_json_file
from virf.ontology.tbox import Vocabulary
from virf.perception import Catalogue, perceive
from virf.planner import Apprentice, ReplayApprentice
from virf.schema import Fact, FactKind, Provenance
from virf.verify.verifier import Verifier
from virf.world.plan import load_plan_file
from virf.world.scene import Scene, build_scene

IMAGE_SUFFIXES: Final = (".png", ".jpg", ".jpeg", ".webp")
ATTRIBUTES: Final = frozenset({"hasState", "hasMaterial"})
RELATIONS: Final = frozenset({"contains", "supports", "isHolding", "isNear"})
MARKERS: Final = frozenset({"UnknownMaterial", "UnknownFillState"})


@dataclass(frozen=True)
class Case:
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


@dataclass
class Counts:
    tp: int = 0
    fp: int = 0
    fn: int = 0

    def add(self, other: Counts) -> None:
        self.tp, self.fp, self.fn = self.tp + other.tp, self.fp + other.fp, self.fn + other.fn

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

    def as_dict(self) -> dict[str, Any]:
        return {
            **asdict(self),
            "precision": self.precision,
            "recall": self.recall,
            "f1": self.f1,
        }


@dataclass
class CaseScore:
    case: str
    mode: str  # cascade or hybrid
    objects: Counts = field(default_factory=Counts)
    attributes: Counts = field(default_factory=Counts)
    relations: Counts = field(default_factory=Counts)
    safety_facts: int = 0
    safety_recovered: int = 0
    gold_verdict: str | None = None
    perceived_verdict: str | None = None
    disagreements: int = 0
    missing: tuple[str, ...] = ()  # gold facts the tutor needed that perception lacked

    @property
    def hazard_lost(self) -> bool:
        return self.gold_verdict not in (None, "SAFE") and self.perceived_verdict == "SAFE"

    def as_dict(self) -> dict[str, Any]:
        return {
            "case": self.case,
            "mode": self.mode,
            "objects": self.objects.as_dict(),
            "attributes": self.attributes.as_dict(),
            "relations": self.relations.as_dict(),
            "safety_facts": self.safety_facts,
            "safety_recovered": self.safety_recovered,
            "gold_verdict": self.gold_verdict,
            "perceived_verdict": self.perceived_verdict,
            "same_verdict": self.gold_verdict == self.perceived_verdict,
            "hazard_lost": self.hazard_lost,
            "disagreements": self.disagreements,
            "missing_safety_facts": list(self.missing),
        }


def load_cases(folder: str | Path) -> list[Case]:
    root = Path(folder)
    if not root.is_dir():
        raise InputError(f"cases folder not found: {root}")
    cases = []
    for sub in sorted(p for p in root.iterdir() if p.is_dir()):
        gold = sub / "gold.json"
        if not gold.is_file():
            continue
        meta: Any = (
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
            Case(
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
    case: Case,
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
    score = CaseScore(case.name, mode, disagreements=len(result.graph.disagreements))
    matched = len([p for p in rename if p != perceived.agent])
    score.objects = Counts(
        matched, len(perceived.objects) - 1 - matched, len(gold.objects) - 1 - matched
    )
    score.attributes = _count(
        _facts(perceived, ATTRIBUTES, rename), _facts(gold, ATTRIBUTES, identity)
    )
    score.relations = _count(
        _facts(perceived, RELATIONS, rename), _facts(gold, RELATIONS, identity)
    )
    if case.plan is None:
        return score
    plan = load_plan_file(case.plan)
    gold_report = verifier.verify(gold, plan)
    score.gold_verdict = gold_report.status
    score.perceived_verdict = verifier.verify(perceived, plan).status
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
    score.safety_facts = len(needed)
    score.safety_recovered = len(needed) - len(missing)
    score.missing = tuple(missing)
    return score


@dataclass(frozen=True)
class PerceptionRun:
    scores: tuple[CaseScore, ...]

    def totals(self, mode: str) -> dict[str, Any]:
        picked = [s for s in self.scores if s.mode == mode]
        out: dict[str, Any] = {"mode": mode, "cases": len(picked)}
        for part in ("objects", "attributes", "relations"):
            total = Counts()
            for s in picked:
                total.add(getattr(s, part))
            out[part] = total.as_dict()
        needed = sum(s.safety_facts for s in picked)
        out["safety_facts"] = needed
        out["safety_recovered"] = sum(s.safety_recovered for s in picked)
        with_plan = [s for s in picked if s.gold_verdict is not None]
        out["verdicts_compared"] = len(with_plan)
        out["same_verdict"] = sum(s.gold_verdict == s.perceived_verdict for s in with_plan)
        out["hazards_lost"] = sum(s.hazard_lost for s in with_plan)
        return out

    def as_json(self) -> dict[str, Any]:
        modes = sorted({s.mode for s in self.scores})
        return {
            "cases": [s.as_dict() for s in self.scores],
            "totals": [self.totals(m) for m in modes],
        }


def run_cases(
    cases: Iterable[Case],
    vocab: Vocabulary,
    verifier: Verifier,
    *,
    vlm: Callable[[Case, str], Apprentice] | None = None,
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


def percent(value: float | None) -> str:
    return "-" if value is None else f"{100 * value:.1f}%"


def markdown(run: PerceptionRun) -> str:
    lines = [
        "| case | mode | objects P / R | attributes P / R | relations P / R | safety facts "
        "| gold verdict | perceived verdict |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for s in run.scores:
        lines.append(
            f"| {s.case} | {s.mode} | {percent(s.objects.precision)} / {percent(s.objects.recall)} "
            f"| {percent(s.attributes.precision)} / {percent(s.attributes.recall)} "
            f"| {percent(s.relations.precision)} / {percent(s.relations.recall)} "
            f"| {s.safety_recovered}/{s.safety_facts} | {s.gold_verdict or '-'} "
            f"| {s.perceived_verdict or '-'}{' (hazard lost)' if s.hazard_lost else ''} |"
        )
    lines += [
        "",
        "| mode | objects F1 | attributes F1 | relations F1 | safety facts | same verdict | hazards lost |",
        "|---|---|---|---|---|---|---|",
    ]
    for t in run.as_json()["totals"]:
        lines.append(
            f"| {t['mode']} | {percent(t['objects']['f1'])} | {percent(t['attributes']['f1'])} "
            f"| {percent(t['relations']['f1'])} | {t['safety_recovered']}/{t['safety_facts']} "
            f"| {t['same_verdict']}/{t['verdicts_compared']} | {t['hazards_lost']} |"
        )
    return "\n".join(lines) + "\n"


def to_json(run: PerceptionRun) -> str:
    return json.dumps(run.as_json(), indent=2)
