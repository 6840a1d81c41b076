"""The OWL modules as a knowledge engineer opens them in Protégé: the catalog
beside them resolves every import to the local file, and every annotation
property is declared once, in the core."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from functools import cache
from pathlib import Path
from typing import Any

import pytest

from virf.ontology.catalog import catalog_path, module_headers, render_catalog
from virf.ontology.iri import MODULE_BASE, short
from virf.ontology.tbox import ontology_dir

CORE = MODULE_BASE + "core"
CATALOG_NS = "urn:oasis:names:tc:entity:xmlns:xml:catalog"
XML_BASE = "{http://www.w3.org/XML/1998/namespace}base"
_DECLARED = re.compile(r"^AnnotationProperty:\s*(\S+)", re.MULTILINE)
_IMPORT = re.compile(r"^\s*Import:\s*<([^>]+)>", re.MULTILINE)


def _modules() -> list[Path]:
    return sorted(ontology_dir().glob("*.omn"))


def _catalog_entries() -> dict[str, Path]:
    """The catalog as an XML catalog reader sees it: IRI -> file."""
    root = ET.parse(catalog_path()).getroot()
    assert root.tag == f"{{{CATALOG_NS}}}catalog"
    for group in root.iter(f"{{{CATALOG_NS}}}group"):
        # A base would move the files the entries name; Protégé writes "".
        assert group.get(XML_BASE, "") == ""
    out: dict[str, Path] = {}
    for entry in root.iter(f"{{{CATALOG_NS}}}uri"):
        name, uri = entry.get("name"), entry.get("uri")
        assert name and uri, ET.tostring(entry, encoding="unicode")
        assert name not in out, f"the catalog maps <{name}> twice"
        out[name] = catalog_path().parent / uri  # relative to the catalog
    return out


def _document(path: Path) -> str:
    from java.io import File
    from org.semanticweb.owlapi.model import IRI

    return str(IRI.create(File(str(path.resolve()))).toString())


@cache
def _opened() -> tuple[Any, dict[str, Any]]:
    """Every module opened from its file as Protégé opens it: with an OWLAPI
    manager that knows no IRI but those the catalog maps."""
    entries = _catalog_entries()
    for path in _modules():
        for iri in _IMPORT.findall(path.read_text(encoding="utf-8")):
            # Checked before OWLAPI looks: it would fetch an unmapped IRI from the web.
            assert iri in entries, f"{path.name} imports <{iri}>, which the catalog lacks"
    from virf.ontology.jvm import ensure_jvm

    ensure_jvm()
    from java.io import File
    from org.semanticweb.owlapi.apibinding import OWLManager
    from org.semanticweb.owlapi.model import IRI
    from org.semanticweb.owlapi.util import SimpleIRIMapper

    manager = OWLManager.createOWLOntologyManager()
    for name, path in entries.items():
        manager.getIRIMappers().add(SimpleIRIMapper(IRI.create(name), IRI.create(File(str(path)))))
    by_file: dict[str, Any] = {}
    for path in _modules():
        # A module another one imported is open already, from its file.
        opened = [
            o
            for o in manager.getOntologies()
            if str(manager.getOntologyDocumentIRI(o).toString()) == _document(path)
        ]
        by_file[path.name] = (
            opened[0] if opened else manager.loadOntologyFromOntologyDocument(File(str(path)))
        )
    return manager, by_file


def _iri(ontology: Any) -> str:
    return str(ontology.getOntologyID().getOntologyIRI().get().toString())


def test_the_committed_catalog_is_what_make_kb_writes() -> None:
    committed = catalog_path().read_text(encoding="utf-8")
    assert committed == render_catalog(), "run 'make kb' and commit catalog-v001.xml"


def test_every_import_of_every_module_resolves_through_the_catalog() -> None:
    entries = _catalog_entries()
    assert sorted(p.resolve() for p in entries.values()) == [p.resolve() for p in _modules()], (
        "the catalog names every module, and only modules"
    )
    manager, by_file = _opened()
    for name, path in entries.items():
        assert _iri(by_file[path.name]) == name, f"{path.name} is not the ontology <{name}>"
    imports = 0
    for file, ontology in by_file.items():
        for decl in ontology.getImportsDeclarations():
            iri = str(decl.getIRI().toString())
            target = entries[iri]
            assert target.is_file(), f"{file} imports <{iri}>: {target} is missing"
            imported = manager.getImportedOntology(decl)
            assert imported is not None, f"{file}: <{iri}> did not resolve"
            assert _iri(imported) == iri, (
                f"{file} imports <{iri}>, {target.name} is {_iri(imported)}"
            )
            assert str(manager.getOntologyDocumentIRI(imported).toString()) == _document(target)
            imports += 1
    assert imports >= len(by_file) - 1  # every module but the core imports something


def test_the_catalog_names_a_module_that_does_not_resolve(tmp_path: Path) -> None:
    header = "Prefix: : <http://virf.dev/ontology#>\n\nOntology: <{}>\n{}\n"
    (tmp_path / "core.omn").write_text(header.format(CORE, '    Annotations: rdfs:label "c"'))
    (tmp_path / "rules.omn").write_text(
        header.format(MODULE_BASE + "rules", f"    Import: <{MODULE_BASE}coer>\nClass: :A")
    )
    with pytest.raises(ValueError, match=r"rules.omn imports <.*coer>.*closest: <.*/core>"):
        module_headers(tmp_path)
    (tmp_path / "rules.omn").write_text(header.format(CORE, "Class: :A"))
    with pytest.raises(ValueError, match=r"core\.omn and rules\.omn both claim"):
        module_headers(tmp_path)
    (tmp_path / "rules.omn").write_text(header.format(MODULE_BASE + "rules", f"Import: <{CORE}>"))
    [core, rules] = module_headers(tmp_path)
    assert (rules.file, rules.iri, rules.imports) == ("rules.omn", MODULE_BASE + "rules", (CORE,))
    assert core.imports == ()


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
    for ontology in _opened()[1].values():
        used |= {
            short(str(p.getIRI().toString())) for p in ontology.getAnnotationPropertiesInSignature()
        }
    # ":id" and "rdfs:label" as the short names OWLAPI's IRIs shorten to
    declared = {p.split(":", 1)[1] for p in in_core}
    assert used <= declared, f"not declared in core.omn: {sorted(used - declared)}"
