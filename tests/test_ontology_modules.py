"""The OWL modules as a knowledge engineer opens them: every annotation
property declared once, in the core."""

from __future__ import annotations

import re
from functools import cache
from pathlib import Path
from typing import Any

from virf.ontology.iri import MODULE_BASE, short
from virf.ontology.tbox import ontology_dir

CORE = MODULE_BASE + "core"
_DECLARED = re.compile(r"^AnnotationProperty:\s*(\S+)", re.MULTILINE)
_IMPORT = re.compile(r"^\s*Import:\s*<([^>]+)>", re.MULTILINE)


def _modules() -> list[Path]:
    return sorted(ontology_dir().glob("*.omn"))


@cache
def _loaded() -> dict[str, Any]:
    """Every module as OWLAPI parses it, by ontology IRI, each file mapped
    from the IRI its name gives (as the loader of the scenarios maps them)."""
    from virf.ontology.jvm import ensure_jvm

    ensure_jvm()
    from java.io import File
    from org.semanticweb.owlapi.apibinding import OWLManager
    from org.semanticweb.owlapi.model import IRI
    from org.semanticweb.owlapi.util import SimpleIRIMapper

    manager = OWLManager.createOWLOntologyManager()
    for path in _modules():
        manager.getIRIMappers().add(
            SimpleIRIMapper(IRI.create(MODULE_BASE + path.stem), IRI.create(File(str(path))))
        )
    for path in _modules():
        manager.loadOntology(IRI.create(MODULE_BASE + path.stem))
    return {
        str(ont.getOntologyID().getOntologyIRI().get().toString()): ont
        for ont in manager.getOntologies()
    }


def test_annotation_properties_are_declared_once_in_the_core() -> None:
    texts = {p.stem: p.read_text(encoding="utf-8") for p in _modules()}
    in_core = set(_DECLARED.findall(texts["core"]))
    for name, text in texts.items():
        if name == "core" or CORE not in _IMPORT.findall(text):
            # A module that reaches the core only through another one must
            # declare what it uses: OWLAPI's Manchester parser reads the
            # declarations of directly imported modules only.
            continue
        again = _DECLARED.findall(text)
        assert not again, f"{name}.omn declares {', '.join(again)} again (core.omn does)"
    used: set[str] = set()
    for ont in _loaded().values():
        used |= {
            short(str(p.getIRI().toString())) for p in ont.getAnnotationPropertiesInSignature()
        }
    # ":id" and "rdfs:label" as the short names OWLAPI's IRIs shorten to
    declared = {p.split(":", 1)[1] for p in in_core}
    assert used <= declared, f"not declared in core.omn: {sorted(used - declared)}"
