"""A workspace's corpus: a folder of safety documents and a cached hybrid index over their passages.

The files in the folder are the truth; what is derived from them (the
documents as parsed, one embedding per passage) is kept in the cache folder,
keyed by a digest of the files (:mod:`virf.authoring.corpus_cache`), so
deleting the cache only costs a rebuild.  When the corpus changes, vectors of
passages whose text did not change are reused, so adding a document embeds
only it.

Retrieval is hybrid: BM25 over the passages' words and the embeddings' cosine
similarity, fused into one score in [0, 1] (:mod:`virf.authoring.scoring`).
Ties go to the smaller passage id.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import os
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

import numpy as np
import numpy.typing as npt

from virf.authoring.corpus_cache import (
    FILE_MODE,
    INDEX_FORMAT,
    read_documents,
    read_index,
    write_documents,
    write_index,
)
from virf.authoring.documents import (
    READERS,
    SUPPORTED,
    Document,
    Passage,
    read_document,
    read_document_bytes,
    shown,
)
from virf.authoring.scoring import bm25_index, fused, indexed_text, tokens
from virf.errors import InputError, clip

if TYPE_CHECKING:
    from virf.embed import Embedder

# A question, not a document: BM25 scores each query word against every passage.
MAX_QUERY_CHARS = 2000
Progress = Callable[[int, int], None]  # (texts embedded so far, texts to embed)


@dataclass(frozen=True)
class Hit:
    passage: Passage
    document: Document
    score: float  # the fused score in [0, 1]
    bm25: float  # raw BM25 score
    dense: float  # cosine similarity of the embeddings
    rank: int  # 1 for the best hit


@dataclass(frozen=True)
class _File:
    name: str
    digest: str


@dataclass
class _Index:
    key: str
    passages: list[Passage]
    documents: dict[str, Document]
    embeddings: npt.NDArray[np.float32]
    bm25: Any  # rank_bm25.BM25Okapi, or None when no passage has an indexable word


class Corpus:
    """The documents in ``folder``, with derived data in ``cache_dir``.

    ``embedder`` defaults to the shared all-MiniLM-L6-v2 model, loaded on
    first use; listing documents never needs it."""

    def __init__(self, folder: Path, cache_dir: Path, embedder: Embedder | None = None) -> None:
        self.folder = Path(folder)
        self.cache_dir = Path(cache_dir)
        self._embedder = embedder
        self._documents: tuple[str, list[Document]] | None = None
        self._index: _Index | None = None
        self._hashed: dict[str, tuple[tuple[int, int], str]] = {}

    # -- embeddings, shared with vocabulary normalisation -------------------

    @property
    def embedder(self) -> Embedder:
        if self._embedder is None:
            from virf.embed import default_embedder

            self._embedder = default_embedder()
        return self._embedder

    def embed_texts(self, texts: Sequence[str]) -> npt.NDArray[np.float32]:
        """Unit vectors (n, 384) of ``texts``, comparable with the passages' by dot product."""
        return self.embedder.encode(texts)

    # -- documents --------------------------------------------------------

    def files(self) -> list[Path]:
        """The document files in the folder, sorted by name.

        Hidden files and editor backups (``.x``, ``x~``) are skipped; any other
        file must be a readable document."""
        if not self.folder.is_dir():
            return []
        out = []
        for path in sorted(self.folder.iterdir(), key=lambda p: p.name):
            if path.name.startswith(".") or path.name.endswith("~") or not path.is_file():
                continue
            if path.suffix.lower() not in READERS:
                raise InputError(
                    f"corpus file {shown(path)} is not a supported document ({SUPPORTED}); "
                    "remove or convert it"
                )
            out.append(path)
        return out

    def documents(self) -> list[Document]:
        """Every document, sorted by id."""
        return list(self._load_documents()[1])

    def document(self, doc_id: str) -> Document | None:
        return next((d for d in self.documents() if d.id == doc_id), None)

    def passages(self) -> list[Passage]:
        """Every passage, in document id order, then in reading order."""
        return [p for d in self.documents() for p in d.passages]

    def passage(self, pid: str) -> Passage | None:
        doc_id = pid.split(":", 1)[0]
        doc = self.document(doc_id)
        return None if doc is None else next((p for p in doc.passages if p.id == pid), None)

    def _scan(self) -> tuple[str, list[_File]]:
        files = []
        whole = hashlib.sha256()
        for path in self.files():
            try:
                st = path.stat()
            except OSError as exc:
                raise InputError(f"cannot read corpus file {shown(path)}: {exc.strerror}") from None
            # Within one process a file whose size and modification time did
            # not change is not hashed again: passage() and document() are
            # called once per cited passage.
            stamp = (st.st_size, st.st_mtime_ns)
            known = self._hashed.get(path.name)
            if known is not None and known[0] == stamp:
                digest = known[1]
            else:
                digest = hashlib.sha256(read_document_bytes(path)).hexdigest()
                self._hashed[path.name] = (stamp, digest)
            files.append(_File(path.name, digest))
            whole.update(f"{path.name}\0{digest}\n".encode())
        return whole.hexdigest(), files

    def _load_documents(self) -> tuple[str, list[Document]]:
        digest, files = self._scan()
        if self._documents is not None and self._documents[0] == digest:
            return self._documents
        docs = read_documents(self.cache_dir, self.folder, digest)
        if docs is None:
            docs = [read_document(self.folder / f.name) for f in files]
            write_documents(self.cache_dir, digest, docs)
        seen: dict[str, str] = {}
        for doc in docs:
            other = seen.setdefault(doc.id, Path(doc.path).name)
            if other != Path(doc.path).name:
                raise InputError(
                    f"corpus files {clip(other)} and {clip(Path(doc.path).name)} both have "
                    f"document id '{doc.id}'; remove one or change its id"
                )
        docs.sort(key=lambda d: d.id)
        self._documents = (digest, docs)
        return self._documents

    # -- adding documents -------------------------------------------------

    def add(self, paths: Sequence[Path], replace: bool = False) -> list[Document]:
        """Copy documents into the corpus; see :meth:`add_with_status`."""
        return [doc for doc, _ in self.add_with_status(paths, replace)]

    def add_with_status(
        self, paths: Sequence[Path], replace: bool = False
    ) -> list[tuple[Document, str]]:
        """Copy documents into the corpus, all or none, under their own file names.

        Every file is read and checked before any is copied.  A document whose
        id is already in the corpus is left alone when its bytes are the same
        ("unchanged"); with other bytes it is an error unless ``replace``
        ("replaced").  Returns each document (at its corpus path) with
        "added", "replaced" or "unchanged"."""
        if not paths:
            raise InputError("give at least one document file to add")
        incoming: list[tuple[Path, bytes, Document]] = []
        by_id: dict[str, Path] = {}
        by_name: dict[str, Path] = {}
        for path in paths:
            path = Path(path)
            doc = read_document(path)
            raw = read_document_bytes(path)
            name = path.name
            if name.startswith(".") or name.endswith("~"):
                raise InputError(
                    f"file name {clip(name)} would be ignored in the corpus (hidden or backup); "
                    "rename the file"
                )
            if doc.id in by_id:
                raise InputError(
                    f"{shown(by_id[doc.id])} and {shown(path)} both have document id "
                    f"'{doc.id}'; add one of them"
                )
            if name in by_name:
                raise InputError(
                    f"{shown(by_name[name])} and {shown(path)} have the same file name; rename one"
                )
            by_id[doc.id], by_name[name] = path, path
            incoming.append((path, raw, doc))

        existing = {d.id: d for d in self.documents()}
        owner_of_name = {Path(d.path).name: d.id for d in existing.values()}
        plan: list[tuple[bytes, Document, str, str | None]] = []  # bytes, doc, status, old name
        for path, raw, doc in incoming:
            old = existing.get(doc.id)
            status = "added"
            old_name = None
            if old is not None:
                old_name = Path(old.path).name
                if read_document_bytes(self.folder / old_name) == raw:
                    plan.append((raw, old, "unchanged", None))
                    continue
                if not replace:
                    raise InputError(
                        f"document id '{doc.id}' ({shown(path)}) is already in the corpus as "
                        f"{clip(old_name)} with other content; use --replace to replace it"
                    )
                status = "replaced"
            owner = owner_of_name.get(path.name)
            if owner is not None and owner != doc.id:
                raise InputError(
                    f"the corpus already has a file named {clip(path.name)} (document '{owner}'); "
                    f"rename {shown(path)} before adding it"
                )
            plan.append((raw, doc, status, old_name))

        self._commit(plan, [p for p, _, _ in incoming])
        out = []
        for (_raw, doc, status, _old), path in zip(plan, (p for p, _, _ in incoming), strict=True):
            target = self.folder / (Path(doc.path).name if status == "unchanged" else path.name)
            out.append((dataclasses.replace(doc, path=str(target)), status))
        return out

    def _commit(
        self, plan: list[tuple[bytes, Document, str, str | None]], paths: list[Path]
    ) -> None:
        """Write every new file under a hidden temporary name, then rename them
        all into place: a failure while writing leaves the corpus as it was."""
        writes = [
            (raw, path.name, old)
            for (raw, _doc, status, old), path in zip(plan, paths, strict=True)
            if status != "unchanged"
        ]
        if not writes:
            return
        staged: list[tuple[Path, Path, str | None]] = []
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            for raw, name, old in writes:
                fd, temp_name = tempfile.mkstemp(
                    prefix=f".{name}.", suffix=".adding", dir=self.folder
                )
                staged.append((Path(temp_name), self.folder / name, old))
                with os.fdopen(fd, "wb") as fh:
                    os.fchmod(fh.fileno(), FILE_MODE)
                    fh.write(raw)
        except OSError as exc:
            self._unstage(staged, exc)
        try:
            for staged_file, target, old in staged:
                os.replace(staged_file, target)
                if old is not None and old != target.name:
                    (self.folder / old).unlink(missing_ok=True)
        except OSError as exc:
            # Renames within one folder fail only when the disk or its
            # permissions change under us; what was renamed stays.
            self._unstage(staged, exc)
        finally:
            self._documents = None
            self._index = None

    # -- the index --------------------------------------------------------

    def _unstage(self, staged: Sequence[tuple[Path, Path, str | None]], exc: OSError) -> NoReturn:
        """Remove the staged copies that are still there, and say why the add failed."""
        for staged_file, _, _ in staged:
            with contextlib.suppress(OSError):
                staged_file.unlink()
        raise InputError(
            f"cannot write to the corpus {shown(self.folder)}: {exc.strerror}"
        ) from None

    def build(self, progress: Progress | None = None) -> None:
        """Make sure the retrieval index is current, embedding what changed.

        ``progress(done, total)`` is called as passages are embedded (not at
        all when the cached index is current)."""
        self._current_index(progress)

    def _current_index(self, progress: Progress | None) -> _Index:
        digest, docs = self._load_documents()
        if not docs:
            raise InputError(
                f"the corpus {shown(self.folder)} is empty; add documents with "
                "'virf kb corpus add FILE...'"
            )
        model_id = self.embedder.model_id
        key = hashlib.sha256(f"{INDEX_FORMAT}\n{digest}\n{model_id}".encode()).hexdigest()
        if self._index is not None and self._index.key == key:
            return self._index
        by_id = {d.id: d for d in docs}
        passages = [p for d in docs for p in d.passages]
        texts = [indexed_text(by_id[p.document], p) for p in passages]
        digests = [hashlib.sha256(t.encode()).hexdigest() for t in texts]
        ids = [p.id for p in passages]
        cached = read_index(self.cache_dir, model_id)
        if cached is not None and cached[0] == key and cached[1] == ids and cached[2] == digests:
            embeddings = cached[3]
        else:
            reuse = {} if cached is None else dict(zip(cached[2], cached[3], strict=True))
            embeddings = self._embed(texts, digests, reuse, progress)
            write_index(self.cache_dir, key, model_id, ids, digests, embeddings)
        self._index = _Index(
            key, passages, by_id, embeddings, bm25_index([tokens(t) for t in texts])
        )
        return self._index

    def _embed(
        self,
        texts: list[str],
        digests: list[str],
        reuse: dict[str, npt.NDArray[np.float32]],
        progress: Progress | None,
    ) -> npt.NDArray[np.float32]:
        from virf.embed import DIMENSION

        out = np.zeros((len(texts), DIMENSION), dtype=np.float32)
        todo = [i for i, d in enumerate(digests) if d not in reuse]
        for i, d in enumerate(digests):
            if d in reuse:
                out[i] = reuse[d]
        if todo:
            done = 0
            if progress is not None:
                progress(0, len(todo))

            def step(n: int) -> None:
                nonlocal done
                done += n
                if progress is not None:
                    progress(done, len(todo))

            out[todo] = self.embedder.encode([texts[i] for i in todo], progress=step)
        return out

    # -- search -----------------------------------------------------------

    def search(self, query: str, k: int = 5, progress: Progress | None = None) -> list[Hit]:
        """The ``k`` best passages for ``query``, best first (scored as
        :mod:`virf.authoring.scoring` says)."""
        if not isinstance(query, str) or not query.strip():
            raise InputError("the search query is empty; give some words to search for")
        if len(query) > MAX_QUERY_CHARS:
            raise InputError(
                f"the search query has {len(query)} characters; the limit is {MAX_QUERY_CHARS}"
            )
        if k < 1:
            raise InputError(f"k (the number of results) must be at least 1, not {k}")
        index = self._current_index(progress)
        vector = self.embedder.encode([query])[0]
        dense = index.embeddings @ vector
        terms = tokens(query)
        if index.bm25 is not None and terms:
            bm25 = np.asarray(index.bm25.get_scores(terms), dtype=np.float64)
        else:
            bm25 = np.zeros(len(index.passages))
        score = fused(bm25, dense.astype(np.float64))
        order = sorted(range(len(index.passages)), key=lambda i: (-score[i], index.passages[i].id))
        return [
            Hit(
                passage=index.passages[i],
                document=index.documents[index.passages[i].document],
                score=float(score[i]),
                bm25=float(bm25[i]),
                dense=float(dense[i]),
                rank=rank,
            )
            for rank, i in enumerate(order[:k], start=1)
        ]
