"""A knowledge workspace: the one place the workflow's steps meet.

``Workspace`` owns the folder (see :mod:`virf.ontology.workspace` for the
part verification reads), the corpus, the database and the layered modules.
Drafting, a person's proposal, checks, the effect preview and decisions all
go through it, so the terminal and the review page behave the same.

The steps themselves live in their own modules, each given the workspace:
:mod:`~virf.authoring.intake` (candidates in), :mod:`~virf.authoring.checks`,
:mod:`~virf.authoring.preview`, :mod:`~virf.authoring.decisions`,
:mod:`~virf.authoring.views` (what the terminal and the review page show) and
:mod:`~virf.authoring.layers` (the modules' Manchester text, the export).
"""

from __future__ import annotations

import json
import shutil
import threading
from collections.abc import Sequence
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from virf.authoring import checks, decisions, intake, layers, views
from virf.authoring.decisions import exclusive
from virf.authoring.layers import EXPORT_IRI
from virf.authoring.models import (
    AcceptedRule,
    CandidateSummary,
    CandidateView,
    CheckReport,
    DecisionView,
    Evidence,
    Preview,
    Status,
)
from virf.authoring.normalize import DEFAULT_THRESHOLD, VocabularyIndex
from virf.authoring.store import Store
from virf.errors import InputError, clip
from virf.files import write_atomically
from virf.migrations import now
from virf.ontology.tbox import TBox, Vocabulary, load_tbox, scenario_names
from virf.ontology.workspace import FORMAT, LAYERS, MARKER, KbLayout, open_layout

if TYPE_CHECKING:
    from virf.authoring.corpus import Corpus
    from virf.authoring.drafts import Draft
    from virf.planner.apprentices import Apprentice

DEFAULT_WORKSPACE: Final = Path("virf-kb")
DATABASE: Final = "kb.sqlite"
RUN_LOG: Final = "runs.sqlite"


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
        with exclusive(self.root):
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
            written.update((cid, path) for cid in layers.block_ids(text))
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
            write_atomically(path, layers.append_block(path.read_text("utf-8"), d.block))

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
                layout.module_path(layer).write_text(layers.module_header(layout, layer), "utf-8")
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

    def vocabulary_index(self, vocab: Vocabulary) -> VocabularyIndex:
        """The embedding index of ``vocab`` that normalisation matches names
        against, built once per TBox and shared by the review server's threads."""
        from virf.embed import default_embedder

        with self._lock:
            if self._index is None or self._index.vocab is not vocab:
                self._index = VocabularyIndex(vocab, default_embedder().encode, self.cache_dir)
            return self._index

    # ------------------------------------------------------------------ candidates in
    def draft(
        self, query: str, apprentice: Apprentice, *, k: int = 5, check: bool = True
    ) -> tuple[list[int], str]:
        """Retrieve evidence for ``query``, ask the drafter, store each rule
        as a candidate (and check it).  Returns the candidate ids and, when
        the reply was unusable, why."""
        return intake.draft(self, query, apprentice, k=k, check=check)

    def propose(self, path: Path, author: str, *, check: bool = True) -> list[int]:
        """A person's candidate rules, from a draft document."""
        return intake.propose(self, path, author, check=check)

    def propose_draft(self, draft: Draft, author: str, *, check: bool = True) -> list[int]:
        return intake.propose_draft(self, draft, author, check=check)

    def propose_learned(
        self, classes: Sequence[tuple[str, str, dict[str, Any], dict[str, Any]]], who: str
    ) -> list[int]:
        """Store classes learned from ``who``'s answers (origin "answer"), each
        ``(name, superclass expression, rule fields, learned document)`` as
        :mod:`virf.authoring.learn` makes them; all or none."""
        return intake.propose_learned(self, classes, who)

    # ------------------------------------------------------------------ checks and preview
    def check(self, cid: int, axiom: str | None = None) -> CheckReport:
        """Normalise and check the candidate's axiom (or an edited one); the
        result is stored as the candidate's latest check."""
        return checks.check(self, cid, axiom)

    recheck = check

    def preview(
        self,
        cid: int,
        axiom: str | None = None,
        tasks: Path | None = None,
        examples: Path | None = None,
    ) -> Preview:
        """The verdicts accepting the candidate would change (see
        :mod:`virf.authoring.preview`)."""
        from virf.authoring.preview import preview

        return preview(self, cid, axiom, tasks, examples)

    # ------------------------------------------------------------------ arbitration
    def opened(self, cid: int, reviewer: str) -> None:
        decisions.opened(self, cid, reviewer)

    def decide(
        self,
        cid: int,
        decision: str,
        *,
        reviewer: str,
        reason: str | None = None,
        axiom: str | None = None,
    ) -> DecisionView:
        """Record a decision (see :func:`virf.authoring.decisions.decide`)."""
        return decisions.decide(self, cid, decision, reviewer=reviewer, reason=reason, axiom=axiom)

    # ------------------------------------------------------------------ reading
    def candidates(self, status: Status | None = None) -> list[CandidateSummary]:
        return views.candidates(self, status)

    def summary(self, cid: int) -> CandidateSummary:
        """The candidate's queue entry (InputError for an unknown id)."""
        return views.summary(self, cid)

    def candidate(self, cid: int) -> CandidateView:
        return views.candidate(self, cid)

    def evidence(self, ids: Sequence[str]) -> tuple[Evidence, ...]:
        return views.evidence(self, ids)

    def rules(self) -> list[AcceptedRule]:
        return views.rules(self)

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
        return layers.export_module(self.scenario, iri, text, (block for _, block in blocks))
