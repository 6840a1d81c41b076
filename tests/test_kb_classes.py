"""Finding the vocabulary: the unknown-class error that names the nearest
classes by meaning and by spelling."""

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


def test_a_scene_with_an_unknown_class_names_the_neighbours(cli: Cli, tmp_path: Any) -> None:
    scene = tmp_path / "scene.json"
    scene.write_text(
        json.dumps({"instances": [{"class_name": "HairDryer", "instance_name": "Dryer_1"}]}),
        encoding="utf-8",
    )
    plan = tmp_path / "plan.txt"
    plan.write_text("find Dryer_1\n", encoding="utf-8")
    result = cli("verify", scene, plan)
    assert result.exit_code == 2
    (line,) = result.stderr.strip().splitlines()
    assert line.startswith("error: ") and "unknown class 'HairDryer'" in line
    assert "closest by meaning: VacuumCleaner" in line and "by spelling: " in line
