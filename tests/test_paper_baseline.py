"""The paper's owlready2 + Pellet baseline: TBox export, job checks, and (opt-in) a real run.

The real run needs ``.venv-paper`` (owlready2 0.49 from PyPI) and starts one
JVM per snapshot, so it only runs with ``VIRF_PAPER_BASELINE=1``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from virf.api import LogicTutor
from virf.bench import paper_baseline
from virf.bench.paper import (
    INDIVIDUAL_NS,
    OVER_LIMIT,
    ensure_paper_env,
    export_tbox,
    fact_json,
    run_paper_baseline,
)
from virf.ontology.iri import NS
from virf.schema import Fact, FactKind

ROOT = Path(__file__).resolve().parent.parent


def test_export_tbox_is_one_rdfxml_ontology_with_every_logical_axiom(
    paper_tutor: LogicTutor, tmp_path: Path
) -> None:
    # The paper's rules (scenario paper), which the paper's baseline reasons with.
    tutor = paper_tutor
    path = tmp_path / "tbox.owl"
    written = export_tbox(tutor.tbox, path)  # starts the JVM the imports below need
    from java.io import File
    from java.util import HashSet
    from org.semanticweb.owlapi.apibinding import OWLManager
    from org.semanticweb.owlapi.formats import RDFXMLDocumentFormat

    expected = HashSet()
    for ax in tutor.tbox.owl.logical_axioms():
        expected.add(ax.getAxiomWithoutAnnotations())
    assert written == expected.size() > 0

    manager = OWLManager.createOWLOntologyManager()
    loaded = manager.loadOntologyFromOntologyDocument(File(str(path)))
    assert isinstance(manager.getOntologyFormat(loaded), RDFXMLDocumentFormat)
    assert loaded.getImportsDeclarations().isEmpty()
    assert loaded.getLogicalAxiomCount() == written
    classes = {str(c.getIRI().toString()) for c in loaded.getClassesInSignature()}
    assert NS + "FridgeLeftOpenDanger" in classes
    # Punned individuals moved out of the class namespace, classes stayed.
    individuals = {str(i.getIRI().toString()) for i in loaded.getIndividualsInSignature()}
    assert INDIVIDUAL_NS + "Metal" in individuals
    assert NS + "Metal" in classes
    assert not any(i.startswith(NS) for i in individuals)


def test_fact_json_spells_closures_with_members() -> None:
    closure = Fact.closure("Fridge_1", "contains", ["Apple_1", "Egg_1"])
    assert fact_json(closure) == {
        "s": "Fridge_1",
        "p": "contains",
        "o": "Apple_1,Egg_1",
        "kind": "closure",
        "members": ["Apple_1", "Egg_1"],
    }
    assert fact_json(Fact("Fridge_1", "isLocated", "true", FactKind.DATA))["kind"] == "data"


@pytest.mark.parametrize(
    ("job", "message"),
    [
        ("[1]", "job must be a JSON object"),
        ('{"tbox": "/no/such.owl", "namespace": "x"}', "TBox file not found"),
        ("{bad", "is not JSON"),
    ],
)
def test_script_rejects_bad_jobs_in_one_line(
    job: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "job.json"
    path.write_text(job, encoding="utf-8")
    assert paper_baseline.main([str(path), str(tmp_path / "out.json")]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_script_rejects_a_bad_fact(tmp_path: Path) -> None:
    tbox = tmp_path / "tbox.owl"
    tbox.write_text("", encoding="utf-8")
    job = {
        "tbox": str(tbox),
        "namespace": NS,
        "concepts": [],
        "plans": [{"id": "p", "snapshots": [[{"s": "A", "p": "q", "o": "x", "kind": "data"}]]}],
    }
    path = tmp_path / "job.json"
    path.write_text(json.dumps(job), encoding="utf-8")
    with pytest.raises(paper_baseline.JobError, match=r"snapshots\[0\]\[0\].*'true' or 'false'"):
        paper_baseline.load_job(path)


def test_the_script_says_where_it_is_in_events(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Before each reasoner call the script says so, and after it what it
    found: the caller stops a call past its limit from these.  (A stand-in
    module: owlready2 itself lives only in .venv-paper; its World fails, as
    a Java error would.)"""
    import io
    import sys
    import types

    owl = types.ModuleType("owlready2")
    owl.VERSION = "stand-in"  # type: ignore[attr-defined]
    owl.JAVA_EXE = "java-that-is-not-there"  # type: ignore[attr-defined]

    class World:
        def get_ontology(self, iri: str) -> None:
            raise RuntimeError("no JVM here\n  at some.Frame")

        def close(self) -> None:
            pass

    owl.World = World  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "owlready2", owl)
    tbox = tmp_path / "tbox.owl"
    tbox.write_text("", encoding="utf-8")
    fact = {"s": "A", "p": "type", "o": "Fridge", "kind": "type"}
    job = {
        "tbox": str(tbox),
        "namespace": NS,
        "concepts": [],
        "plans": [{"id": "p", "snapshots": [[fact], [fact]]}],
    }
    path = tmp_path / "job.json"
    path.write_text(json.dumps(job), encoding="utf-8")
    events = io.StringIO()
    assert paper_baseline.main([str(path), str(tmp_path / "out.json")], events) == 0
    said = [json.loads(line) for line in events.getvalue().splitlines()]
    assert [(e["event"], e.get("step")) for e in said] == [
        ("ready", None),
        ("call", 0),
        ("step", 0),
        ("call", 1),
        ("step", 1),
        ("end", None),
    ]
    assert said[0]["owlready2"] == "stand-in"
    assert said[2]["plan"] == 0 and said[2]["consistent"] is None
    assert said[2]["findings"] == {"error": "RuntimeError: no JVM here"}
    out = json.loads((tmp_path / "out.json").read_text(encoding="utf-8"))
    assert out["plans"][0]["findings"] == [said[2]["findings"], said[4]["findings"]]


def test_a_plan_with_a_failed_call_has_no_time() -> None:
    from virf.bench.latency import _paper_plan_ms

    finding = [{"concept": "C", "individual": "x"}]
    ok = {"step_ms": [10.0, 20.0, 30.0], "findings": [[], finding, []], "consistent": [True] * 3}
    assert _paper_plan_ms(ok) == (30.0, True)  # the paper's loop stops at its first finding
    failed = {
        "step_ms": [10.0, 900.0],
        "findings": [[], {"error": "OwlReadyJavaError: java.lang.OutOfMemoryError"}],
        "consistent": [True, None],
    }
    assert _paper_plan_ms(failed) is None


def test_a_plan_with_a_call_over_the_limit_is_a_lower_bound() -> None:
    from virf.bench.latency import _paper_plan_ms

    over = {
        "step_ms": [10.0, 60000.0],
        "findings": [[], {"error": OVER_LIMIT}],
        "consistent": [True, None],
    }
    assert _paper_plan_ms(over) == (60010.0, False)
    # A finding before the call stopped ends the paper's loop: the time is exact.
    finding = [{"concept": "C", "individual": "x"}]
    found_first = {
        "step_ms": [10.0, 20.0, 60000.0],
        "findings": [[], finding, {"error": OVER_LIMIT}],
        "consistent": [True, True, None],
    }
    assert _paper_plan_ms(found_first) == (30.0, True)


@pytest.mark.skipif(
    os.environ.get("VIRF_PAPER_BASELINE") != "1",
    reason="needs .venv-paper (owlready2 0.49 from PyPI) and a JVM per snapshot; "
    "set VIRF_PAPER_BASELINE=1",
)
def test_paper_baseline_finds_what_our_engine_finds(
    paper_tutor: LogicTutor, tmp_path: Path
) -> None:
    tutor = paper_tutor  # FridgeLeftOpenDanger is one of the paper's rules
    python = ensure_paper_env(ROOT)

    def fridge(state: str) -> list[Fact]:
        return [
            Fact("Fridge_1", "type", "Fridge", FactKind.TYPE),
            Fact("Fridge_1", "hasState", state),
            Fact("Fridge_1", "isLocated", "true", FactKind.DATA),
            Fact.closure("Fridge_1", "contains", []),
        ]

    snapshots = [fridge("OpenState"), fridge("ClosedState")]
    concepts = ["FridgeLeftOpenDanger"]
    out = run_paper_baseline(tutor.tbox, [("fridge", snapshots)], concepts, tmp_path, python)

    assert out["owlready2"] == "0.49"
    plan = out["plans"][0]
    assert plan["consistent"] == [True, True]
    assert plan["findings"] == [[{"concept": "FridgeLeftOpenDanger", "individual": "Fridge_1"}], []]
    assert len(plan["step_ms"]) == 2 and plan["total_ms"] > 0
    for snapshot, found in zip(snapshots, plan["findings"], strict=True):
        ours = tutor.engine.classify(snapshot, concepts)
        assert {(c, i) for c, inds in ours.instances.items() for i in inds} == {
            (f["concept"], f["individual"]) for f in found
        }
