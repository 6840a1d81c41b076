"""A workspace's corpus: a folder of safety documents and a cached hybrid index over their passages.

The files in the folder are the truth; everything else is derived and kept
in the cache folder, keyed by a digest of the files, so deleting the cache
only costs a rebuild:

* ``corpus-documents.json``: the documents as parsed (for listing and
  search without re-reading PDFs);
* ``retrieval-index.npz``: one all-MiniLM-L6-v2 vector per passage, with the
  passage ids and text digests it was built from.  Key: index format, corpus
  digest and model id.  When the corpus changes, vectors of passages whose
  text did not change are reused, so adding a document embeds only it.

Both are written to a temporary file and renamed into place, so a build that
is interrupted leaves the old cache or none, never half of one; a cache that
cannot be read is rebuilt.

Retrieval is hybrid.  BM25 (``rank_bm25.BM25Okapi``) finds passages sharing
the query's words, the embeddings find paraphrases that share none.  Each
score list is min-max normalised over the corpus to [0, 1] and the two are
averaged with weight 0.5 each (a list whose scores are all equal, such as
BM25's when no query word occurs anywhere, counts 0 for everyone).  This
keeps the size of the gap between passages, which reciprocal-rank fusion
would throw away, and gives a score a reader can compare across hits.  Ties
go to the smaller passage id.  A passage is indexed with its section title
(or, for an introduction, body or PDF page, its document's title) in front,
because the corpus's paragraphs often leave the topic to their heading.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import json
import os
import re
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

import numpy as np
import numpy.typing as npt

from virf.authoring.documents import (
    BODY,
    INTRODUCTION,
    PAGE,
    READERS,
    SUPPORTED,
    Document,
    Passage,
    read_document,
    read_document_bytes,
    shown,
    web_address,
)
from virf.errors import InputError, clip

if TYPE_CHECKING:
    from virf.embed import Embedder

# Bump when the files below change shape or the indexed text changes.
INDEX_FORMAT = 1
BM25_WEIGHT = 0.5
DENSE_WEIGHT = 0.5
# A question, not a document: BM25 scores each query word against every passage.
MAX_QUERY_CHARS = 2000
DOCUMENTS_CACHE = "corpus-documents.json"
INDEX_CACHE = "retrieval-index.npz"

# mkstemp makes files only their owner may read; corpus copies and caches
# are ordinary files of the workspace.
_FILE_MODE = 0o644
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
        docs = self._read_documents_cache(digest)
        if docs is None:
            docs = [read_document(self.folder / f.name) for f in files]
            self._write_documents_cache(digest, docs)
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

    def _read_documents_cache(self, digest: str) -> list[Document] | None:
        try:
            data = json.loads((self.cache_dir / DOCUMENTS_CACHE).read_text(encoding="utf-8"))
            if data["format"] != INDEX_FORMAT or data["corpus"] != digest:
                return None
            return [_document_from(d, self.folder) for d in data["documents"]]
        except (OSError, ValueError, KeyError, TypeError):
            return None  # absent or damaged: parse the files again

    def _write_documents_cache(self, digest: str, docs: list[Document]) -> None:
        data = {
            "format": INDEX_FORMAT,
            "corpus": digest,
            "documents": [_document_to(d) for d in docs],
        }
        self._write_atomic(DOCUMENTS_CACHE, json.dumps(data).encode())

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
                    os.fchmod(fh.fileno(), _FILE_MODE)
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
        cached = self._read_index_cache(model_id)
        if cached is not None and cached[0] == key and cached[1] == ids and cached[2] == digests:
            embeddings = cached[3]
        else:
            reuse = {} if cached is None else dict(zip(cached[2], cached[3], strict=True))
            embeddings = self._embed(texts, digests, reuse, progress)
            self._write_index_cache(key, model_id, ids, digests, embeddings)
        self._index = _Index(key, passages, by_id, embeddings, _bm25([_tokens(t) for t in texts]))
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

    def _read_index_cache(
        self, model_id: str
    ) -> tuple[str, list[str], list[str], npt.NDArray[np.float32]] | None:
        """(key, passage ids, text digests, vectors) of the cached index if it
        was built by this model and format; None if absent or unreadable."""
        from virf.embed import DIMENSION

        try:
            with np.load(self.cache_dir / INDEX_CACHE, allow_pickle=False) as data:
                meta = json.loads(bytes(data["meta"]).decode("utf-8"))
                vectors = np.asarray(data["embeddings"], dtype=np.float32)
            ids = [str(x) for x in meta["passages"]]
            digests = [str(x) for x in meta["digests"]]
            if (
                meta["format"] != INDEX_FORMAT
                or meta["model"] != model_id
                or vectors.shape != (len(ids), DIMENSION)
                or len(digests) != len(ids)
                or not np.all(np.isfinite(vectors))
            ):
                return None
            return str(meta["key"]), ids, digests, vectors
        except Exception:
            # Whatever a damaged or foreign file raises inside numpy's zip
            # and npy readers (BadZipFile, ValueError, EOFError, KeyError...):
            # the cache is derived, so it is rebuilt.
            return None

    def _write_index_cache(
        self,
        key: str,
        model_id: str,
        ids: list[str],
        digests: list[str],
        embeddings: npt.NDArray[np.float32],
    ) -> None:
        meta = {
            "format": INDEX_FORMAT,
            "key": key,
            "model": model_id,
            "passages": ids,
            "digests": digests,
        }
        buffer = io.BytesIO()
        np.savez(
            buffer,
            meta=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8),
            embeddings=embeddings,
        )
        self._write_atomic(INDEX_CACHE, buffer.getvalue())

    def _write_atomic(self, name: str, data: bytes) -> None:
        """Temp file + rename.  A cache that cannot be written is not an error:
        it is only rebuilt next time."""
        tmp: str | None = None
        try:
            self.cache_dir.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=self.cache_dir)
            with os.fdopen(fd, "wb") as fh:
                os.fchmod(fh.fileno(), _FILE_MODE)
                fh.write(data)
            os.replace(tmp, self.cache_dir / name)
        except OSError:
            if tmp is not None:
                with contextlib.suppress(OSError):
                    os.unlink(tmp)

    # -- search -----------------------------------------------------------

    def search(self, query: str, k: int = 5, progress: Progress | None = None) -> list[Hit]:
        """The ``k`` best passages for ``query``, best first (see the module
        docstring for the scoring)."""
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
        terms = _tokens(query)
        if index.bm25 is not None and terms:
            bm25 = np.asarray(index.bm25.get_scores(terms), dtype=np.float64)
        else:
            bm25 = np.zeros(len(index.passages))
        fused = BM25_WEIGHT * _min_max(bm25) + DENSE_WEIGHT * _min_max(dense.astype(np.float64))
        order = sorted(range(len(index.passages)), key=lambda i: (-fused[i], index.passages[i].id))
        return [
            Hit(
                passage=index.passages[i],
                document=index.documents[index.passages[i].document],
                score=float(fused[i]),
                bm25=float(bm25[i]),
                dense=float(dense[i]),
                rank=rank,
            )
            for rank, i in enumerate(order[:k], start=1)
        ]


def _min_max(scores: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    low, high = float(scores.min()), float(scores.max())
    if high - low <= 1e-12:
        return np.zeros_like(scores)
    return (scores - low) / (high - low)


def _bm25(tokenized: list[list[str]]) -> Any:
    from rank_bm25 import BM25Okapi

    if not any(tokenized):
        return None  # BM25Okapi divides by the vocabulary size
    return BM25Okapi(tokenized)


_GENERIC_SECTION = re.compile(rf"{INTRODUCTION}|{BODY}|{PAGE} \d+")


def indexed_text(document: Document, passage: Passage) -> str:
    """The text a passage is indexed under: its section title (or, where the
    section has none of its own, the document's title), then its words."""
    context = document.title if _GENERIC_SECTION.fullmatch(passage.section) else passage.section
    return f"{context}. {passage.text}"


# English function words: they carry no topic, and with min-max fusion a
# passage matching only "while" would otherwise get BM25's full half of the
# score.  Negations and "off"/"without" stay: in safety advice they matter.
_STOP = frozenset({
    "a", "about", "above", "after", "again", "against", "all", "also", "am", "an", "and",
    "any", "are", "as", "at", "be", "because", "been", "before", "being", "below", "between",
    "both", "but", "by", "can", "could", "did", "do", "does", "doing", "down", "during",
    "each", "few", "for", "from", "further", "had", "has", "have", "having", "he", "her",
    "here", "hers", "herself", "him", "himself", "his", "how", "i", "if", "in", "into", "is",
    "it", "its", "itself", "just", "may", "me", "might", "more", "most", "must", "my",
    "myself", "nor", "now", "of", "on", "once", "only", "or", "other", "our", "ours",
    "ourselves", "out", "over", "own", "same", "shall", "she", "should", "so", "some", "such",
    "than", "that", "the", "their", "theirs", "them", "themselves", "then", "there", "these",
    "they", "this", "those", "through", "to", "too", "under", "until", "up", "very", "was",
    "we", "were", "what", "when", "where", "which", "while", "who", "whom", "why", "will",
    "with", "would", "you", "your", "yours", "yourself", "yourselves",
})  # fmt: skip


def _tokens(text: str) -> list[str]:
    """Lowercase words for BM25, stop words dropped, plurals folded.

    Folding plurals by hand instead of a stemmer library (snowball, Porter):
    "fires"/"fire" and "pans"/"pan" are the mismatches household questions
    hit; deeper stemming would be a dependency for little, since the dense
    half already matches related forms."""
    return [_singular(w) for w in re.findall(r"[^\W_]+", text.lower()) if w not in _STOP]


def _singular(word: str) -> str:
    if len(word) <= 3:
        return word
    if word.endswith("ies") and len(word) > 4:
        return word[:-3] + "y"
    if word.endswith(("sses", "shes", "ches", "xes")):
        return word[:-2]
    if word.endswith("s") and not word.endswith(("ss", "us", "is")):
        return word[:-1]
    return word


def _document_to(doc: Document) -> dict[str, Any]:
    data = dataclasses.asdict(doc)
    data["path"] = Path(doc.path).name
    return data


def _document_from(data: dict[str, Any], folder: Path) -> Document:
    name = str(data["path"])
    if "/" in name or "\\" in name or name.startswith("."):
        raise ValueError("not a corpus file name")
    url = str(data["url"])
    if url and not web_address(url):
        raise ValueError("not a web address")  # not what reading the file gives: read it again
    return Document(
        id=str(data["id"]),
        title=str(data["title"]),
        publisher=str(data["publisher"]),
        url=url,
        kind=str(data["kind"]),
        path=str(folder / name),
        rooms=tuple(str(r) for r in data["rooms"]),
        topics=tuple(str(t) for t in data["topics"]),
        passages=tuple(
            Passage(
                id=str(p["id"]),
                document=str(p["document"]),
                section=str(p["section"]),
                number=int(p["number"]),
                text=str(p["text"]),
            )
            for p in data["passages"]
        ),
    )
