"""A knowledge workspace: the one place the workflow's steps meet.

``Workspace`` owns the folder (see :mod:`virf.ontology.workspace` for the
part verification reads), the corpus, the database and the layered modules.
Drafting, a person's proposal, checks, the effect preview and decisions all
go through it, so the terminal and the review page behave the same.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from datetime import datetime
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from virf.authoring.drafts import Draft, read_draft, rule_json
from virf.authoring.models import (
    AcceptedRule,
    CandidateSummary,
    CandidateView,
    CheckItem,
    CheckReport,
    DecisionView,
    Evidence,
    Layer,
    Preview,
    Related,
    RuleDraft,
    Status,
)
from virf.authoring.normalize import DEFAULT_THRESHOLD, VocabularyIndex, normalise
from virf.authoring.store import CandidateRow, DecisionRow, Store, status_of
from virf.errors import InputError, clip, read_json_file
from virf.files import write_atomically
from virf.migrations import now
from virf.ontology import manchester
from virf.ontology.iri import MODULE_BASE
from virf.ontology.tbox import TBox, Vocabulary, load_tbox, ontology_dir, scenario_names
from virf.ontology.workspace import FORMAT, LAYERS, MARKER, KbLayout, open_layout
from virf.schema import Fact, FactKind

if TYPE_CHECKING:
    from virf.authoring.corpus import Corpus
    from virf.ontology.axiom_check import AxiomCheck
    from virf.planner.apprentices import Apprentice

DEFAULT_WORKSPACE: Final = Path("virf-kb")
DATABASE: Final = "kb.sqlite"
RUN_LOG: Final = "runs.sqlite"
CANDIDATE_IRI: Final = "http://virf.dev/ontology/workspace/candidate"
EXPORT_IRI: Final = "http://virf.dev/ontology/workspace/export"
# The annotations a workspace adds to what every USC carries.
PROVENANCE: Final = ("evidence", "drafter", "reviewer", "decision", "decidedOn", "candidate")
_USC_ANNOTATIONS: Final = (
    "id",
    "kind",
    "category",
    "dangerLevel",
    "safetyWarning",
    "triggerReason",
    "suggestion",
    "source",
    "checkAt",
    "mechanism",
    "twin",
    "question",
)
# The first line of every block a decision writes (see _block).
_BLOCK_HEADER: Final = re.compile(r"^# candidate ([0-9]+): [A-Za-z][A-Za-z0-9_]*$", re.MULTILINE)
EDIT_LABELS: Final = {
    "none": "accepted unedited",
    "minor": "accepted after a minor edit",
    "major": "accepted after a major edit",
}


def _declarations() -> str:
    props = (*_USC_ANNOTATIONS, *PROVENANCE, "rdfs:comment", "rdfs:label")
    return "".join(manchester.frame("AnnotationProperty", p) + "\n" for p in props)


def _builtin_imports(scenario: str) -> list[str]:
    """The modules the built-in scenario module imports (its domain layer)."""
    text = (ontology_dir() / f"scenario-{scenario}.omn").read_text(encoding="utf-8")
    return manchester.imports_of(text)


def _module_header(layout: KbLayout, layer: str) -> str:
    if layer == "core":
        imports = [f"{MODULE_BASE}core"]
    elif layer == "domain":
        imports = [layout.module_iri("core"), *_builtin_imports(layout.scenario)]
    else:
        imports = [layout.module_iri("domain"), f"{MODULE_BASE}scenario-{layout.scenario}"]
    about = (
        ("rdfs:label", f"Workspace {layer} layer"),
        (
            "rdfs:comment",
            "Axioms accepted through VIRF knowledge acquisition (virf kb decide or the review "
            "page). Written by VIRF, one block per decision; edit through the workflow.",
        ),
    )
    return manchester.document(layout.module_iri(layer), imports, about, _declarations())


def starter_corpus_dir() -> Path:
    return Path(str(resources.files("virf.authoring").joinpath("starter_corpus")))


class Workspace:
    """An open knowledge workspace."""

    def __init__(self, layout: KbLayout) -> None:
        self.layout = layout
        self.root = layout.root
        self.scenario = layout.scenario
        self.corpus_dir = layout.root / "corpus"
        self.cache_dir = layout.cache_dir
        self.config: dict[str, Any] = json.loads((layout.root / MARKER).read_text(encoding="utf-8"))
        threshold = self.config.get("similarity_threshold", DEFAULT_THRESHOLD)
        if isinstance(threshold, bool) or not isinstance(threshold, int | float):
            raise InputError(f"{layout.root / MARKER}: similarity_threshold must be a number")
        if not 0 < threshold <= 1:
            raise InputError(
                f"{layout.root / MARKER}: similarity_threshold {threshold} is not in (0, 1]"
            )
        self.threshold = float(threshold)
        self.store = Store(layout.root / DATABASE)
        self._corpus: Corpus | None = None
        self._index: VocabularyIndex | None = None
        self._lock = threading.Lock()
        # Under the decisions' lock: a decision being written is not a lost one.
        with self._exclusive():
            self._check_modules_match_decisions()

    def _check_modules_match_decisions(self) -> None:
        """The modules hold exactly the accepted candidates.  A block whose
        decision was committed but not yet written (a crash in between) is
        written now; a block no decision accepted (a hand edit) is refused,
        so no command works with a rule nobody accepted."""
        written: dict[int, Path] = {}
        for path in self.layout.modules():
            try:
                text = path.read_text(encoding="utf-8")
            except (OSError, UnicodeDecodeError) as exc:
                raise InputError(f"workspace module {path} is unreadable: {exc}") from None
            written.update((int(n), path) for n in _BLOCK_HEADER.findall(text))
        accepted = {d.candidate_id: d for d in self.store.decisions() if d.decision == "accept"}
        stray = sorted(set(written) - set(accepted))
        if stray:
            raise InputError(
                f"workspace {self.root}: {written[stray[0]].name} holds candidate {stray[0]}, "
                "which no decision accepted; remove its block (from '# candidate "
                f"{stray[0]}:' to the next block) or restore the module"
            )
        for cid in sorted(set(accepted) - set(written)):
            d = accepted[cid]
            if not d.block or not d.layer:
                raise InputError(f"workspace {self.root}: accepted candidate {cid} has no block")
            path = self.layout.module_path(d.layer)
            write_atomically(path, _append_block(path.read_text("utf-8"), d.block))

    # ------------------------------------------------------------------ making and opening
    @classmethod
    def init(
        cls, path: str | Path, scenario: str = "kitchen", *, starter: bool = True
    ) -> Workspace:
        root = Path(path)
        if scenario not in scenario_names():
            from virf.errors import unknown_term

            raise unknown_term("scenario", scenario, scenario_names())
        if root.exists() and (not root.is_dir() or any(root.iterdir())):
            what = "already a workspace" if (root / MARKER).exists() else "not an empty folder"
            raise InputError(f"{clip(str(root))} is {what}; choose a new folder")
        created = not root.exists()
        try:
            root.mkdir(parents=True, exist_ok=True)
            layout = KbLayout(root.resolve(), scenario)
            layout.module_dir.mkdir()
            for layer in LAYERS:
                layout.module_path(layer).write_text(_module_header(layout, layer), "utf-8")
            (root / "corpus").mkdir()
            layout.cache_dir.mkdir()
            if starter:
                for doc in sorted(starter_corpus_dir().glob("*.md")):
                    shutil.copyfile(doc, root / "corpus" / doc.name)
            config = {
                "format": FORMAT,
                "scenario": scenario,
                "similarity_threshold": DEFAULT_THRESHOLD,
                "created_at": now(),
            }
            # The marker last: a folder without it is not a workspace yet.
            (root / MARKER).write_text(json.dumps(config, indent=2) + "\n", "utf-8")
        except OSError as exc:
            if created:
                shutil.rmtree(root, ignore_errors=True)
            raise InputError(f"cannot create workspace {root}: {exc.strerror}") from None
        return cls(layout)

    @classmethod
    def open(cls, path: str | Path = DEFAULT_WORKSPACE) -> Workspace:
        return cls(open_layout(path))

    def close(self) -> None:
        self.store.close()

    def corpus(self) -> Corpus:
        from virf.authoring.corpus import Corpus

        if self._corpus is None:
            self._corpus = Corpus(self.corpus_dir, self.cache_dir)
        return self._corpus

    def tbox(self) -> TBox:
        """The built-in TBox plus what this workspace has accepted so far."""
        return load_tbox(self.scenario, kb=self.root)

    def run_log_path(self) -> Path:
        return self.root / RUN_LOG

    # ------------------------------------------------------------------ candidates in
    def draft(
        self, query: str, apprentice: Apprentice, *, k: int = 5, check: bool = True
    ) -> tuple[list[int], str]:
        """Retrieve evidence for ``query``, ask the drafter, store each rule
        as a candidate (and check it).  Returns the candidate ids and, when
        the reply was unusable, why."""
        from virf.authoring.draft import ask_drafter

        query = query.strip()
        if not query:
            raise InputError("the question is empty; say what the rules should be about")
        hits = self.corpus().search(query, k=k)
        drafted = ask_drafter(apprentice, self.tbox().vocabulary, query, hits)
        self.store.add_event("drafted", actor=apprentice.label, detail=query)
        if drafted.draft is None:
            self.store.add_event(
                "draft_failed", actor=apprentice.label, detail=f"{query}: {drafted.problem}"
            )
            return [], drafted.problem
        ids = self._store_draft(
            drafted.draft,
            query=query,
            drafter=apprentice.label,
            kind="llm",
            retrieved=[h.passage.id for h in hits],
        )
        if check:
            for cid in ids:
                self.check(cid)
        return ids, ""

    def propose(self, path: Path, author: str, *, check: bool = True) -> list[int]:
        """A person's candidate rules, from a draft document."""
        draft = read_draft(read_json_file(path, "proposal"), f"proposal {path}")
        return self.propose_draft(draft, author, check=check)

    def propose_draft(self, draft: Draft, author: str, *, check: bool = True) -> list[int]:
        ids = self._store_draft(
            draft, query=None, drafter=f"person:{author}", kind="person", retrieved=[]
        )
        if check:
            for cid in ids:
                self.check(cid)
        return ids

    def propose_learned(
        self, classes: Sequence[tuple[str, str, dict[str, Any], dict[str, Any]]], who: str
    ) -> list[int]:
        """Store classes learned from ``who``'s answers (origin "answer"), each
        ``(name, superclass expression, rule fields, learned document)`` as
        :mod:`virf.authoring.learn` makes them; all or none."""
        ids = []
        with self.store.transaction() as conn:
            for name, axiom, rule, document in classes:
                ids.append(
                    self.store.add_candidate(
                        query=None,
                        drafter=f"answer:{who}",
                        drafter_kind="person",
                        name=name,
                        axiom=axiom,
                        rule=rule,
                        draft=document,
                        evidence=[],
                        retrieved=[],
                        origin="answer",
                        conn=conn,
                    )
                )
        for cid, (name, *_rest) in zip(ids, classes, strict=True):
            self.store.add_event("learned", cid, actor=who, detail=name)
        return ids

    def _store_draft(
        self, draft: Draft, *, query: str | None, drafter: str, kind: str, retrieved: Sequence[str]
    ) -> list[int]:
        ids = []
        with self.store.transaction() as conn:
            for rule in draft.rules:
                ids.append(
                    self.store.add_candidate(
                        query=query,
                        drafter=drafter,
                        drafter_kind=kind,
                        name=rule.name,
                        axiom=rule.definition,
                        rule=rule.as_rule().model_dump(),
                        draft=rule_json(draft, rule),
                        evidence=draft.evidence_of(rule),
                        retrieved=retrieved,
                        conn=conn,
                    )
                )
        return ids

    # ------------------------------------------------------------------ checks
    def _vocabulary_index(self, vocab: Vocabulary) -> VocabularyIndex:
        from virf.embed import default_embedder

        with self._lock:
            if self._index is None or self._index.vocab is not vocab:
                self._index = VocabularyIndex(vocab, default_embedder().encode, self.cache_dir)
            return self._index

    def evidence(self, ids: Sequence[str]) -> tuple[Evidence, ...]:
        corpus = self.corpus()
        out = []
        for pid in ids:
            passage = corpus.passage(pid)
            if passage is None:
                out.append(Evidence(passage_id=pid, found=False))
                continue
            doc = corpus.document(passage.document)
            out.append(
                Evidence(
                    passage_id=pid,
                    found=True,
                    document_id=passage.document,
                    document_title=doc.title if doc else "",
                    publisher=doc.publisher if doc else "",
                    url=doc.url if doc else "",
                    section=passage.section,
                    text=passage.text,
                )
            )
        return tuple(out)

    def check(self, cid: int, axiom: str | None = None) -> CheckReport:
        """Normalise and check the candidate's axiom (or an edited one); the
        result is stored as the candidate's latest check."""
        row = self.store.candidate(cid)
        self._undecided(cid)
        text = row.axiom if axiom is None else axiom
        report = self._check_row(row, text)
        self.store.add_check(cid, text, report.passed, report.model_dump(mode="json"))
        return report

    recheck = check

    def _check_row(
        self, row: CandidateRow, axiom: str, decision: dict[str, str] | None = None
    ) -> CheckReport:
        """The checks of ``axiom`` as the candidate's: a drafted rule's, or a
        learned class's (:func:`virf.authoring.learn.check`)."""
        if row.origin == "answer":
            from virf.authoring import learn

            return learn.check(self, row, axiom, decision)
        return self._check(row.id, row.rule, row.draft, row.evidence, axiom, row.drafter, decision)

    def _check(
        self,
        cid: int,
        rule: dict[str, Any],
        draft: dict[str, Any],
        evidence_ids: Sequence[str],
        axiom: str,
        drafter: str,
        decision: dict[str, str] | None = None,
    ) -> CheckReport:
        from virf.ontology.axiom_check import check_candidate

        name = str(rule["name"])
        parsed_draft = read_draft(draft, f"candidate {cid}")
        items: list[CheckItem] = []
        vocab = self.tbox().vocabulary
        try:
            normalised = normalise(
                axiom,
                vocab,
                self._vocabulary_index(vocab),
                declared_parents=parsed_draft.parents(),
                threshold=self.threshold,
                own_name=name,
            )
        except InputError as exc:
            items.append(CheckItem.error("parses", str(exc)))
            return self._report(axiom, "", items, (), Related(), "core", "")
        items.extend(normalised.problems)
        if name in vocab.classes:
            items.append(
                CheckItem.error(
                    "name",
                    f"{name} is already a class of the TBox; a candidate must name a new "
                    "concept (propose a different name)",
                )
            )
        items.extend(self._annotation_items(rule, vocab.uscs.values()))
        items.extend(self._evidence_items(parsed_draft, evidence_ids))
        items.extend(_twin_items(name, rule.get("twins", ())))
        block = self._block(
            vocab,
            cid,
            rule,
            normalised.axiom,
            normalised.new_classes,
            evidence_ids,
            parsed_draft.rules[0].modelling_decision,
            drafter,
            decision,
        )
        if any(i.severity == "error" for i in items):
            return self._report(
                axiom, normalised.display, items, normalised.terms, Related(), "core", block
            )
        used = [t.chosen for t in normalised.terms] + [p for _, p in normalised.new_classes]
        result = check_candidate(
            self.scenario,
            tuple(str(p) for p in self.layout.modules()),
            self._candidate_module(block),
            name,
            used,
            vocab.uscs,
            always=ALWAYS_PRESENT,
            scene=empty_scene_facts(vocab),
        )
        items.extend(reasoner_items(result, name, "no situation can ever fall under it"))
        if not result.parses:
            return self._report(
                axiom, normalised.display, items, normalised.terms, Related(), "core", block
            )
        if result.consistent and result.every_state:
            items.append(
                CheckItem.error(
                    "trivial", f"{name} holds of everything: every state would be unsafe"
                )
            )
        elif result.consistent and result.satisfiable:
            items.extend(_everywhere_items(name, result))
        related = Related(
            equivalent=result.equivalent, subsumed_by=result.subsumed_by, subsumes=result.subsumes
        )
        items.extend(_novelty_items(name, related))
        layer = max((result.layers.get(t, "core") for t in used), key=LAYERS.index, default="core")
        # New classes go into the module the rule goes into.
        terms = tuple(
            t.model_copy(update={"layer": layer}) if t.match == "new" and t.role == "class" else t
            for t in normalised.terms
        )
        return self._report(axiom, normalised.display, items, terms, related, layer, block)

    def _report(
        self,
        axiom: str,
        normalised: str,
        items: Sequence[CheckItem],
        terms: Sequence[Any],
        related: Related,
        layer: str,
        block: str,
    ) -> CheckReport:
        return CheckReport(
            axiom=axiom,
            normalised=normalised,
            passed=not any(i.severity == "error" for i in items),
            layer=layer,  # type: ignore[arg-type]
            threshold=self.threshold,
            terms=tuple(terms),
            items=tuple(items),
            related=related,
            module_text=block,
            checked_at=now(),
        )

    @staticmethod
    def _annotation_items(rule: dict[str, Any], uscs: Any) -> list[CheckItem]:
        known = sorted({u.category for u in uscs})
        if rule["category"] in known:
            return []
        return [
            CheckItem.warning(
                "category",
                f"category '{rule['category']}' is new to the TBox; known: {', '.join(known)}",
                ok=False,
            )
        ]

    def _evidence_items(self, draft: Draft, ids: Sequence[str]) -> list[CheckItem]:
        rule = draft.rules[0]
        if not ids:
            if rule.modelling_decision:
                return [
                    CheckItem.warning(
                        "evidence",
                        "cites no document: a common-sense modelling decision "
                        f"({rule.modelling_decision})",
                    )
                ]
            return [
                CheckItem.error(
                    "evidence",
                    "cites no evidence: give passage ids, or a 'modellingDecision' "
                    "saying why no document is needed",
                )
            ]
        corpus = self.corpus()
        missing = [pid for pid in ids if corpus.passage(pid) is None]
        if missing:
            return [
                CheckItem.error(
                    "evidence", f"cites passages the corpus does not have: {', '.join(missing)}"
                )
            ]
        return [CheckItem.info("evidence", f"{len(ids)} passage(s) found")]

    def _source(self, ids: Sequence[str], modelling_decision: str | None) -> str:
        corpus = self.corpus()
        by_doc: dict[str, list[str]] = {}
        for pid in ids:
            passage = corpus.passage(pid)
            if passage is not None:
                by_doc.setdefault(passage.document, []).append(pid)
        parts = []
        for doc_id, pids in by_doc.items():
            doc = corpus.document(doc_id)
            title = f"{doc.publisher}, {doc.title}" if doc else doc_id
            url = f" <{doc.url}>" if doc and doc.url else ""
            parts.append(f"{title}{url}: passages {', '.join(pids)}")
        if modelling_decision:
            parts.append(f"common-sense modelling decision: {modelling_decision}")
        return "; ".join(parts) or "no evidence"

    def _block(
        self,
        vocab: Vocabulary,
        cid: int,
        rule: dict[str, Any],
        axiom: str,
        new_classes: Sequence[tuple[str, str]],
        evidence_ids: Sequence[str],
        modelling_decision: str | None,
        drafter: str,
        decision: dict[str, str] | None,
    ) -> str:
        """The Manchester frames accepting the candidate adds to a layer module."""
        name = rule["name"]
        source = self._source(evidence_ids, modelling_decision)
        lines = [f"# candidate {cid}: {name}"]
        # Every term the block uses is declared in it: OWLAPI's Manchester
        # parser does not look into already-loaded imports when it parses a
        # document from a string, and the declarations cost nothing.
        new = {c for c, _ in new_classes}
        for term, role in sorted(manchester.names(axiom).items()):
            if term in new:
                continue
            keyword = manchester.FRAME_OF_ROLE[role]
            if term in vocab.data_properties:
                keyword = "DataProperty"
            lines.append(manchester.frame(keyword, term))
        for parent in sorted({p for _, p in new_classes} - new | {"UnsafeStateConcept"}):
            lines.append(manchester.frame("Class", parent))
        lines.append("")
        for cls, parent in new_classes:
            introduced = ("rdfs:comment", f"Introduced by candidate {cid} ({name}).")
            lines += [
                manchester.frame(
                    "Class",
                    cls,
                    manchester.annotations_section([introduced], one_line=True),
                    manchester.section("SubClassOf", [manchester.term(parent)], one_line=True),
                ),
                "",
            ]
        anns = [
            ("id", name),
            ("kind", rule["kind"]),
            ("category", rule["category"]),
            ("dangerLevel", rule["danger_level"]),
            ("rdfs:comment", rule["description"]),
            ("safetyWarning", rule["safety_warning"]),
            ("triggerReason", rule["trigger_reason"]),
            ("suggestion", rule["suggestion"]),
            ("source", source),
            ("checkAt", rule["check_at"]),
            *([("mechanism", rule["mechanism"])] if rule.get("mechanism") else []),
            *([("question", rule["question"])] if rule.get("question") else []),
            *(("twin", t) for t in rule.get("twins", ())),
            *(("evidence", pid) for pid in evidence_ids),
            ("drafter", drafter),
            ("candidate", str(cid)),
            *(decision or {}).items(),
        ]
        definition = manchester.Axiom(axiom, (("id", name + "-def"), ("source", source)))
        lines += [
            manchester.frame(
                "Class",
                name,
                manchester.annotations_section(anns),
                manchester.section("EquivalentTo", [definition]),
                manchester.section("SubClassOf", [":UnsafeStateConcept"], one_line=True),
            ),
            "",
        ]
        return "\n".join(lines)

    def _candidate_module(self, block: str) -> str:
        return manchester.document(
            CANDIDATE_IRI, [self.layout.module_iri("scenario")], (), _declarations(), block
        )

    # ------------------------------------------------------------------ preview
    def preview(
        self,
        cid: int,
        axiom: str | None = None,
        tasks: Path | None = None,
        examples: Path | None = None,
    ) -> Preview:
        from virf.authoring.preview import effect_preview

        row = self.store.candidate(cid)
        self._undecided(cid)
        if examples is not None and not examples.is_dir():
            raise InputError(f"examples folder {clip(str(examples))} does not exist")
        if tasks is not None and not tasks.is_file():
            raise InputError(f"benchmark file {clip(str(tasks))} does not exist")
        text = axiom if axiom is not None else self._current_axiom(cid, row.axiom)
        report = self._check_row(row, text)
        if not report.passed:
            failed = next(i for i in report.items if i.severity == "error")
            raise InputError(f"candidate {cid} does not pass its checks: {failed.message}")
        self.cache_dir.mkdir(exist_ok=True)
        module = self.cache_dir / f"preview-{cid}.omn"
        write_atomically(module, self._candidate_module(report.module_text))
        scenes: list[tuple[str, dict[str, Any], tuple[str, ...]]] = []
        if row.origin == "answer":
            from virf.authoring.learn import learned_of

            learned = learned_of(row)
            scenes.append(
                (f"scene {learned.scene_name} (learned from)", row.draft["scene"], learned.plan)
            )
        result = effect_preview(
            self,
            module,
            text,
            tasks=tasks,
            examples=examples,
            scenes=scenes,
            kb_test=row.origin == "answer",
        )
        self.store.add_preview(cid, text, result.model_dump(mode="json"))
        return result

    def _current_axiom(self, cid: int, drafted: str) -> str:
        latest = self.store.latest_check(cid)
        return str(latest["axiom"]) if latest else drafted

    # ------------------------------------------------------------------ arbitration
    def opened(self, cid: int, reviewer: str) -> None:
        self.store.candidate(cid)  # an unknown id is an error here too
        self.store.add_event("opened", cid, actor=reviewer)

    def decide(
        self,
        cid: int,
        decision: str,
        *,
        reviewer: str,
        reason: str | None = None,
        axiom: str | None = None,
    ) -> DecisionView:
        """Record a decision.  Accepting checks the final axiom (``axiom``, or
        the one checked last) once more and writes its block into its layer's
        module; a candidate whose checks fail is refused.

        The database is the record: the decision is committed first and the
        module replaced after, so a crash in between leaves an accepted rule
        out of the TBox (restored when the workspace is next opened), never a
        rule nobody accepted in it."""
        if decision not in ("accept", "reject"):
            raise InputError(f"unknown decision '{clip(decision)}'; choose accept or reject")
        if not reviewer.strip():
            raise InputError("a decision needs a reviewer's name (--reviewer or $USER)")
        if decision == "reject" and not (reason and reason.strip()):
            raise InputError("a rejection needs a reason (--reason TEXT)")
        row = self.store.candidate(cid)
        with self._exclusive():
            self._undecided(cid)
            opened = self.store.first_event(cid, "opened")
            decided_at = now()
            seconds = _seconds_between(opened, decided_at) if opened else None
            if decision == "reject":
                assert reason is not None
                record = DecisionRow(
                    cid, decided_at, "reject", "none", None, None, reason.strip(), reviewer, seconds
                )
                with self.store.transaction() as conn:
                    self.store.add_decision(conn, record)
                    self.store.add_event("decided", cid, actor=reviewer, detail="reject")
                return _decision_view(record)
            current = self._current_axiom(cid, row.axiom)
            final = axiom if axiom is not None else current
            edit = _edit_size(row.axiom, final)
            provenance = {
                "reviewer": reviewer,
                "decision": EDIT_LABELS[edit]
                + (f": {' '.join(reason.split())}" if reason and reason.strip() else ""),
                "decidedOn": decided_at[:10],
            }
            report = self._check_row(row, final, provenance)
            if not report.passed:
                failed = next(i for i in report.items if i.severity == "error")
                if final == current:
                    # The candidate's own axiom, checked again: its latest check.
                    self.store.add_check(cid, final, False, report.model_dump(mode="json"))
                else:
                    # An edit refused at acceptance does not become the
                    # candidate's axiom: a later plain accept (or preview)
                    # still takes the version checked last.  The attempt is
                    # kept as an event.
                    self.store.add_event(
                        "accept_refused",
                        cid,
                        actor=reviewer,
                        detail=f"{' '.join(final.split())}: {failed.message}",
                    )
                raise InputError(f"candidate {cid} cannot be accepted: {failed.message}")
            layer: Layer = report.layer
            record = DecisionRow(
                cid,
                decided_at,
                "accept",
                edit,
                final,
                layer,
                reason,
                reviewer,
                seconds,
                report.module_text,
            )
            path = self.layout.module_path(layer)
            staged = path.with_name(f".{path.name}.staged")
            try:
                write_atomically(staged, _append_block(path.read_text("utf-8"), report.module_text))
                # The modules as they will be must load: a block that parses
                # on top of the workspace but not in its layer stays out.
                from virf.ontology.axiom_check import parses_with

                parses_with(
                    self.scenario,
                    tuple(str(staged if p == path else p) for p in self.layout.modules()),
                )
                with self.store.transaction() as conn:
                    self.store.add_check(cid, final, True, report.model_dump(mode="json"))
                    self.store.add_decision(conn, record)
                    self.store.add_event("decided", cid, actor=reviewer, detail=f"accept ({edit})")
                os.replace(staged, path)
            finally:
                staged.unlink(missing_ok=True)
        return _decision_view(record)

    @contextmanager
    def _exclusive(self) -> Iterator[None]:
        """One decision at a time, across the review server's threads and
        every process using the workspace."""
        import fcntl

        with open(self.root / ".lock", "a+") as fh:
            fcntl.flock(fh, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(fh, fcntl.LOCK_UN)

    def _undecided(self, cid: int) -> None:
        decided = self.store.decision(cid)
        if decided is not None:
            what = "accepted" if decided.decision == "accept" else "rejected"
            raise InputError(f"candidate {cid} has already been decided ({what})")

    # ------------------------------------------------------------------ reading
    def candidates(self, status: Status | None = None) -> list[CandidateSummary]:
        statuses = self.store.statuses()
        out = []
        for cid, st in statuses.items():
            if status is not None and st != status:
                continue
            out.append(self._summary(self.store.candidate(cid), st, self.store.latest_check(cid)))
        return out

    @staticmethod
    def _summary(row: CandidateRow, status: str, latest: dict[str, Any] | None) -> CandidateSummary:
        return CandidateSummary(
            id=row.id,
            name=row.name,
            category=str(row.rule["category"]),
            drafter=row.drafter,
            query=row.query,
            created_at=row.created_at,
            status=status,  # type: ignore[arg-type]
            passed=None if latest is None else bool(latest["passed"]),
            origin=row.origin,  # type: ignore[arg-type]
        )

    def summary(self, cid: int) -> CandidateSummary:
        """The candidate's queue entry (InputError for an unknown id)."""
        row = self.store.candidate(cid)  # first: it refuses an id no candidate can have
        decision = self.store.decision(cid)
        return self._summary(
            row,
            status_of(decision.decision if decision else None),
            self.store.latest_check(cid),
        )

    def candidate(self, cid: int) -> CandidateView:
        row = self.store.candidate(cid)
        check = self.store.latest_check(cid)
        preview = self.store.latest_preview(cid)
        decision = self.store.decision(cid)
        status = status_of(decision.decision if decision else None)
        learned = None
        if row.origin == "answer":
            from virf.authoring.learn import learned_of

            learned = learned_of(row)
        return CandidateView(
            summary=self._summary(row, status, check),
            rule=RuleDraft(**row.rule),
            evidence=self.evidence(row.evidence),
            retrieved=row.retrieved,
            draft=row.draft,
            check=CheckReport.model_validate(check) if check else None,
            preview=Preview.model_validate(preview) if preview else None,
            decision=_decision_view(decision) if decision else None,
            learned=learned,
        )

    def export(self, iri: str = EXPORT_IRI, label: str | None = None) -> str:
        """Every accepted block as one module that imports the built-in
        scenario the workspace is layered on: what a release of the reviewed
        knowledge adds to the built-in ontology (``virf kb export``).

        Blocks keep their provenance (evidence, drafter, candidate, reviewer,
        decision) and come in candidate order, so the same decisions give the
        same module whatever order they were taken in."""
        blocks = sorted(
            (d.candidate_id, d.block)
            for d in self.store.decisions()
            if d.decision == "accept" and d.block
        )
        text = label or f"Knowledge accepted in workspace {self.root.name} (virf kb export)"
        about = (
            ("rdfs:label", text),
            (
                "rdfs:comment",
                "Written by 'virf kb export' from the workspace's accepted candidates; "
                "each block is one decision. Edit through the workflow, not by hand.",
            ),
        )
        module = manchester.document(
            iri, [f"{MODULE_BASE}scenario-{self.scenario}"], about, _declarations()
        )
        return module + "".join(f"\n{block.rstrip()}\n" for _, block in blocks)

    def rules(self) -> list[AcceptedRule]:
        out = []
        for d in self.store.decisions():
            if d.decision != "accept":
                continue
            row = self.store.candidate(d.candidate_id)
            out.append(
                AcceptedRule(
                    id=row.name,
                    name=row.name,
                    layer=d.layer or "core",  # type: ignore[arg-type]
                    axiom=d.axiom or row.axiom,
                    category=str(row.rule["category"]),
                    evidence=row.evidence,
                    drafter=row.drafter,
                    reviewer=d.reviewer,
                    edit=d.edit,  # type: ignore[arg-type]
                    decided_at=d.created_at,
                    candidate_id=d.candidate_id,
                )
            )
        return out


def reasoner_items(result: AxiomCheck, name: str, unsatisfiable: str) -> list[CheckItem]:
    """What HermiT said of a candidate, as check items: the axiom parses, the
    TBox stays consistent with it, and ``name`` is satisfiable (else why
    not: ``unsatisfiable``)."""
    if not result.parses:
        return [CheckItem.error("parses", result.parse_error)]
    items = [CheckItem.info("parses", "the axiom parses")]
    if not result.consistent:
        items.append(CheckItem.error("consistent", "the TBox becomes inconsistent with this axiom"))
        return items
    items.append(CheckItem.info("consistent", "the TBox stays consistent"))
    if result.satisfiable is False:
        items.append(CheckItem.error("satisfiable", f"{name} is unsatisfiable: {unsatisfiable}"))
    else:
        items.append(CheckItem.info("satisfiable", f"{name} is satisfiable"))
    return items


# Classes every verification has an individual of, with why.  A rule that
# holds of every individual of one of them would make every scene, or every
# plan, unsafe, whatever it holds: it is refused.
ALWAYS_PRESENT: Final = {
    "Robot": "every scene has one: the scene reader adds Robot_1 when it names none",
    "Action": "every plan step is one",
    "PhysicalObject": "every object a scene names is one",
}


# The action individual every plan's first step has in common with any other.
ANY_STEP: Final = "Step1_action"


def empty_scene_facts(vocab: Vocabulary) -> tuple[Fact, ...]:
    """What every verification starts from: the first snapshot of a scene
    that names nothing (the robot the scene reader adds, with empty hands),
    as the verifier hands it to the reasoner, with what every plan's first
    step adds to it whatever its verb: an action, by the robot."""
    from virf.world.scene import build_scene
    from virf.world.simulator import Simulator

    sim = Simulator(vocab)
    state = sim.initial(build_scene({"instances": [], "assertions": []}, vocab))
    step = {
        Fact(ANY_STEP, "type", "Action", FactKind.TYPE),
        Fact(ANY_STEP, "hasAgent", state.agent),
    }
    return tuple(sorted({*state.facts, *sim.closure_facts(state), *step}))


def _everywhere_items(name: str, result: AxiomCheck) -> list[CheckItem]:
    """A rule that would fire on every scene or plan: one that holds of every
    individual of a class each verification has, of the knowledge base's own
    individuals (which scenes mention as states, materials and properties),
    or of something in the empty scene."""
    items = []
    if result.holds_of_every:
        every = ", ".join(f"every {c} ({ALWAYS_PRESENT.get(c, '')})" for c in result.holds_of_every)
        items.append(
            CheckItem.error(
                "always-present",
                f"{name} holds of {every}: every scene or plan would be unsafe",
            )
        )
    if result.holds_of_named:
        shown = ", ".join(result.holds_of_named[:5]) + (
            ", ..." if len(result.holds_of_named) > 5 else ""
        )
        items.append(
            CheckItem.error(
                "named-individuals",
                f"{name} holds of the knowledge base's own individual(s) {shown}: every scene "
                "that mentions one would be unsafe; a rule is about the things of a scene",
            )
        )
    if not result.empty_scene_consistent:
        items.append(
            CheckItem.error(
                "empty-scene",
                f"the empty scene (only the robot every scene has) contradicts {name}: "
                "every scene would be an inconsistent world",
            )
        )
    elif result.empty_scene and not result.holds_of_every:
        robot = [i for i in result.empty_scene if i != ANY_STEP]
        if robot:
            items.append(
                CheckItem.error(
                    "empty-scene",
                    f"{name} fires in the empty scene (on {', '.join(robot)}): a scene that "
                    "names nothing would be unsafe before any step, and so would every scene "
                    "that does not rule it out",
                )
            )
        if ANY_STEP in result.empty_scene:
            items.append(
                CheckItem.error(
                    "empty-scene",
                    f"{name} fires on every plan step (on {ANY_STEP}, an action by the robot "
                    "and nothing more): every plan would be unsafe at its first step",
                )
            )
    if not items:
        items.append(
            CheckItem.info(
                "always-present",
                "holds of nothing every scene or plan has (the robot, an action, any object), "
                "nor of the empty scene",
            )
        )
    return items


def _append_block(module: str, block: str) -> str:
    return module.rstrip("\n") + "\n\n" + block


def _twin_items(name: str, twins: Sequence[str]) -> list[CheckItem]:
    """Whether the rule comes with minimal pairs that read (virf kb test runs them)."""
    from virf.verify.twins import read_pair

    if not twins:
        return [
            CheckItem.warning(
                "twins",
                "no minimal pair: give 'twins' ('WORLD | PLAN | OLD => NEW', a world where the "
                "rule holds and a twin differing in the property that matters) so that "
                "virf kb test can check the rule",
                ok=False,
            )
        ]
    for text in twins:
        try:
            read_pair(name, text)
        except InputError as exc:
            return [CheckItem.error("twins", str(exc))]
    return [CheckItem.info("twins", f"{len(twins)} minimal pair(s) read")]


def _novelty_items(name: str, related: Related) -> list[CheckItem]:
    items = []
    if related.equivalent:
        items.append(
            CheckItem.warning(
                "redundancy",
                f"redundant: {name} is equivalent to {', '.join(related.equivalent)}",
                ok=False,
            )
        )
    if related.subsumed_by:
        items.append(
            CheckItem.warning(
                "redundancy",
                f"redundant: every {name} situation is already a "
                f"{', '.join(related.subsumed_by)} situation",
                ok=False,
            )
        )
    if related.subsumes:
        items.append(CheckItem.info("generalisation", f"generalises {', '.join(related.subsumes)}"))
    if not items:
        items.append(CheckItem.info("novelty", "no existing rule covers it"))
    return items


def _edit_size(drafted: str, final: str) -> str:
    """none: the same expression; minor: only names changed (URI alignment,
    a fixed spelling); major: the structure changed (scope, restrictions)."""
    try:
        a, b = manchester.tokens(drafted), manchester.tokens(final)
    except InputError:
        return "major"
    if [t.text for t in a] == [t.text for t in b]:
        return "none"
    return "minor" if manchester.shape(drafted) == manchester.shape(final) else "major"


def _seconds_between(start: str, end: str) -> float:
    delta = datetime.fromisoformat(end) - datetime.fromisoformat(start)
    return round(max(0.0, delta.total_seconds()), 3)


def _decision_view(d: DecisionRow) -> DecisionView:
    return DecisionView(
        decision=d.decision,  # type: ignore[arg-type]
        edit=d.edit,  # type: ignore[arg-type]
        axiom=d.axiom,
        reason=d.reason,
        reviewer=d.reviewer,
        decided_at=d.created_at,
        seconds=d.seconds,
        layer=d.layer,  # type: ignore[arg-type]
    )
