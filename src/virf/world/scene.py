"""Read a scene (the paper's ABox JSON) into facts with provenance.

Format (Appendix C of the paper)::

    {"instances":  [{"class_name": "Pot", "instance_name": "Pot_1"}, ...],
     "assertions": [{"subject": "Pot_1", "property": "isOn",
                     "object": "CounterTop_1", "type": "object_property"}, ...],
     "closed_world": ["contains", "supports"],          # optional
     "unlocated_by_default": false}                     # optional

* An instance may be listed several times with different classes, or typed
  by ``rdf:type`` assertions.
* One world, many spellings: the reader builds one canonical world.  A state
  or material is stored as its class's own individual (``hasState OnState``,
  ``hasMaterial Metal``) whether the scene names that individual, an
  individual of the class (``On_1``, ``DoorClosedState_1``), a word
  (``"closed"``), or gives the object the class as a type; a class defined
  only by a material (``MetallicObject``) becomes ``hasMaterial Metal``.
  Either direction of an inverse pair is stored in one direction
  (``isOn`` as ``supports``).  How the scene wrote a rewritten fact is kept in
  ``Scene.spelling`` for reports.  docs/scenes.md lists every form.
* Objects in a scene were perceived, so they start *located* (``isLocated
  true``) unless an assertion says ``isLocated false`` or the scene sets
  ``unlocated_by_default`` (as a benchmark scene does for a robot that must
  ``find`` everything before acting on it).
* ``unknown_contents`` lists objects whose contents are not known even when
  ``contains`` is closed-world (a pot AI2-THOR may have filled).
* ``closed_world`` names relations the scene lists completely.  Closure facts
  for other relations are open-world assumptions: a hazard that needs one is
  UNKNOWN, with a question, rather than UNSAFE.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, Field

from virf.errors import (
    EnvironmentProblem,
    InputError,
    Record,
    Says,
    clip,
    closest,
    hidden_char,
    read_json_file,
)
from virf.names import term_key
from virf.ontology.lexicon import Proposal, propose
from virf.ontology.tbox import Vocabulary
from virf.schema import Fact, FactKind, Provenance

NAME_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]*")
# Limits on one scene (docs/scenes.md): well above real rooms, well below what
# would overrun the verification deadline or memory.
MAX_INSTANCES = 5_000
MAX_ASSERTIONS = 50_000
MAX_NAME = 128
# The direction in which the simulator reads each relation; a scene may write
# either direction of any inverse pair the ontology declares.
CANONICAL_DIRECTION = ("contains", "supports", "isHolding", "controls")
TYPE_PROPERTIES = frozenset({"rdf:type", "type", "a", "isA", "is_a", "instanceOf"})
# The property that carries each kind of value individual.
VALUE_PROPERTY = {"State": "hasState", "Material": "hasMaterial", "Attribute": "hasProperty"}
CLOSABLE = ("contains", "supports")
# Words a scene may use as data values of hasState/hasMaterial.
VALUE_WORDS = {
    "on": "OnState",
    "off": "OffState",
    "open": "OpenState",
    "opened": "OpenState",
    "closed": "ClosedState",
    "close": "ClosedState",
    "hot": "HotState",
    "cold": "ColdState",
    "wet": "WetState",
    "dry": "DryState",
    "dirty": "DirtyState",
    "clean": "CleanState",
    "broken": "BrokenState",
    "sliced": "SlicedState",
    "cooked": "CookedState",
    "filled": "FilledWithLiquidState",
    "full": "FilledWithLiquidState",
    "empty": "EmptyState",
    "usedup": "UsedUpState",
    "sealed": "SealedState",
    "lit": "OnState",
    "burning": "OnState",
    "running": "OnState",
    "plugged": "PluggedInState",
    "pluggedin": "PluggedInState",
    "unplugged": "UnpluggedState",
    "unknown": "UnknownMaterial",
    "metallic": "Metal",
}


def _near_values(value: str, prop: str, instances: list[str], vocab: Vocabulary) -> list[str]:
    """What an unknown value of ``prop`` may have meant: for a state, the
    states its words or spelling come near ('switched on' -> OnState, 'lite'
    -> OnState, by the word 'lit'); for a material, the materials; else any
    instance or individual."""
    if prop == "hasState":
        words = {w: v for w, v in VALUE_WORDS.items() if v.endswith("State")}
        pool = sorted({*(i for i in vocab.individuals if i.endswith("State")), *words})
    elif prop == "hasMaterial":
        known = set().union(*vocab.class_materials.values(), vocab.material_classes.values())
        pool = sorted(m for m in known if m in vocab.individuals)
        words = {w: v for w, v in VALUE_WORDS.items() if v in pool}
    else:
        return closest(value, instances + sorted(vocab.individuals))
    said = [words[w] for w in re.findall(r"[a-z]+", value.lower()) if w in words]
    near = said + [words.get(n, n) for n in closest(value, pool)]
    return list(dict.fromkeys(near))[:3]


DEFAULT_AGENT = "Robot_1"
# A class name the knowledge base lacks is read as an open-world object when
# it looks like a name of a kind of thing ('HairDryer', 'space heater').
OPEN_CLASS_RE = re.compile(r"[A-Za-z][A-Za-z0-9]*(?:[ _\-][A-Za-z0-9]+)*")
MAX_OPEN_CLASS = 64
# How close in spelling an unknown name must be to a known class to be read
# as a misspelling of it ('Mircowave') rather than as a new kind of thing.
TYPO_CUTOFF = 0.8
# How near in meaning (cosine of the sentence embeddings) a class must be to
# be proposed as the place of a word WordNet lacks ('nightlight'); below it
# the neighbours are noise ('zorblax' -> PepperShaker at 0.45).
PROPOSAL_FLOOR = 0.5


# The scene file's shape (docs/scenes.md).  Every spelling of a world passes
# here; what the names mean is the reader's business (``build_scene``).
class InstanceEntry(Record):
    when_not_object = "{where} needs 'class_name' and 'instance_name'"
    when_missing = when_not_object

    class_name: str
    instance_name: str


class AssertionEntry(Record):
    when_not_object = "{where} needs 'subject', 'property' and 'object'"
    when_missing = when_not_object

    subject: str
    property: str
    # true/false: a data property's value; as an individual it is refused later.
    object: Annotated[
        str | bool,
        Says("{where}: 'object' must be a string (or true/false for a data property), not {value}"),
    ]
    type: Annotated[
        Literal["object_property", "data_property"],
        Says("{where}: type '{text}' must be object_property or data_property"),
    ] = "object_property"
    # A fact the source is not sure of (perception below its confidence
    # threshold): a hazard that needs it is UNKNOWN, with it as the question.
    assumed: Annotated[bool, Says("{where}: 'assumed' must be true or false")] = False


def _one_visible_line(name: str) -> str:
    if not name.strip() or hidden_char(name) is not None:
        raise ValueError("not one line of visible text")
    return name


class SceneDocument(Record):
    when_not_object = "{where} must be a JSON object with 'instances' and 'assertions'"
    # The message users know, word for word (it has never listed 'name').
    when_unknown_key = (
        "unknown scene key '{key}'; expected instances, assertions, closed_world, "
        "unlocated_by_default, unknown_contents, referents, denied, description"
    )

    instances: Annotated[
        list[InstanceEntry],
        Field(max_length=MAX_INSTANCES),
        Says(
            "{where} needs an 'instances' list",
            too_long="{where} has {actual_length} instances; the limit is {max_length}",
        ),
    ]
    assertions: Annotated[
        list[AssertionEntry],
        Field(default_factory=list, max_length=MAX_ASSERTIONS),
        Says(
            "{where} 'assertions' must be a list",
            too_long="{where} has {actual_length} assertions; the limit is {max_length}",
        ),
    ]
    unlocated_by_default: bool = False
    # None is the same as no name (it reads as the string "None", as it always has).
    name: Annotated[
        Annotated[str, Field(max_length=MAX_NAME), AfterValidator(_one_visible_line)] | None,
        Says(
            f"{{where}} 'name' must be one line of at most {MAX_NAME} visible characters, "
            "not {value}"
        ),
    ] = None
    description: str = ""
    referents: Annotated[
        dict[str, str],
        Field(default_factory=dict),
        Says(
            "{where} 'referents' must map plan words to declared instances, "
            'e.g. {{"bowl": "Bowl_2"}}'
        ),
    ]
    closed_world: Annotated[
        list[str],
        Field(default_factory=list),
        Says("{where} 'closed_world' must be a list of relation names"),
    ]
    denied: Annotated[
        list[str],
        Field(default_factory=list),
        Says("{where} 'denied' must be a list of facts written 'Subject property Object'"),
    ]
    unknown_contents: Annotated[
        list[str],
        Field(default_factory=list),
        Says("{where} 'unknown_contents' must list declared instances"),
    ]


@dataclass(frozen=True)
class Scene:
    """A validated scene: its individuals, typed facts and closed relations."""

    objects: Mapping[str, frozenset[str]]  # individual -> asserted classes (objects and agents)
    order: tuple[str, ...]  # scene order of objects, for deterministic resolution
    facts: Mapping[Fact, Provenance]
    agent: str
    closed_world: frozenset[str]
    name: str = "scene"
    unknown_contents: frozenset[str] = frozenset()
    unlocated_by_default: bool = False
    # What a plan's type word means when several instances fit equally well
    # (a user's answer to an ambiguity question): term_key(word) -> instance.
    referents: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))
    # canonical fact -> the fact as the scene wrote it, where the two differ
    # ('Toaster_1 hasState OnState_1' for 'Toaster_1 hasState OnState'), so
    # that reports can speak the user's words
    spelling: Mapping[Fact, Fact] = field(default_factory=lambda: MappingProxyType({}))
    # How the reader read what the knowledge base does not name (an open-world
    # object and the place proposed for it), for the report's notes.
    notes: tuple[str, ...] = ()
    # Objects whose class the knowledge base does not name: instance -> the
    # class name as written (HairDryer_1 -> 'HairDryer').
    open_world: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))


def load_scene_file(path: str | Path, vocab: Vocabulary) -> Scene:
    p = Path(path)
    return build_scene(
        load_scene_data(p), vocab, name=p.stem if p.stem != "scene" else p.parent.name
    )


def load_scene_data(path: str | Path) -> dict[str, Any]:
    """A scene file's JSON object, unvalidated (``build_scene`` checks it)."""
    data = read_json_file(path, "scene")
    if not isinstance(data, dict):
        raise InputError(f"scene {path} must be a JSON object with 'instances' and 'assertions'")
    return data


def build_scene(
    data: Any, vocab: Vocabulary, name: str = "scene", *, strict_vocabulary: bool = False
) -> Scene:
    """The canonical world ``data`` describes. A class name the knowledge base
    lacks makes an open-world object (see :func:`_open_world`) unless
    ``strict_vocabulary``, which refuses it."""
    doc = SceneDocument.parse(data, "scene")
    instances, assertions = doc.instances, doc.assertions

    classes: dict[str, set[str]] = {}
    order: list[str] = []
    # Names that could be read as another term: a plan says 'pan' for a Pan,
    # so an instance called 'pan' (or 'PAN') would be a second reading.
    keyed: dict[str, str] = {}
    # Class names the knowledge base lacks, per instance, as written.
    unknown_names: dict[str, list[str]] = {}

    def declare(iname: str, cname: str, where: str) -> None:
        if not NAME_RE.fullmatch(iname) or len(iname) > MAX_NAME:
            raise InputError(
                f"{where}: instance name '{clip(iname)}' must start with a letter or '_', "
                f"use only letters, digits, '_', '.', '-', and be at most {MAX_NAME} characters"
            )
        key = term_key(iname)
        term = vocab.term_by_key(key)
        if term is not None:
            raise InputError(
                f"{where}: instance name '{iname}' reads as the ontology term '{term}'; "
                f"choose another name, such as '{term}_1'"
            )
        if keyed.setdefault(key, iname) != iname:
            raise InputError(
                f"{where}: instance names '{keyed[key]}' and '{iname}' differ only in case or "
                "separators, so a plan could not tell them apart"
            )
        cls = vocab.canonical_class(cname)
        if cls is None:
            # One class, many spellings: 'stove knob', 'stove_knob', 'Stove-Knob'.
            hit = vocab.term_by_key(term_key(cname))
            cls = vocab.canonical_class(hit) if hit is not None else None
        if cls is None:
            _check_open_class(cname, vocab, strict_vocabulary)
        if iname not in classes:
            classes[iname] = set()
            order.append(iname)
        if cls is None:
            unknown_names.setdefault(iname, []).append(cname)
        else:
            classes[iname].add(cls)

    for i, inst in enumerate(instances):
        declare(inst.instance_name, inst.class_name, f"instances[{i}]")
    # rdf:type assertions declare and type individuals like 'instances' entries;
    # they are read first because an individual's kind depends on its types.
    for i, a in enumerate(assertions):
        if a.property in TYPE_PROPERTIES:
            declare(a.subject, str(a.object), f"assertions[{i}]")
    # An object named by a class the knowledge base lacks is an open-world
    # object: what the name suggests stays a hypothesis even when the user
    # has since given it a known class too (a Vinegar confirmed as food may
    # still be an acid).
    open_world = {ind: words[0] for ind, words in unknown_names.items()}
    proposals = {ind: propose(word) for ind, word in open_world.items()}
    for ind, proposal in proposals.items():
        if not classes[ind]:
            classes[ind].add("MaterialEntity" if proposal.person else "PhysicalObject")

    # An individual of a material class is a value ('Pot_1 hasMaterial
    # Metal_1') when some assertion uses it as one; otherwise it is a portion
    # of that stuff (bleach in a toilet), an object like any other.
    used_as_value = {
        str(a.object)
        for a in assertions
        if a.property not in TYPE_PROPERTIES
        and vocab.canonical_property(a.property) in VALUE_PROPERTY.values()
    }
    values = _value_individuals(classes, vocab, used_as_value)
    facts: dict[Fact, Provenance] = {}
    spelling: dict[Fact, Fact] = {}

    def state(fact: Fact, assumed: bool) -> None:
        # Stated once for sure, a fact stays sure however often it is assumed.
        if not assumed:
            facts[fact] = Provenance.SCENE
        else:
            facts.setdefault(fact, Provenance.ASSUMED)

    def state_fact(subject: str, value: str, written: Fact, assumed: bool = False) -> None:
        """A state, material or attribute of ``subject``, whatever property named it."""
        kind = _value_kind(value, classes, vocab)
        assert kind is not None  # callers pass only value individuals
        fact = Fact(subject, VALUE_PROPERTY[kind], value)
        state(fact, assumed)
        if written != fact:
            spelling.setdefault(fact, written)

    for ind in order:
        if ind in values:
            # A user's individual of a state or material class stands for the
            # class's canonical individual; one without one is kept as written.
            if not values[ind]:
                for cls in sorted(classes[ind]):
                    facts[Fact(ind, "type", cls, FactKind.TYPE)] = Provenance.SCENE
            continue
        kept: set[str] = set()
        for cls in sorted(classes[ind]):
            written = Fact(ind, "type", cls, FactKind.TYPE)
            if _value_kind(cls, classes, vocab) is not None and cls in vocab.individuals:
                state_fact(ind, cls, written)  # an object typed OpenState is open
                if vocab.is_a(cls, "Material"):
                    kept.add("Substance")  # typed by its stuff alone: a portion of it
            elif cls in vocab.material_classes:
                state_fact(ind, vocab.material_classes[cls], written)
                kept.add("PhysicalObject")
            else:
                kept.add(cls)
        for cls in sorted(_most_specific(kept, vocab)):
            facts[Fact(ind, "type", cls, FactKind.TYPE)] = Provenance.SCENE
        classes[ind] = _most_specific(kept, vocab)

    _check_referent_words(doc.referents)
    closed = doc.closed_world
    for entry in closed:
        if not entry.strip():
            raise InputError("closed_world: empty entry; choose from " + ", ".join(CLOSABLE))
        # "contains" closes the relation for every receptacle; "contains:Fridge_1"
        # for one (a user confirming what is inside one thing).
        rel, colon, owner = entry.partition(":")
        if rel not in CLOSABLE:
            raise InputError(
                f"closed_world: '{clip(rel)}' cannot be closed; choose from {', '.join(CLOSABLE)}"
            )
        if colon and not owner:
            # "contains:" closes nothing a reader can name: neither every
            # receptacle nor one.
            raise InputError(
                f"closed_world: '{entry}' names no instance; write '{rel}' or '{rel}:NAME'"
            )
        if owner and owner not in classes:
            near = closest(owner[:200], classes)
            hint = f"; closest known: {', '.join(near)}" if near else ""
            raise InputError(f"closed_world: '{clip(entry)}' names an undeclared instance{hint}")

    def resolve_value(value: str, prop: str, where: str) -> list[str]:
        if value in classes:
            return list(values.get(value) or [value])
        if value in vocab.individuals:
            return [value]
        alias = vocab.class_synonyms.get(value)
        if alias and alias in vocab.individuals:
            return [alias]
        lowered = value.lower().replace("_", "").replace(" ", "")
        if lowered.startswith("is") and lowered[2:] in VALUE_WORDS:
            lowered = lowered[2:]
        if lowered == "unknown":
            return ["UnknownFillState" if prop == "hasState" else "UnknownMaterial"]
        if lowered in VALUE_WORDS:
            return [VALUE_WORDS[lowered]]
        for ind in sorted(vocab.individuals):
            if ind.lower() == lowered or ind.lower() == lowered + "state":
                return [ind]
        near = _near_values(value, prop, list(classes), vocab)
        hint = f"; closest known: {', '.join(near)}" if near else ""
        raise InputError(f"{where}: unknown individual or value '{clip(value)}' for {prop}{hint}")

    for i, a in enumerate(assertions):
        where = f"assertions[{i}]"
        subj, prop_name, obj, kind = a.subject, a.property, a.object, a.type
        if prop_name in TYPE_PROPERTIES:
            continue
        if subj not in classes:
            near = closest(subj, classes)
            hint = f"; closest known: {', '.join(near)}" if near else ""
            raise InputError(
                f"{where}: unknown individual '{clip(subj)}' (declare it in instances){hint}"
            )
        prop = vocab.canonical_property(prop_name)
        if prop is None:
            near = closest(prop_name, list(vocab.object_properties | vocab.data_properties))
            hint = f"; closest known: {', '.join(near)}" if near else ""
            raise InputError(f"{where}: unknown property '{clip(prop_name)}'{hint}")
        if prop in vocab.data_properties:
            if not isinstance(obj, bool) and str(obj).lower() not in ("true", "false"):
                raise InputError(f"{where}: {prop} takes true or false, not '{clip(str(obj))}'")
            value = str(obj).lower()
            state(Fact(subj, prop, value, FactKind.DATA), a.assumed)
            continue
        if kind == "data_property" and prop not in VALUE_PROPERTY.values():
            # Appendix C writes states as data values; a relation between two
            # individuals has no literal reading.
            raise InputError(
                f"{where}: {prop_name} relates two individuals; write it with type object_property"
            )
        if isinstance(obj, bool):
            raise InputError(f"{where}: {prop_name} needs an individual, not {str(obj).lower()}")
        written_obj = str(obj)
        for target in resolve_value(written_obj, prop, where):
            written = Fact(subj, prop_name, written_obj)
            if prop in VALUE_PROPERTY.values():
                if subj in values:
                    raise InputError(f"{where}: '{subj}' is a {prop} value, not an object")
                if _value_kind(target, classes, vocab) is None:
                    raise InputError(
                        f"{where}: {prop} needs a state, material or attribute, "
                        f"not '{clip(written_obj)}'"
                    )
                state_fact(subj, target, written, a.assumed)
                continue
            fact = _canonical_direction(subj, prop, target, vocab)
            if fact.subject not in classes or (
                fact.object not in classes and fact.object not in vocab.individuals
            ):
                raise InputError(f"{where}: '{target}' must be a declared instance for {prop_name}")
            state(fact, a.assumed)
            if fact != written:
                spelling.setdefault(fact, written)

    _check_physical(facts)
    unknown_contents = doc.unknown_contents
    if any(u not in classes for u in unknown_contents):
        raise InputError("scene 'unknown_contents' must list declared instances")
    referents = doc.referents
    if not all(v in classes for v in referents.values()):
        raise InputError(
            'scene \'referents\' must map plan words to declared instances, e.g. {"bowl": "Bowl_2"}'
        )
    objects = {
        ind: frozenset(cs)
        for ind, cs in classes.items()
        if ind not in values and not vocab.any_is_a(cs, "Action")
    }
    object_order = tuple(ind for ind in order if ind in objects)

    agents = [ind for ind in object_order if vocab.any_is_a(objects[ind], "Robot")]
    if len(agents) > 1:
        # The plan's actor would be whichever robot the file lists first, so
        # reordering the file could turn UNSAFE into SAFE.
        raise InputError(
            f"scene has {len(agents)} robots ({', '.join(sorted(agents)[:3])}); a plan is "
            "verified for one agent, so declare one Robot"
        )
    if agents:
        agent = agents[0]
    else:
        agent = DEFAULT_AGENT
        while agent in classes:
            agent = "_" + agent
        objects[agent] = frozenset({"Robot"})
        facts[Fact(agent, "type", "Robot", FactKind.TYPE)] = Provenance.PLAN

    _apply_default_states(objects, facts, vocab)
    _apply_material_knowledge(objects, facts, vocab)
    _mark_unknown_fill(objects, facts, vocab)
    _mark_unknown_contents(objects, facts, vocab, frozenset(closed), frozenset(unknown_contents))
    _assume_controls(objects, object_order, facts, vocab)
    notes = _hypothesise(proposals, open_world, facts, vocab)
    _deny(doc.denied, facts, classes, vocab)
    return Scene(
        objects=MappingProxyType(objects),
        order=object_order,
        facts=MappingProxyType(dict(sorted(facts.items()))),
        agent=agent,
        closed_world=frozenset(closed),
        name=str(doc.name) if "name" in doc.model_fields_set else name,
        unlocated_by_default=doc.unlocated_by_default,
        unknown_contents=frozenset(unknown_contents),
        referents=MappingProxyType({term_key(k): v for k, v in sorted(referents.items())}),
        spelling=MappingProxyType(dict(sorted(spelling.items()))),
        notes=notes,
        open_world=MappingProxyType(dict(sorted(open_world.items()))),
    )


def _check_open_class(cname: str, vocab: Vocabulary, strict: bool) -> None:
    """Refuse a class name that cannot be an open-world object: under
    ``strict``, one that does not look like a name, or a misspelling of a
    known class that the dictionary does not know either ('Mircowave' is a
    microwave, and reading it as an unknown thing would lose its hazards)."""
    if strict or len(cname) > MAX_OPEN_CLASS or not OPEN_CLASS_RE.fullmatch(cname):
        vocab.require_class(cname)  # raises, naming the closest classes
    if propose(cname).found:
        return
    near = closest(cname, vocab.classes)
    typo = [
        c
        for c in near
        if difflib.SequenceMatcher(None, cname.lower(), c.lower()).ratio() >= TYPO_CUTOFF
    ]
    if typo:
        raise InputError(
            f"unknown class '{clip(cname)}' (neither the knowledge base nor the dictionary "
            f"knows it, and it is spelled like a known class); closest known: {', '.join(typo)}"
        )


# What a hypothesis asks, in words (questions and notes).
HYPOTHESIS_WORDS = {
    "ElectricallyPowered": "an electrical appliance",
    "HeatSource": "a heat source",
    "OpenFlame": "an open flame",
    "HotBulb": "a lamp with a hot bulb",
    "Flammable": "flammable",
    "Fragile": "fragile",
    "Toxic": "toxic",
    "Sharp": "sharp",
}


def _hypothesise(
    proposals: Mapping[str, Proposal],
    open_world: Mapping[str, str],
    facts: dict[Fact, Provenance],
    vocab: Vocabulary,
) -> tuple[str, ...]:
    """Add each open-world object's proposal as assumed facts (a hazard that
    needs one is UNKNOWN, asking about it) and say what was read."""
    stated_material = {
        f.subject
        for f, p in facts.items()
        if f.predicate == "hasMaterial" and p is Provenance.SCENE
    }
    notes = []
    for ind in sorted(proposals):
        p = proposals[ind]
        said = []
        for prop in p.properties:
            if prop in vocab.individuals:
                facts.setdefault(Fact(ind, "hasProperty", prop), Provenance.ASSUMED)
                said.append(HYPOTHESIS_WORDS.get(prop, prop))
        if ind not in stated_material:
            for m in p.materials:
                if m in vocab.individuals:
                    facts.setdefault(Fact(ind, "hasMaterial", m), Provenance.ASSUMED)
                    said.append(f"made of {m}")
        for t in p.types:
            if vocab.canonical_class(t) is not None:
                facts.setdefault(Fact(ind, "type", t, FactKind.TYPE), Provenance.ASSUMED)
                said.append(f"a {t}")
        base = "a person (MaterialEntity)" if p.person else "a PhysicalObject"
        parent = _proposed_parent(open_world[ind], p, vocab)
        place = f"; proposed place: under {parent}" if parent else ""
        hypotheses = (
            f"it may be {', '.join(said)}, which is asked only where a hazard depends on it"
            if said
            else "nothing suggests a hazard of its own; its material is unknown"
        )
        notes.append(
            f"{ind}: '{open_world[ind]}' is not a class of the knowledge base; read as {base} "
            f"of the open world ({p.describe()}{place}); {hypotheses}"
        )
    return tuple(notes)


def _proposed_parent(word: str, p: Proposal, vocab: Vocabulary) -> str | None:
    """Where the object might sit in the ontology, for the user and for
    learning: the nearest WordNet hypernym the knowledge base names (a
    bookshelf is a kind of shelf), else, for a word WordNet lacks, the class
    closest in meaning (the bundled sentence embedder)."""
    for hypernym in p.path[:6]:
        cls = vocab.canonical_class(term_key(hypernym))
        if cls is not None and cls not in ("PhysicalObject", "Entity", "Agent"):
            return f"{cls} (WordNet)"
    if p.found or not p.dictionary:
        return None
    from virf.ontology.suggest import rank_classes  # loads the embedder: only here

    try:
        ranked = rank_classes(word, vocab, "object")
    except (EnvironmentProblem, OSError):  # a missing model only loses the proposal
        return None
    best = max(ranked, key=lambda r: (r.meaning, r.name), default=None)
    if best is None or best.meaning < PROPOSAL_FLOOR:
        return None
    return f"{best.name} (closest in meaning)"


def _deny(
    denied: list[str],
    facts: dict[Fact, Provenance],
    classes: Mapping[str, set[str]],
    vocab: Vocabulary,
) -> None:
    """Drop the assumptions the user has said are false ('denied': a 'no' to
    a question about one); denying what the scene states is a contradiction."""
    for i, text in enumerate(denied):
        parts = text.split()
        if len(parts) != 3:
            raise InputError(f"scene denied[{i}]: '{clip(text)}' must be 'Subject property Object'")
        subject, prop, obj = parts
        if subject not in classes:
            raise InputError(f"scene denied[{i}]: '{clip(subject)}' is not a declared instance")
        if prop in TYPE_PROPERTIES:
            fact = Fact(subject, "type", obj, FactKind.TYPE)
        else:
            canonical = vocab.canonical_property(prop)
            if canonical is None:
                raise InputError(f"scene denied[{i}]: unknown property '{clip(prop)}'")
            fact = Fact(subject, canonical, obj)
        provenance = facts.get(fact)
        if provenance is Provenance.SCENE:
            raise InputError(f"scene denied[{i}]: the scene also states {fact.render()}")
        if provenance is Provenance.ASSUMED:
            del facts[fact]


def _check_referent_words(referents: Mapping[str, str]) -> None:
    for word in referents:
        if not term_key(word) or hidden_char(word) is not None:
            # The key is a word of a plan, compared through term_key: one
            # that reads as nothing ("", "--") would match nothing a plan says.
            raise InputError(
                f"scene 'referents': '{clip(word, 40)}' is not a word a plan could use"
            )


def _check_physical(facts: Mapping[Fact, Provenance]) -> None:
    """Worlds that cannot exist are bad input, not something to verify: a hand
    holding two things, an object in or on two places, a thing inside itself."""
    held: dict[str, list[str]] = {}
    parents: dict[str, list[str]] = {}
    for f in facts:
        if f.kind is not FactKind.OBJECT:
            continue
        if f.predicate == "isHolding":
            held.setdefault(f.subject, []).append(f.object)
            parents.setdefault(f.object, []).append(f.subject)
        elif f.predicate in ("contains", "supports"):
            if f.subject == f.object:
                raise InputError(f"scene: {f.subject} {f.predicate} itself")
            parents.setdefault(f.object, []).append(f.subject)
    for agent, things in sorted(held.items()):
        if len(things) > 1:
            raise InputError(
                f"scene: {agent} holds {' and '.join(sorted(things))}; a robot holds one object"
            )
    for thing, places in sorted(parents.items()):
        if len(places) > 1:
            raise InputError(
                f"scene: {thing} is in, on or held by {' and '.join(sorted(places))} at once; "
                "give it one place"
            )
    # Each chain is walked once: restarting from every object would be cubic
    # in a deep nesting (5,000 boxes one inside the next took minutes).
    done: set[str] = set()
    for start in sorted(parents):
        path: dict[str, int] = {}
        node = start
        while node in parents and node not in done:
            if node in path:
                chain = list(path)
                cycle = " in ".join([*chain[path[node] :], node])
                raise InputError(f"scene: containment cycle {cycle}")
            path[node] = len(path)
            node = parents[node][0]
        done.update(path)


def _value_kind(term: str, classes: Mapping[str, set[str]], vocab: Vocabulary) -> str | None:
    """'State', 'Material' or 'Attribute' for a value individual or class."""
    types = classes.get(term) or {term}
    for root in VALUE_PROPERTY:
        if types and all(vocab.is_a(c, root) for c in types):
            return root
    return None


def _value_individuals(
    classes: Mapping[str, set[str]], vocab: Vocabulary, used_as_value: set[str]
) -> dict[str, list[str]]:
    """User individuals of state, material or attribute classes, each with the
    canonical individuals it stands for (empty: keep the user's individual,
    because some class of it has no canonical individual).  An individual of
    material classes only is a value only where a scene uses it as one."""
    out: dict[str, list[str]] = {}
    for ind, cs in classes.items():
        kind = _value_kind(ind, classes, vocab)
        if kind is None or (kind == "Material" and ind not in used_as_value):
            continue
        specific = _most_specific(cs, vocab)
        out[ind] = sorted(specific) if specific <= vocab.individuals else []
    return out


def _most_specific(classes: set[str], vocab: Vocabulary) -> set[str]:
    """The classes without a strict subclass among them: the others are implied."""
    return {
        c
        for c in classes
        if not any(d != c and vocab.is_a(d, c) and not vocab.is_a(c, d) for d in classes)
    }


def _canonical_direction(subject: str, prop: str, obj: str, vocab: Vocabulary) -> Fact:
    """One spelling of a relation and its inverse: the simulator's direction
    where it reads the relation, else the 'has...' side of the pair."""
    inverse = vocab.inverses.get(prop)
    if inverse is None or prop in CANONICAL_DIRECTION:
        return Fact(subject, prop, obj)
    if (
        inverse in CANONICAL_DIRECTION
        or (prop.startswith("is") and not inverse.startswith("is"))
        or (prop.startswith("is") == inverse.startswith("is") and inverse < prop)
    ):
        return Fact(obj, inverse, subject)
    return Fact(subject, prop, obj)


def _apply_default_states(
    objects: dict[str, frozenset[str]], facts: dict[Fact, Provenance], vocab: Vocabulary
) -> None:
    """States a type starts in (a fridge is closed, a toaster off) when the
    scene says nothing about that state or its opposite."""
    stated: dict[str, set[str]] = {}
    for f in facts:
        if f.predicate == "hasState":
            stated.setdefault(f.subject, set()).add(f.object)
    for ind, cs in objects.items():
        have = stated.get(ind, set())
        for cls in sorted(cs):
            for default in vocab.annotation(cls, "defaultState"):
                if not have & (vocab.excluded_by(default) | {default}):
                    facts[Fact(ind, "hasState", default)] = Provenance.DEFAULT
                    have = have | {default}


def _assume_controls(
    objects: dict[str, frozenset[str]],
    order: tuple[str, ...],
    facts: dict[Fact, Provenance],
    vocab: Vocabulary,
) -> None:
    """A control whose device the scene does not name (a stove knob without a
    'controls' fact) is assumed to control every device of its type: hazards
    that follow are then UNKNOWN, with the assumption as the question."""
    stated = {f.subject for f in facts if f.predicate == "controls"}
    for ind in order:
        if ind in stated:
            continue
        for cls in sorted(objects[ind]):
            for device_type in vocab.annotation(cls, "controlsType"):
                for device in order:
                    if vocab.any_is_a(objects[device], device_type):
                        facts[Fact(ind, "controls", device)] = Provenance.ASSUMED


def _mark_unknown_fill(
    objects: dict[str, frozenset[str]], facts: dict[Fact, Provenance], vocab: Vocabulary
) -> None:
    """A liquid container whose fill state the scene does not give gets an
    explicit UnknownFillState marker (AI2-THOR randomises it)."""
    fill_known = {
        f.subject
        for f in facts
        if f.predicate == "hasState"
        and f.object in ("FilledWithLiquidState", "EmptyState", "UnknownFillState")
    }
    for ind, cs in objects.items():
        if ind not in fill_known and vocab.any_is_a(cs, "LiquidContainer"):
            facts[Fact(ind, "hasState", "UnknownFillState")] = Provenance.ASSUMED


def _mark_unknown_contents(
    objects: dict[str, frozenset[str]],
    facts: dict[Fact, Provenance],
    vocab: Vocabulary,
    closed: frozenset[str],
    unknown_contents: frozenset[str],
) -> None:
    """A receptacle or vessel whose contents the scene does not list
    completely gets an explicit UnknownContentsState marker: a toilet or a
    bucket may already hold a cleaner nobody mentioned."""
    for ind, cs in objects.items():
        if not (vocab.any_is_a(cs, "ContainerReceptacle") or vocab.any_is_a(cs, "LiquidContainer")):
            continue
        listed = "contains" in closed or f"contains:{ind}" in closed
        if not listed or ind in unknown_contents:
            facts[Fact(ind, "hasState", "UnknownContentsState")] = Provenance.ASSUMED


def _apply_material_knowledge(
    objects: dict[str, frozenset[str]], facts: dict[Fact, Provenance], vocab: Vocabulary
) -> None:
    """Typical-material defaults, possible materials, then unknown-material
    markers, for objects whose scene states no material.

    A Mug is ceramic *unless the scene says otherwise*: OWL has no defaults, so
    the default is applied here.  A Vase may be ceramic, glass or metal (AI2-THOR's
    vases differ): each possibility is an ASSUMED fact, so a hazard that needs
    one is UNKNOWN and asks what the vase is made of, never UNSAFE or SAFE.  An
    object whose material is still unknown gets an explicit UnknownMaterial
    marker (an ASSUMED fact): the open world made visible, so that uncertainty
    rules can ask about it.
    """
    stated: dict[str, set[str]] = {}
    for f in facts:
        if f.predicate == "hasMaterial":
            stated.setdefault(f.subject, set()).add(f.object)
    for ind, cs in objects.items():
        if not vocab.any_is_a(cs, "PhysicalObject") or vocab.any_is_a(cs, "Liquid"):
            continue
        if stated.get(ind):
            continue
        typical = vocab.typical_materials(cs)
        possible = vocab.possible_materials(cs)
        for m in typical:
            facts[Fact(ind, "hasMaterial", m)] = Provenance.DEFAULT
        for m in possible:
            facts.setdefault(Fact(ind, "hasMaterial", m), Provenance.ASSUMED)
        if not (typical or possible or vocab.materials_of(cs) or vocab.any_is_a(cs, "FoodItem")):
            facts[Fact(ind, "hasMaterial", "UnknownMaterial")] = Provenance.ASSUMED


def describe_scene(scene: Scene) -> dict[str, Any]:
    """The canonical world the reader built, as plain data (``virf scene show``):
    per object its types, states, materials and relations, each with where it
    came from (the scene, a catalogue default, an open-world assumption) and,
    where the scene wrote it differently, how it was written."""

    def entry(f: Fact, prov: Provenance) -> dict[str, str]:
        out = {"value": f.object, "from": prov.value}
        written = scene.spelling.get(f)
        if written is not None:
            out["written"] = written.render()
            out["canonical"] = f.render()
        return out

    objects: dict[str, Any] = {}
    for ind in (*scene.order, *sorted(set(scene.objects) - set(scene.order))):
        objects[ind] = {
            "types": sorted(scene.objects[ind]),
            "states": [],
            "materials": [],
            "properties": [],
            "relations": [],
            "data": {},
        }
    value_keys = {"hasState": "states", "hasMaterial": "materials", "hasProperty": "properties"}
    for f, prov in scene.facts.items():
        if f.subject not in objects:
            continue
        obj = objects[f.subject]
        if f.kind is FactKind.DATA:
            obj["data"][f.predicate] = f.object
        elif f.predicate in value_keys:
            obj[value_keys[f.predicate]].append(entry(f, prov))
        elif f.kind is FactKind.OBJECT:
            rel = entry(f, prov)
            rel["relation"] = f.predicate
            obj["relations"].append(rel)
    others = sorted(
        {f.subject for f in scene.facts if f.subject not in objects and f.kind is FactKind.TYPE}
    )
    return {
        "name": scene.name,
        "agent": scene.agent,
        "objects": objects,
        "value_individuals": {
            ind: sorted(f.object for f in scene.facts if f.subject == ind) for ind in others
        },
        "closed_world": sorted(scene.closed_world),
        "unknown_contents": sorted(scene.unknown_contents),
        "unlocated_by_default": scene.unlocated_by_default,
        "referents": dict(scene.referents),
        "open_world_objects": {
            ind: {
                "written": word,
                "proposal": propose(word).describe(),
                "hypotheses": sorted(
                    f.render()
                    for f, p in scene.facts.items()
                    if f.subject == ind and p is Provenance.ASSUMED
                ),
            }
            for ind, word in scene.open_world.items()
        },
        "open_world_markers": sorted(
            f.render()
            for f, p in scene.facts.items()
            if p is Provenance.ASSUMED
            or f.object in ("UnknownMaterial", "UnknownFillState", "UnknownLiquid")
        ),
    }
