"""``virf kb check``: the TBox is consistent and every USC is satisfiable,
checked with the reference reasoner (HermiT).  What the fast engine makes of
the TBox is added by :func:`virf.api.check_knowledge_base`."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path
from typing import Any

from virf.ontology.owlapi import make_reasoner
from virf.ontology.tbox import TBox, Vocabulary, load_tbox


def check_tbox(scenario: str | None = None, kb: str | Path | None = None) -> dict[str, Any]:
    tbox = load_tbox(scenario, kb=kb)
    scenario = tbox.scenario
    owl = tbox.owl  # starts the JVM
    artifact_differs = _artifact_differs(tbox)
    vocab = tbox.vocabulary
    reasoner = make_reasoner("hermit", owl.root)
    try:
        consistent = bool(reasoner.isConsistent())
        unsat = []
        if consistent:
            for name in sorted(vocab.uscs):
                cls = owl.owl_class(name)
                if not reasoner.isSatisfiable(cls):
                    unsat.append(vocab.uscs[name].id)
            unsat_classes = sorted(
                name
                for name in vocab.classes
                if name not in vocab.class_synonyms
                and not reasoner.isSatisfiable(owl.owl_class(name))
            )
        else:
            unsat = sorted(u.id for u in vocab.uscs.values())
            unsat_classes = sorted(vocab.classes)
    finally:
        reasoner.dispose()
    evidence = evidence_shares(vocab)
    by_category: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
    for u in vocab.uscs.values():
        by_category[u.category][u.kind] += 1
    return {
        "scenario": scenario,
        "reasoner": "HermiT 1.4.3 (OWLAPI 5)",
        "consistent": consistent,
        "uscs": len(vocab.uscs),
        "unsatisfiable_uscs": unsat,
        "classes": len(vocab.classes),
        "unsatisfiable_classes": unsat_classes,
        "preconditions": len(vocab.preconditions),
        "background_axioms": len(vocab.background),
        "modules": [
            {
                "name": m.name,
                "label": m.label,
                "imports": list(m.imports),
                "classes": m.classes,
                "object_properties": m.object_properties,
                "data_properties": m.data_properties,
                "individuals": m.individuals,
                "logical_axioms": m.logical_axioms,
                "uscs": m.uscs,
                "usc_by_category": dict(m.usc_by_category),
                "usc_by_kind": dict(m.usc_by_kind),
            }
            for m in tbox.module_stats
        ],
        "usc_by_category": {k: dict(v) for k, v in sorted(by_category.items())},
        "evidence": evidence,
        # What verification reads (the compiled artifact) is what the modules
        # compile to; else the figures above describe modules no verdict uses.
        "artifact_matches_modules": not artifact_differs,
        "artifact_differs_in": artifact_differs,
    }


def _artifact_differs(tbox: TBox) -> list[str]:
    """The parts of the artifact ``tbox`` was loaded from that differ from
    what its modules compile to now (none when it was compiled in this
    process): a built-in artifact edited inside the installed package, or
    one a stale build left behind."""
    if tbox.source == "modules":
        return []
    from virf.ontology.artifact import to_json
    from virf.ontology.compile import compile_kb

    loaded = json.loads(to_json(tbox.compiled))
    built = json.loads(to_json(compile_kb(tbox.owl, tbox.compiled.digest)))
    out = []
    for part in sorted(set(loaded) | set(built)):
        a, b = loaded.get(part), built.get(part)
        if a == b:
            continue
        if isinstance(a, dict) and isinstance(b, dict):
            out += [f"{part}.{k}" for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]
        else:
            out.append(part)
    return out


MODELLING_DECISION = "common-sense modelling decision"


def evidence_of(vocab: Vocabulary, name: str) -> tuple[tuple[str, ...], str | None]:
    """A USC's cited corpus passages and its modelling decision, if any.  A
    workspace's accepted rule states its decision inside ``:source``; a
    built-in rule in ``:modellingDecision``."""
    passages = vocab.annotation(name, "evidence")
    decision = next(iter(vocab.annotation(name, "modellingDecision")), None)
    if decision is None:
        source = vocab.uscs[name].source if name in vocab.uscs else ""
        if MODELLING_DECISION in source:
            decision = source[source.index(MODELLING_DECISION) :]
    return passages, decision


def evidence_shares(vocab: Vocabulary) -> dict[str, Any]:
    """How each USC is justified: by corpus passages, by a stated modelling
    decision, or by neither (a gap ``virf kb check`` reports)."""
    documents: list[str] = []
    decisions: list[str] = []
    neither: list[str] = []
    for name in sorted(vocab.uscs):
        passages, decision = evidence_of(vocab, name)
        (documents if passages else decisions if decision else neither).append(name)
    total = len(vocab.uscs) or 1
    return {
        "documents": len(documents),
        "modelling_decisions": len(decisions),
        "neither": len(neither),
        "share_documents": round(len(documents) / total, 4),
        "share_modelling_decisions": round(len(decisions) / total, 4),
        "without_evidence": neither,
    }
