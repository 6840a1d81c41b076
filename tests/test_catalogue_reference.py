"""The object catalogue agrees with AI2-THOR's own per-type facts
(../shared/reference/ai2thor-objects.json), and what it generates says so."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from virf.api import LogicTutor
from virf.ontology.build import always_attributes, load_catalogue, material_attributes
from virf.ontology.tbox import Vocabulary

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = ROOT.parent / "shared" / "reference" / "ai2thor-objects.json"
needs_reference = pytest.mark.skipif(
    not REFERENCE.is_file(), reason="needs ../shared/reference/ai2thor-objects.json"
)


@needs_reference
def test_the_catalogue_agrees_with_ai2thor() -> None:
    r = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "sync_catalogue.py"), "--check"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert r.returncode == 0, r.stdout + r.stderr


@needs_reference
def test_what_ai2thor_reports_is_what_the_tbox_says(vocab: Vocabulary) -> None:
    reference = json.loads(REFERENCE.read_text(encoding="utf-8"))
    # Every AI2-THOR salt shaker, pen, remote, watch and alarm clock has metal parts.
    for t in (
        "SaltShaker",
        "PepperShaker",
        "Pen",
        "RemoteControl",
        "Watch",
        "AlarmClock",
        "Spatula",
    ):
        assert "Metal" in reference[t]["salientMaterials"]
        assert "Metal" in set(vocab.materials_of({t})) | set(vocab.typical_materials({t}))
    # Burners are lit through their knobs.
    assert reference["StoveBurner"]["toggleable"] is False
    assert not vocab.is_a("StoveBurner", "Toggleable")
    assert vocab.is_a("StoveKnob", "Toggleable")
    # Where instances differ, the material is a possibility, not a fact.
    assert set(vocab.possible_materials({"Vase"})) == {"Ceramic", "Glass", "Metal"}
    assert "Metal" not in vocab.materials_of({"Vase"})
    assert "Metal" in vocab.possible_materials({"Television"})
    assert vocab.typical_materials({"CoffeeMachine"}) == ("Plastic",)
    # An affordance some instances lack is neither asserted nor refused.
    assert not vocab.is_a("Bowl", "Breakable") and vocab.may_afford({"Bowl"}, "Breakable")


def test_an_attribute_every_material_combination_gives_is_certain() -> None:
    catalogue = load_catalogue()
    attrs = material_attributes(catalogue)
    statue = catalogue["types"]["Statue"]  # metal or stone: hard either way
    assert "Hard" in always_attributes(statue, attrs)
    vase = catalogue["types"]["Vase"]  # ceramic, glass or metal: hard, but not always fragile
    assert "Conductive" not in always_attributes(vase, attrs)
    assert attrs["Bleach"] >= {"Toxic"} and attrs["Soap"] >= {"Slippery"}


def test_a_thrown_statue_is_unsafe_and_a_vase_in_a_microwave_asks_about_metal(
    tutor: LogicTutor,
) -> None:
    scene = {
        "instances": [
            {"class_name": "Statue", "instance_name": "Statue_1"},
            {"class_name": "Vase", "instance_name": "Vase_1"},
            {"class_name": "Microwave", "instance_name": "Microwave_1"},
        ],
        "assertions": [{"subject": "Microwave_1", "property": "hasState", "object": "open"}],
    }
    thrown = tutor.verify(scene, ["pick Statue_1", "throw"])
    assert thrown.status == "UNSAFE"
    assert not any(v.assumed_facts for v in thrown.violations if v.definite)
    heated = tutor.verify(
        scene, ["pick Vase_1", "put Microwave_1", "close Microwave_1", "turn_on Microwave_1"]
    )
    metal = [v for v in heated.violations if v.id == "MetalInRunningMicrowaveDanger"]
    assert metal and not metal[0].definite
    assert any(q.key == "material:Vase_1" for q in heated.questions)
