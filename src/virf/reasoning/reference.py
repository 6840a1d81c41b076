"""Reference engines: complete OWL 2 DL reasoners (HermiT, Openllet/Pellet)
running in-process through OWLAPI 5.

The Java side lives in :mod:`virf.ontology.owlapi`; this module only puts it
behind the engine interface.  Building one starts the JVM and loads the
ontology modules, which the fast engine does not need until it falls back.
"""

from __future__ import annotations

from virf.ontology.owlapi import ReasonerSession
from virf.ontology.tbox import TBox
from virf.reasoning import Classification, Engine
from virf.schema import Fact


class OwlapiEngine(Engine):
    complete = True
    name = "owlapi"
    reasoner = "hermit"

    def __init__(self, tbox: TBox, timeout_s: float = 30.0) -> None:
        super().__init__(tbox, timeout_s)
        self.session = ReasonerSession(tbox.owl, self.reasoner, timeout_s)

    def _classify(self, facts: list[Fact], concepts: list[str]) -> Classification:
        consistent, found = self.session.classify(facts, concepts)
        return Classification(consistent, found)

    def _entails(
        self, facts: list[Fact], concept: str, individual: str, without: frozenset[str]
    ) -> bool:
        return self.session.entails(facts, concept, individual, without)

    def _consistent(self, facts: list[Fact], without: frozenset[str]) -> bool:
        return self.session.consistent(facts, without)


class HermitEngine(OwlapiEngine):
    """HermiT 1.4 (hypertableau), the default reference engine."""

    name = "hermit"
    reasoner = "hermit"


class PelletEngine(OwlapiEngine):
    """Openllet 2.6 (the maintained fork of Pellet, the paper's reasoner)."""

    name = "pellet"
    reasoner = "pellet"
