"""The layered safety ontology (TBox) as immutable Python data.

The Manchester-syntax modules in ``virf/ontology/modules`` are compiled ahead
of time (:mod:`virf.ontology.compile`) into one artifact per scenario:
vocabulary, inferred class hierarchy, annotations, USC metadata and the TBox
as fast-engine terms.  :func:`load_tbox` reads that artifact without Java.
The OWLAPI ontology itself (:attr:`TBox.owl`) is loaded only when something
asks for it: a reference engine, the fast engine's fallback, ``virf kb
check``.  When a module was edited after the artifact was written, or extra
modules are imported, the modules are compiled in-process instead, which
needs Java; an answer is never built from an out-of-date artifact.  A
workspace's compiled modules are cached in its folder under a seal of this
user's key (:mod:`virf.ontology.seal`): a cache without a valid seal is
compiled again, never trusted.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, field
from functools import cache, cached_property
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

from virf.errors import InputError, closest
from virf.files import write_atomically
from virf.names import term_key

if TYPE_CHECKING:  # the Java bridge and the compiler load only when used
    from virf.ontology.artifact import CompiledKB
    from virf.ontology.fragment import Fragment
    from virf.ontology.owlapi import OwlModules
DEFAULT_SCENARIO = "kitchen"

USC_KINDS = ("state-based", "action-based", "logical-inconsistency", "uncertainty")
DANGER_LEVELS = ("low", "medium", "high", "critical")
REQUIRED_USC_ANNOTATIONS = (
    "id",
    "kind",
    "category",
    "dangerLevel",
    "comment",
    "safetyWarning",
    "triggerReason",
    "suggestion",
    "source",
    "checkAt",
)


def ontology_dir() -> Path:
    return Path(str(resources.files("virf.ontology").joinpath("modules")))


def scenario_names() -> list[str]:
    return sorted(p.stem.removeprefix("scenario-") for p in ontology_dir().glob("scenario-*.omn"))


@dataclass(frozen=True)
class UnsafeStateConcept:
    """An Unsafe State Concept with the annotations a report needs."""

    id: str
    name: str
    kind: str
    category: str
    danger_level: str
    description: str
    safety_warning: str
    trigger_reason: str
    suggestion: str
    source: str
    # Defaults for concepts the verifier makes itself (a missing object, an
    # inconsistent world); every concept read from the ontology sets them.
    check_at: str = "always"
    definition: str = ""
    module: str = ""
    question: str = ""
    generalizes: str = ""
    # ``:ai2thorRefuses`` on a step the plan cannot run: "yes" when AI2-THOR
    # itself refuses the step, "no" when it would run it, "" when unsaid.
    ai2thor_refuses: str = ""

    @property
    def final_only(self) -> bool:
        return self.check_at == "final"


@dataclass(frozen=True)
class BackgroundAxiom:
    """A TBox axiom carrying world knowledge (``:kind "background"``)."""

    id: str
    description: str
    source: str
    text: str
    module: str
    signature: frozenset[str]


@dataclass(frozen=True)
class ModuleStats:
    name: str
    iri: str
    label: str
    imports: tuple[str, ...]
    classes: int
    object_properties: int
    data_properties: int
    individuals: int
    logical_axioms: int
    uscs: int
    usc_by_category: Mapping[str, int]
    usc_by_kind: Mapping[str, int]


@dataclass(frozen=True)
class Vocabulary:
    """Immutable, Java-free view of the TBox."""

    classes: frozenset[str]
    object_properties: frozenset[str]
    data_properties: frozenset[str]
    individuals: frozenset[str]
    ancestors: Mapping[str, frozenset[str]]
    annotations: Mapping[str, Mapping[str, tuple[str, ...]]]
    uscs: Mapping[str, UnsafeStateConcept]
    preconditions: Mapping[str, UnsafeStateConcept]
    background: Mapping[str, BackgroundAxiom]
    property_synonyms: Mapping[str, str]
    class_synonyms: Mapping[str, str]
    class_materials: Mapping[str, frozenset[str]]
    _lower: Mapping[str, str] = field(default_factory=dict)
    # property -> its declared inverse (both directions listed)
    inverses: Mapping[str, str] = field(default_factory=dict)
    # C -> M for a class defined exactly as "PhysicalObject and hasMaterial some M"
    # that says nothing else: typing an object C says no more than hasMaterial M.
    material_classes: Mapping[str, str] = field(default_factory=dict)
    # state -> the states it excludes (declared disjoint), plus the epistemic
    # markers it settles (UnknownFillState is settled by a known fill state)
    exclusive_states: Mapping[str, frozenset[str]] = field(default_factory=dict)
    # object types generated from an object-type catalogue (a `:catalogue` annotation)
    catalogue_types: frozenset[str] = frozenset()

    def is_a(self, cls: str, ancestor: str) -> bool:
        return cls == ancestor or ancestor in self.ancestors.get(cls, frozenset())

    def any_is_a(self, classes: frozenset[str] | set[str], ancestor: str) -> bool:
        # (A loop, not a generator over is_a: the simulator asks this of
        # every object it touches, several times a step.)
        ancestors = self.ancestors
        for c in classes:  # noqa: SIM110 - any() over a generator costs a call per class
            if c == ancestor or ancestor in ancestors.get(c, ()):
                return True
        return False

    def annotation(self, term: str, prop: str) -> tuple[str, ...]:
        return self.annotations.get(term, {}).get(prop, ())

    def rule_listing(self) -> list[dict[str, object]]:
        """Every Unsafe State Concept as plain data, with its mechanism and
        minimal pairs: what ``virf kb rules --json`` and ``GET /v1/rules`` give."""
        return [
            {
                **asdict(u),
                "mechanism": next(iter(self.annotation(u.name, "mechanism")), ""),
                "twins": list(self.annotation(u.name, "twin")),
            }
            for u in sorted(self.uscs.values(), key=lambda u: (u.module, u.id))
        ]

    def canonical_class(self, name: str) -> str | None:
        """Resolve a class name case-insensitively, through synonyms."""
        if name in self.classes:
            return self.class_synonyms.get(name, name)
        hit = self._lower.get(name.lower())
        if hit is None:
            return None
        return self.class_synonyms.get(hit, hit)

    def require_class(self, name: str) -> str:
        """The class ``name`` resolves to; InputError for an unknown one, whose
        line names the closest classes by meaning and by spelling."""
        found = self.canonical_class(name)
        if found is None:
            # Only here does the embedder load: resolving a known name never
            # touches it.
            from virf.ontology.suggest import unknown_class

            raise unknown_class(name, self)
        return found

    def materials_of(self, classes: frozenset[str] | set[str]) -> frozenset[str]:
        """Materials every instance of these classes has by background knowledge."""
        out: set[str] = set()
        for cls in classes:
            for c in {cls} | set(self.ancestors.get(cls, ())):
                out |= self.class_materials.get(c, frozenset())
        return frozenset(out)

    def typical_materials(self, classes: frozenset[str] | set[str]) -> tuple[str, ...]:
        for cls in sorted(classes):
            found = self.annotation(cls, "typicalMaterial")
            if found:
                return found
        return ()

    def possible_materials(self, classes: frozenset[str] | set[str]) -> tuple[str, ...]:
        """Materials some instances of these types have and others do not
        (AI2-THOR's vases are ceramic, glass or metal)."""
        return tuple(
            sorted({m for cls in classes for m in self.annotation(cls, "possibleMaterial")})
        )

    def may_afford(self, classes: frozenset[str] | set[str], affordance: str) -> bool:
        """Some instances of these types afford ``affordance`` and others do
        not: the simulator neither assumes nor refuses it."""
        return any(affordance in self.annotation(cls, "mayAfford") for cls in classes)

    @cached_property
    def _keys(self) -> Mapping[str, str]:
        out: dict[str, str] = {}
        for term in sorted(self.classes | self.individuals):
            out.setdefault(term_key(term), term)
        return out

    def term_by_key(self, key: str) -> str | None:
        """The class or individual a name reads as, ignoring case and separators."""
        return self._keys.get(key)

    def excluded_by(self, state: str) -> frozenset[str]:
        """The states an object leaves when it enters ``state``."""
        return self.exclusive_states.get(state, frozenset())

    def canonical_property(self, name: str) -> str | None:
        if name in self.property_synonyms:
            return self.property_synonyms[name]
        if name in self.object_properties or name in self.data_properties:
            return name
        return None


def lower_index(classes: Iterable[str]) -> dict[str, str]:
    """Lower-cased class name -> class, for case-insensitive lookups."""
    return {c.lower(): c for c in sorted(classes)}


def _hint(near: list[str]) -> str:
    return f"; closest known: {', '.join(near)}" if near else ""


class TBox:
    """The ontology of one scenario: the compiled knowledge, and the OWLAPI
    ontology behind it on demand."""

    def __init__(self, kb: CompiledKB, owl: OwlModules | None = None) -> None:
        self.scenario = kb.scenario
        self.compiled = kb
        self.vocabulary: Vocabulary = kb.vocabulary
        self.module_stats: tuple[ModuleStats, ...] = kb.module_stats
        self.fragment: Fragment = kb.fragment
        self.extra_modules: tuple[str, ...] = ()
        # Where the knowledge came from: "artifact" (no Java was needed) or
        # "modules" (compiled in this process).
        self.source = "artifact" if owl is None else "modules"
        self._owl = owl
        self._lock = threading.Lock()

    @property
    def owl(self) -> OwlModules:
        """The modules as OWLAPI loaded them; the first use starts the JVM."""
        with self._lock:
            if self._owl is None:
                from virf.ontology.owlapi import OwlModules

                self._owl = OwlModules(self.scenario, ontology_dir(), self.extra_modules)
            return self._owl


def resolve_scenario(scenario: str | None, kb: str | Path | None) -> str:
    """The scenario a command means: the one named, else the workspace's with
    ``kb``, else the kitchen."""
    if scenario is not None:
        return scenario
    if kb is not None:
        from virf.ontology.workspace import open_layout

        return open_layout(kb).scenario
    return DEFAULT_SCENARIO


def load_tbox(
    scenario: str | None = None,
    extra_modules: tuple[str, ...] = (),
    kb: str | Path | None = None,
) -> TBox:
    """The TBox for ``scenario``, loaded once per process for each content of
    its modules.

    ``kb`` is a knowledge workspace (``virf kb init``): its layered modules of
    reviewed axioms are imported on top of the built-in ones.  ``extra_modules``
    are further Manchester files imported into it (scaling runs, test fixtures,
    a candidate's effect preview).  ``scenario`` defaults to the workspace's
    scenario with ``kb``, else to the kitchen."""
    scenario = resolve_scenario(scenario, kb)
    names = scenario_names()
    if scenario not in names:
        raise InputError(
            f"unknown scenario '{scenario}'" + _hint(closest(scenario, names) or names)
        )
    extras = tuple(str(p) for p in extra_modules)
    cache_dir: str | None = None
    if kb is not None:
        from virf.ontology.workspace import open_layout

        layout = open_layout(kb)
        if layout.scenario != scenario:
            raise InputError(
                f"workspace {kb} is layered on scenario '{layout.scenario}', not '{scenario}'; "
                f"pass --scenario {layout.scenario}"
            )
        # Cached only as the workspace itself: a load with further modules (a
        # candidate's preview) must not replace the workspace's artifact.
        cache_dir = None if extras else str(layout.cache_dir)
        extras = tuple(str(p) for p in layout.modules()) + extras
    # Keyed by content, not path: a workspace gains axioms while a process
    # (the review server) keeps running.
    return _load(scenario, extras, _files_digest(extras), cache_dir)


def _files_digest(paths: tuple[str, ...]) -> str:
    import hashlib

    h = hashlib.sha256()
    for p in paths:
        try:
            data = Path(p).read_bytes()
        except OSError:
            data = b"\0missing"  # OwlModules reports the missing file
        h.update(p.encode() + b"\0" + data + b"\0")
    return h.hexdigest()


@cache
def _load(
    scenario: str, extras: tuple[str, ...], extras_digest: str, cache_dir: str | None
) -> TBox:
    from virf.ontology.artifact import from_json, to_json
    from virf.ontology.compile import compile_kb, read_artifact, source_digest
    from virf.ontology.seal import local_key, seal, unseal

    digest = source_digest()
    # A workspace's artifact sits in its own writable cache folder, where its
    # digest is no proof of anything: it is used only under a seal of this
    # user's key (virf.ontology.seal), else compiled again.  The built-in
    # artifacts ship inside the package, trusted like its code.
    key: bytes | None = None
    artifact: Path | None = None  # the workspace's sealed cache
    if extras:
        digest = f"{digest}+{extras_digest}"
        key = local_key() if cache_dir is not None else None
        if cache_dir is not None and key is not None:
            artifact = Path(cache_dir) / f"compiled-{scenario}.json"
    kb: CompiledKB | None = None
    try:
        if not extras:
            kb = read_artifact(scenario)
        elif artifact is not None and key is not None:
            opened = unseal(artifact.read_text(encoding="utf-8"), key)
            kb = from_json(opened) if opened is not None else None
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        kb = None  # missing, unreadable or unsealed: compile the modules instead
    if kb is not None and kb.digest == digest and kb.scenario == scenario:
        tbox = TBox(kb)
        tbox.extra_modules = extras
        return tbox
    from virf.ontology.owlapi import OwlModules

    owl = OwlModules(scenario, ontology_dir(), extras)
    tbox = TBox(compile_kb(owl, digest), owl)
    tbox.extra_modules = extras
    if key is not None and artifact is not None:
        try:
            artifact.parent.mkdir(parents=True, exist_ok=True)
            write_atomically(artifact, seal(to_json(tbox.compiled), key))
        except OSError:
            pass  # a cache: failing to write it only costs the next load a compile
    return tbox
