"""The ontology's namespaces and the one function that shortens an IRI.

Everything past the Java bridge speaks short names (``Pot``, ``hasMaterial``,
``owl:Thing``); this is where full IRIs become them.
"""

from __future__ import annotations

from typing import Any

NS = "http://virf.dev/ontology#"
MODULE_BASE = "http://virf.dev/ontology/"
OWL = "http://www.w3.org/2002/07/owl#"
THING = "owl:Thing"
NOTHING = "owl:Nothing"


def short(iri: str) -> str:
    """``NS#Pot`` -> ``Pot``; OWL's own terms keep an ``owl:`` prefix (they
    are not ours to reuse); any other IRI -> its last segment (``rdfs:label``
    -> ``label``, a module IRI -> the module's name)."""
    text = iri[1:-1] if iri.startswith("<") and iri.endswith(">") else iri
    if text.startswith(NS):
        return text[len(NS) :]
    if text.startswith(OWL):
        return "owl:" + text[len(OWL) :]
    if "#" in text:
        return text.rsplit("#", 1)[1]
    return text.rsplit("/", 1)[-1]


def iri_short(iri: Any) -> str:
    """A Java ``IRI`` (anything with ``toString()``) as its short name."""
    return short(str(iri.toString()))
