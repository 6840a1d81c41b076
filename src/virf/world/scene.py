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

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, Field

from virf.errors import (
    InputError,
    Record,
    Says,
    clip,
    closest,
    hidden_char,
    read_json_file,
)
from virf.names import term_key
from virf.ontology.lexicon import propose
from virf.ontology.tbox import Vocabulary
from virf.schema import Fact, FactKind, Provenance
from virf.world.defaults import (
    apply_default_states,
    apply_material_knowledge,
    assume_controls,
    mark_unknown_contents,
    mark_unknown_fill,
)
from virf.world.open_world import check_open_class, hypothesise
from virf.world.values import (
    VALUE_PROPERTY,
    VALUE_WORDS,
    most_specific,
    near_values,
    value_individuals,
    value_kind,
)

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
CLOSABLE = ("contains", "supports")
DEFAULT_AGENT = "Robot_1"


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
            check_open_class(cname, vocab, strict_vocabulary)
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
    values = value_individuals(classes, vocab, used_as_value)
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
        kind = value_kind(value, classes, vocab)
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
            if value_kind(cls, classes, vocab) is not None and cls in vocab.individuals:
                state_fact(ind, cls, written)  # an object typed OpenState is open
                if vocab.is_a(cls, "Material"):
                    kept.add("Substance")  # typed by its stuff alone: a portion of it
            elif cls in vocab.material_classes:
                state_fact(ind, vocab.material_classes[cls], written)
                kept.add("PhysicalObject")
            else:
                kept.add(cls)
        for cls in sorted(most_specific(kept, vocab)):
            facts[Fact(ind, "type", cls, FactKind.TYPE)] = Provenance.SCENE
        classes[ind] = most_specific(kept, vocab)

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
        near = near_values(value, prop, list(classes), vocab)
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
                if value_kind(target, classes, vocab) is None:
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

    apply_default_states(objects, facts, vocab)
    apply_material_knowledge(objects, facts, vocab)
    mark_unknown_fill(objects, facts, vocab)
    mark_unknown_contents(objects, facts, vocab, frozenset(closed), frozenset(unknown_contents))
    assume_controls(objects, object_order, facts, vocab)
    notes = hypothesise(proposals, open_world, facts, vocab)
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
