"""The one Manchester writer and reader of documents (virf.ontology.manchester):
what the generated kitchen module and a workspace's modules are written with."""

from __future__ import annotations

import pytest

from virf.ontology import manchester
from virf.ontology.tbox import ontology_dir


def test_a_literal_escapes_quotes_and_backslashes() -> None:
    assert manchester.literal('say "hi" \\ bye') == '"say \\"hi\\" \\\\ bye"'


def test_names_of_ours_get_the_empty_prefix_and_others_keep_theirs() -> None:
    assert manchester.term("Pot") == ":Pot"
    assert manchester.term("rdfs:comment") == "rdfs:comment"
    assert manchester.value("hasMaterial", "Metal") == ":hasMaterial value :Metal"
    assert manchester.some("hasMaterial", manchester.value("hasProperty", "Sharp")) == (
        ":hasMaterial some (:hasProperty value :Sharp)"
    )


def test_a_frame_with_annotated_and_plain_axioms() -> None:
    sharp = manchester.Axiom(":hasProperty value :Sharp", (("id", "K-1"), ("kind", "background")))
    text = manchester.frame(
        "Class",
        "Knife",
        manchester.annotations_section([("rdfs:comment", "A knife."), ("catalogue", "X")]),
        manchester.section("SubClassOf", [":Cutlery", sharp]),
    )
    assert text == (
        "Class: :Knife\n"
        "    Annotations:\n"
        '        rdfs:comment "A knife.",\n'
        '        :catalogue "X"\n'
        "    SubClassOf:\n"
        "        :Cutlery,\n"
        '        Annotations: :id "K-1", :kind "background"\n'
        "        :hasProperty value :Sharp"
    )
    assert manchester.frame(
        "Class",
        "Mug",
        manchester.annotations_section([("rdfs:comment", "A mug.")], one_line=True),
        manchester.section("SubClassOf", [":Cup", ":Tableware"], one_line=True),
    ) == ('Class: :Mug\n    Annotations: rdfs:comment "A mug."\n    SubClassOf: :Cup, :Tableware')


def test_an_annotated_axiom_is_never_squeezed_onto_the_keyword_line() -> None:
    with pytest.raises(ValueError, match="line of its own"):
        manchester.section("SubClassOf", [manchester.Axiom(":A", (("id", "x"),))], one_line=True)


def test_a_document_reads_back_its_header() -> None:
    text = manchester.document(
        "http://example.org/m",
        ["http://example.org/a", "http://example.org/b"],
        [("rdfs:label", "M")],
        "Class: :A\n",
    )
    assert text.startswith(manchester.prefixes() + "\nOntology: <http://example.org/m>\n")
    assert manchester.header_of(text, "m.omn") == manchester.Header(
        "http://example.org/m", ("http://example.org/a", "http://example.org/b")
    )
    # A comment among the imports is not one; a line that is neither is named.
    text = "Ontology: <http://x/m>\n# Import: <http://x/c>\n    Import: <http://x/a>\n"
    assert manchester.header_of(text, "m.omn").imports == ("http://x/a",)
    with pytest.raises(ValueError, match=r"m\.omn: cannot read the header line '<http://x/b>'"):
        manchester.header_of(text + "<http://x/b>\n", "m.omn")
    with pytest.raises(ValueError, match=r"m\.omn has no 'Ontology: <IRI>' header"):
        manchester.header_of("Class: :A\n", "m.omn")


def test_every_built_in_scenario_s_imports_are_read() -> None:
    for path in ontology_dir().glob("scenario-*.omn"):
        text = path.read_text(encoding="utf-8")
        declared = [ln for ln in text.splitlines() if ln.strip().startswith("Import:")]
        imports = manchester.header_of(text, path.name).imports
        assert len(imports) == len(declared) > 0, path.name
