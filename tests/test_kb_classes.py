"""Finding the vocabulary: the classes a scene can use, a search over them by
spelling and meaning, and the unknown-class error that names the nearest."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import pytest
from typer.testing import Result

from virf.errors import InputError
from virf.ontology.suggest import (
    CLASS_KINDS,
    class_kind,
    listed_classes,
    rank_classes,
    suggest_classes,
)
from virf.ontology.tbox import Vocabulary

Cli = Callable[..., Result]


def _classes(cli: Cli, *args: str) -> dict[str, Any]:
    result = cli("kb", "classes", "--json", *args)
    assert result.exit_code == 0, result.output
    document: dict[str, Any] = json.loads(result.stdout)
    return document


def _by_name(document: dict[str, Any]) -> dict[str, dict[str, Any]]:
    return {c["name"]: c for c in document["classes"]}


# -------------------------------------------------------------- the listing
def test_the_table_lists_every_kind(cli: Cli) -> None:
    result = cli("kb", "classes")
    assert result.exit_code == 0, result.output
    out = result.stdout
    assert "Classes in scenario kitchen" in out
    for header in ("class", "kind", "parents", "materials", "affordances", "properties"):
        assert header in out
    for name in ("Microwave", "Child", "HotState (also Hot)", "Metal", "ElectricallyPowered"):
        assert name in out
    assert "typically Ceramic" in out  # the mug's
    assert "UnsafeMicrowaveUsage" not in out  # rules are not for scenes


def test_json_says_what_the_knowledge_base_knows_of_each_class(cli: Cli) -> None:
    document = _classes(cli)
    assert document["scenario"] == "kitchen"
    assert document["search"] is None
    classes = _by_name(document)
    assert {c["kind"] for c in classes.values()} == set(CLASS_KINDS)
    mug = classes["Mug"]
    assert mug["kind"] == "object" and mug["catalogue"] == "AI2-THOR"
    assert "Ceramic" in mug["materials"]["typical"]
    assert "DrinkingVessel" in mug["parents"]
    microwave = classes["Microwave"]
    assert "toggleable" in [a.lower() for a in microwave["affordances"]]
    assert {"Openable", "ContainerReceptacle"} <= set(microwave["affordances"])
    assert "Metal" in microwave["materials"]["always"]
    assert {"ElectricallyPowered", "MicrowaveEmitter"} <= set(microwave["properties"])
    assert "Toaster" in classes and "HeatSource" in classes["Toaster"]["properties"]
    assert "Breakable" in classes["Bowl"]["may_afford"]  # AI2-THOR's plastic bowls do not break
    assert "Metal" in classes["Vase"]["materials"]["possible"]
    # Properties through a material: every pot is metal, and metal conducts.
    assert "Conductive" in classes["Pot"]["properties"]
    child = classes["Child"]
    assert child["kind"] == "agent" and child["parents"] == ["Person"]
    assert classes["HotState"]["synonyms"] == ["Hot"] and "Hot" not in classes
    assert "Conductive" in classes["Metal"]["properties"]
    assert classes["Flammable"]["kind"] == "property"
    for name in ("UnsafeMicrowaveUsage", "Precondition_NothingHeld", "PickAction"):
        assert name not in classes


def test_kind_and_limit(cli: Cli) -> None:
    materials = _classes(cli, "--kind", "material")
    assert materials["kind"] == "material"
    assert {c["kind"] for c in materials["classes"]} == {"material"}
    assert "Metal" in _by_name(materials)
    assert len(_classes(cli, "--limit", "3")["classes"]) == 3


def test_another_scenario(cli: Cli) -> None:
    paper = _by_name(_classes(cli, "--scenario", "paper"))
    household = _by_name(_classes(cli, "--scenario", "household"))
    assert "Microwave" in paper and "Microwave" in household
    assert len(household) >= len(paper)


# -------------------------------------------------------------- search
# Words the catalogue has no class of, each with a class that should be among
# the five nearest and one that should not.
SEARCHES = [
    # an electrical appliance (the vacuum cleaner is ElectricallyPowered)
    ("hair dryer", "VacuumCleaner", "Child"),
    ("toddler", "Child", "Kettle"),
    # the attribute and the objects that heat
    ("space heater", "HeatSourceObject", "Child"),
    ("cardboard", "Box", "Microwave"),
    ("kettle", "Kettle", "Toddler"),
]


@pytest.mark.parametrize(
    ("words", "expected", "unexpected"), SEARCHES, ids=[s[0] for s in SEARCHES]
)
def test_search_by_meaning(cli: Cli, words: str, expected: str, unexpected: str) -> None:
    document = _classes(cli, "--search", words, "--limit", "5")
    assert document["search"] == words
    top = [c["name"] for c in document["classes"]]
    assert len(top) == 5
    assert expected in top, top
    assert unexpected not in top, top
    scores = [c["score"] for c in document["classes"]]
    assert scores == sorted(scores, reverse=True)


def test_search_ranks_an_exact_name_and_a_typo_first(cli: Cli) -> None:
    assert _classes(cli, "--search", "kettle")["classes"][0]["name"] == "Kettle"
    first = _classes(cli, "--search", "Mircowave")["classes"][0]
    assert first["name"] == "Microwave" and first["spelling"] > first["meaning"]


def test_search_hair_dryer_finds_an_electrical_appliance(cli: Cli) -> None:
    top = _classes(cli, "--search", "hair dryer", "--limit", "5")["classes"]
    assert any("ElectricallyPowered" in c["properties"] for c in top), top


def test_search_within_a_kind(cli: Cli) -> None:
    agents = _classes(cli, "--search", "toddler", "--kind", "agent")["classes"]
    assert agents[0]["name"] == "Child"
    assert {c["kind"] for c in agents} == {"agent"}
    objects = [
        c["name"] for c in _classes(cli, "--search", "toddler", "--kind", "object")["classes"]
    ]
    assert "Child" not in objects


def test_search_table_shows_the_score(cli: Cli) -> None:
    result = cli("kb", "classes", "--search", "toddler", "--limit", "3")
    assert result.exit_code == 0, result.output
    assert "nearest 'toddler'" in result.stdout
    assert "score" in result.stdout and "Child" in result.stdout


# -------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--kind", "objects"], "unknown kind 'objects'; closest known: object"),
        (["--scenario", "kitchn"], "unknown scenario 'kitchn'; closest known: kitchen"),
        (["--search", " "], "--search needs words"),
        (["--limit", "0"], "--limit"),
    ],
    ids=["kind", "scenario", "empty-search", "limit"],
)
def test_bad_input_is_one_line(cli: Cli, args: list[str], expected: str) -> None:
    result = cli("kb", "classes", *args)
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("error: ") and expected in lines[0]
    assert "Traceback" not in result.output
    as_json = cli("kb", "classes", "--json", *args)
    assert as_json.exit_code == 2
    assert json.loads(as_json.stdout)["status"] == "BAD_INPUT"


# -------------------------------------------------------------- the unknown-class error
def _unknown(vocab: Vocabulary, name: str) -> str:
    with pytest.raises(InputError) as err:
        vocab.require_class(name)
    return str(err.value)


def test_a_guess_gets_neighbours_by_meaning_and_by_spelling(vocab: Vocabulary) -> None:
    msg = _unknown(vocab, "HairDryer")
    assert "\n" not in msg
    assert msg.startswith("unknown class 'HairDryer'; closest by meaning: ")
    meaning = msg.split("closest by meaning: ", 1)[1].split(";", 1)[0].split(", ")
    spelling = msg.split("by spelling: ", 1)[1].split(";", 1)[0].split(", ")
    # A hair dryer is an electrical appliance; the vocabulary's nearest one by
    # meaning is the vacuum cleaner.  Spelling alone finds only look-alikes.
    assert "VacuumCleaner" in meaning
    assert vocab.is_a("VacuumCleaner", "ElectricalDevice")
    assert "Chair" in spelling and "VacuumCleaner" not in spelling
    assert msg.endswith("`virf kb classes --search 'hair dryer'` lists more")


def test_a_guess_at_a_person(vocab: Vocabulary) -> None:
    msg = _unknown(vocab, "Toddler")
    assert "closest by meaning: Child" in msg


def test_a_typo_is_still_found_by_spelling(vocab: Vocabulary) -> None:
    msg = _unknown(vocab, "Mircowave")
    assert "by spelling: Microwave" in msg
    # Meaning neighbours of a typo are noise below the floor, not suggestions.
    assert "DishSponge" not in msg


def test_a_term_without_words_gets_no_meaning_neighbours(vocab: Vocabulary) -> None:
    msg = _unknown(vocab, "_1")
    assert "by meaning" not in msg
    assert "`virf kb classes --search WORDS` lists more" in msg


def test_the_error_without_the_embedding_model(
    vocab: Vocabulary, monkeypatch: pytest.MonkeyPatch
) -> None:
    # No model installed: the error is still the same input error, with the
    # spelling neighbours alone.
    from virf.errors import EnvironmentProblem
    from virf.ontology import suggest

    def missing(*args: object, **kwargs: object) -> None:
        raise EnvironmentProblem("the sentence-embedding model is not installed")

    monkeypatch.setattr(suggest, "rank_classes", missing)
    msg = _unknown(vocab, "Toastr")
    assert msg.startswith("unknown class 'Toastr'; closest by spelling: Toaster")
    assert suggest_classes("Toastr", vocab)[0] == "Toaster"


def test_known_names_resolve_without_the_embedder(vocab: Vocabulary) -> None:
    from virf.ontology import suggest

    suggest._class_vectors.cache_clear()
    assert vocab.require_class("microwave") == "Microwave"
    assert vocab.require_class("Hot") == "HotState"
    assert suggest._class_vectors.cache_info().misses == 0


def test_suggest_classes_ranks_spelling_and_meaning_together(vocab: Vocabulary) -> None:
    assert suggest_classes("Mircowave", vocab)[0] == "Microwave"
    assert suggest_classes("toddler", vocab, n=1) == ("Child",)
    assert suggest_classes("toddler", vocab, n=1, kind="object") != ("Child",)
    with pytest.raises(InputError, match="unknown kind 'objects'; closest known: object"):
        suggest_classes("toddler", vocab, kind="objects")


def test_kinds(vocab: Vocabulary) -> None:
    assert class_kind(vocab, "Mug") == "object"
    assert class_kind(vocab, "Child") == "agent"
    assert class_kind(vocab, "OnState") == "state"
    assert class_kind(vocab, "Metal") == "material"
    assert class_kind(vocab, "ElectricallyPowered") == "property"
    # Rules, preconditions, actions and synonyms are not for scenes.
    for name in ("UnsafeMicrowaveUsage", "Precondition_NothingHeld", "PickAction", "Hot"):
        assert class_kind(vocab, name) is None, name
    every = listed_classes(vocab)
    assert set(every) == {c for k in CLASS_KINDS for c in listed_classes(vocab, k)}
    assert "ChildNearPoisonDanger" not in every  # a rule, though it is about a Child
    ranked = rank_classes("toddler", vocab, "agent")
    assert {r.kind for r in ranked} == {"agent"}
