"""A corpus's derived files, kept in the workspace's cache folder and keyed
by a digest of the corpus files, so deleting them only costs a rebuild:

* ``corpus-documents.json``: the documents as parsed (for listing and
  search without re-reading PDFs);
* ``retrieval-index.npz``: one all-MiniLM-L6-v2 vector per passage, with the
  passage ids and text digests it was built from.  Key: index format, corpus
  digest and model id.

Both are written to a temporary file and renamed into place, so a build that
is interrupted leaves the old cache or none, never half of one; a cache that
cannot be read is treated as absent.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from virf.authoring.documents import Document, Passage, web_address

# Bump when the files below change shape or the indexed text changes.
INDEX_FORMAT = 1
DOCUMENTS_CACHE = "corpus-documents.json"
INDEX_CACHE = "retrieval-index.npz"
# mkstemp makes files only their owner may read; corpus copies and caches
# are ordinary files of the workspace.
FILE_MODE = 0o644


def read_documents(cache_dir: Path, folder: Path, digest: str) -> list[Document] | None:
    """The documents of ``folder`` as parsed when its files had ``digest``;
    None if the cache is absent, of another corpus or unreadable."""
    try:
        data = json.loads((cache_dir / DOCUMENTS_CACHE).read_text(encoding="utf-8"))
        if data["format"] != INDEX_FORMAT or data["corpus"] != digest:
            return None
        return [_document_from(d, folder) for d in data["documents"]]
    except (OSError, ValueError, KeyError, TypeError):
        return None  # absent or damaged: parse the files again


def write_documents(cache_dir: Path, digest: str, docs: list[Document]) -> None:
    data = {
        "format": INDEX_FORMAT,
        "corpus": digest,
        "documents": [_document_to(d) for d in docs],
    }
    _write_atomic(cache_dir, DOCUMENTS_CACHE, json.dumps(data).encode())


def read_index(
    cache_dir: Path, model_id: str
) -> tuple[str, list[str], list[str], npt.NDArray[np.float32]] | None:
    """(key, passage ids, text digests, vectors) of the cached index if it
    was built by this model and format; None if absent or unreadable."""
    from virf.embed import DIMENSION

    try:
        with np.load(cache_dir / INDEX_CACHE, allow_pickle=False) as data:
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


def write_index(
    cache_dir: Path,
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
    _write_atomic(cache_dir, INDEX_CACHE, buffer.getvalue())


def _write_atomic(cache_dir: Path, name: str, data: bytes) -> None:
    """Temp file + rename.  A cache that cannot be written is not an error:
    it is only rebuilt next time."""
    tmp: str | None = None
    try:
        cache_dir.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=cache_dir)
        with os.fdopen(fd, "wb") as fh:
            os.fchmod(fh.fileno(), FILE_MODE)
            fh.write(data)
        os.replace(tmp, cache_dir / name)
    except OSError:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


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
