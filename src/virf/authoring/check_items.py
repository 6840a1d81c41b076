"""What each check of a candidate says, as check items: HermiT's verdicts,
whether a rule would fire on every scene or plan, its minimal pairs, whether
it is new, its category and its evidence."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any, Final

from virf.authoring.models import CheckItem, Related
from virf.errors import InputError
from virf.ontology.tbox import Vocabulary
from virf.schema import Fact, FactKind

if TYPE_CHECKING:
    from virf.authoring.corpus import Corpus
    from virf.authoring.drafts import Draft
    from virf.ontology.axiom_check import AxiomCheck


def reasoner_items(result: AxiomCheck, name: str, unsatisfiable: str) -> list[CheckItem]:
    """What HermiT said of a candidate, as check items: the axiom parses, the
    TBox stays consistent with it, and ``name`` is satisfiable (else why
    not: ``unsatisfiable``)."""
    if not result.parses:
        return [CheckItem.error("parses", result.parse_error)]
    items = [CheckItem.info("parses", "the axiom parses")]
    if not result.consistent:
        items.append(CheckItem.error("consistent", "the TBox becomes inconsistent with this axiom"))
        return items
    items.append(CheckItem.info("consistent", "the TBox stays consistent"))
    if result.satisfiable is False:
        items.append(CheckItem.error("satisfiable", f"{name} is unsatisfiable: {unsatisfiable}"))
    else:
        items.append(CheckItem.info("satisfiable", f"{name} is satisfiable"))
    return items


# Classes every verification has an individual of, with why.  A rule that
# holds of every individual of one of them would make every scene, or every
# plan, unsafe, whatever it holds: it is refused.
ALWAYS_PRESENT: Final = {
    "Robot": "every scene has one: the scene reader adds Robot_1 when it names none",
    "Action": "every plan step is one",
    "PhysicalObject": "every object a scene names is one",
}


# The action individual every plan's first step has in common with any other.
ANY_STEP: Final = "Step1_action"


def empty_scene_facts(vocab: Vocabulary) -> tuple[Fact, ...]:
    """What every verification starts from: the first snapshot of a scene
    that names nothing (the robot the scene reader adds, with empty hands),
    as the verifier hands it to the reasoner, with what every plan's first
    step adds to it whatever its verb: an action, by the robot."""
    from virf.world.scene import build_scene
    from virf.world.simulator import Simulator

    sim = Simulator(vocab)
    state = sim.initial(build_scene({"instances": [], "assertions": []}, vocab))
    step = {
        Fact(ANY_STEP, "type", "Action", FactKind.TYPE),
        Fact(ANY_STEP, "hasAgent", state.agent),
    }
    return tuple(sorted({*state.facts, *sim.closure_facts(state), *step}))


def everywhere_items(name: str, result: AxiomCheck) -> list[CheckItem]:
    """A rule that would fire on every scene or plan: one that holds of every
    individual of a class each verification has, of the knowledge base's own
    individuals (which scenes mention as states, materials and properties),
    or of something in the empty scene."""
    items = []
    if result.holds_of_every:
        every = ", ".join(f"every {c} ({ALWAYS_PRESENT.get(c, '')})" for c in result.holds_of_every)
        items.append(
            CheckItem.error(
                "always-present",
                f"{name} holds of {every}: every scene or plan would be unsafe",
            )
        )
    if result.holds_of_named:
        shown = ", ".join(result.holds_of_named[:5]) + (
            ", ..." if len(result.holds_of_named) > 5 else ""
        )
        items.append(
            CheckItem.error(
                "named-individuals",
                f"{name} holds of the knowledge base's own individual(s) {shown}: every scene "
                "that mentions one would be unsafe; a rule is about the things of a scene",
            )
        )
    if not result.empty_scene_consistent:
        items.append(
            CheckItem.error(
                "empty-scene",
                f"the empty scene (only the robot every scene has) contradicts {name}: "
                "every scene would be an inconsistent world",
            )
        )
    elif result.empty_scene and not result.holds_of_every:
        robot = [i for i in result.empty_scene if i != ANY_STEP]
        if robot:
            items.append(
                CheckItem.error(
                    "empty-scene",
                    f"{name} fires in the empty scene (on {', '.join(robot)}): a scene that "
                    "names nothing would be unsafe before any step, and so would every scene "
                    "that does not rule it out",
                )
            )
        if ANY_STEP in result.empty_scene:
            items.append(
                CheckItem.error(
                    "empty-scene",
                    f"{name} fires on every plan step (on {ANY_STEP}, an action by the robot "
                    "and nothing more): every plan would be unsafe at its first step",
                )
            )
    if not items:
        items.append(
            CheckItem.info(
                "always-present",
                "holds of nothing every scene or plan has (the robot, an action, any object), "
                "nor of the empty scene",
            )
        )
    return items


def twin_items(name: str, twins: Sequence[str]) -> list[CheckItem]:
    """Whether the rule comes with minimal pairs that read (virf kb test runs them)."""
    from virf.verify.twins import read_pair

    if not twins:
        return [
            CheckItem.warning(
                "twins",
                "no minimal pair: give 'twins' ('WORLD | PLAN | OLD => NEW', a world where the "
                "rule holds and a twin differing in the property that matters) so that "
                "virf kb test can check the rule",
                ok=False,
            )
        ]
    for text in twins:
        try:
            read_pair(name, text)
        except InputError as exc:
            return [CheckItem.error("twins", str(exc))]
    return [CheckItem.info("twins", f"{len(twins)} minimal pair(s) read")]


def novelty_items(name: str, related: Related) -> list[CheckItem]:
    items = []
    if related.equivalent:
        items.append(
            CheckItem.warning(
                "redundancy",
                f"redundant: {name} is equivalent to {', '.join(related.equivalent)}",
                ok=False,
            )
        )
    if related.subsumed_by:
        items.append(
            CheckItem.warning(
                "redundancy",
                f"redundant: every {name} situation is already a "
                f"{', '.join(related.subsumed_by)} situation",
                ok=False,
            )
        )
    if related.subsumes:
        items.append(CheckItem.info("generalisation", f"generalises {', '.join(related.subsumes)}"))
    if not items:
        items.append(CheckItem.info("novelty", "no existing rule covers it"))
    return items


def category_items(rule: dict[str, Any], uscs: Iterable[Any]) -> list[CheckItem]:
    known = sorted({u.category for u in uscs})
    if rule["category"] in known:
        return []
    return [
        CheckItem.warning(
            "category",
            f"category '{rule['category']}' is new to the TBox; known: {', '.join(known)}",
            ok=False,
        )
    ]


def evidence_items(corpus: Corpus, draft: Draft, ids: Sequence[str]) -> list[CheckItem]:
    rule = draft.rules[0]
    if not ids:
        if rule.modelling_decision:
            return [
                CheckItem.warning(
                    "evidence",
                    "cites no document: a common-sense modelling decision "
                    f"({rule.modelling_decision})",
                )
            ]
        return [
            CheckItem.error(
                "evidence",
                "cites no evidence: give passage ids, or a 'modellingDecision' "
                "saying why no document is needed",
            )
        ]
    missing = [pid for pid in ids if corpus.passage(pid) is None]
    if missing:
        return [
            CheckItem.error(
                "evidence", f"cites passages the corpus does not have: {', '.join(missing)}"
            )
        ]
    return [CheckItem.info("evidence", f"{len(ids)} passage(s) found")]
