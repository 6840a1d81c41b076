"""One safety document read into passages: the units retrieval returns and drafts cite.

Formats: Markdown (with an optional ``---`` front matter of ``key: value``
lines, as in the starter corpus), plain text, HTML and PDF.  Every format is
first cut into headings and paragraphs; one builder then makes the passages,
so the rules are the same for all of them:

* a section is a heading's span (Markdown ``#``..``###`` after the title,
  HTML h1-h3, a plain-text heading line, a PDF page); text before the first
  heading is the "Introduction" section, or "Body" when there is no heading;
* a passage is a paragraph; paragraphs under 12 words join the next one of
  their section, paragraphs over 180 words are cut at sentence ends into
  pieces of about 150 words;
* a passage id is ``<document-id>:<section-slug>:<n>``, n counting from 1
  within the section; a repeated section slug gets ``-2``, ``-3``.
"""

from __future__ import annotations

import hashlib
import io
import logging
import math
import re
import unicodedata
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal
from urllib.parse import urlsplit

from virf.errors import (
    MAX_FILE_BYTES,
    InputError,
    clip,
    closest,
    printable,
    read_input_bytes,
    read_input_file,
)

if TYPE_CHECKING:
    from bs4 import BeautifulSoup, Tag
    from markdown_it.token import Token

READERS: dict[str, str] = {
    ".md": "markdown",
    ".markdown": "markdown",
    ".txt": "text",
    ".html": "html",
    ".htm": "html",
    ".pdf": "pdf",
}
SUPPORTED = "Markdown (.md, .markdown), plain text (.txt), HTML (.html, .htm) or PDF (.pdf)"

FRONT_MATTER_KEYS = ("id", "title", "publisher", "url", "rooms", "topics", "kind")
INTRODUCTION = "Introduction"
BODY = "Body"
PAGE = "Page"  # PDF sections: "Page 3", slug "page-3"
# Without front matter a document is taken to be the source itself, as
# opposed to the starter corpus's summaries ("kind: summary").
DEFAULT_KIND = "source"

TINY_WORDS = 12
SPLIT_ABOVE_WORDS = 180
TARGET_WORDS = 150
# Far more than a real safety document has; a bound on what one file may
# cost to embed.
MAX_PASSAGES = 20_000
_ID = re.compile(r"[a-z0-9]+(?:-[a-z0-9]+)*")


@dataclass(frozen=True)
class Passage:
    id: str
    document: str
    section: str
    number: int
    text: str


@dataclass(frozen=True)
class Document:
    id: str
    title: str
    publisher: str
    url: str
    kind: str
    path: str
    rooms: tuple[str, ...]
    topics: tuple[str, ...]
    passages: tuple[Passage, ...]


def slug(text: str, limit: int = 60) -> str:
    """Lowercase-kebab ASCII: "Grease fires!" -> "grease-fires"; '' if nothing is left."""
    ascii_text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode("ascii")
    out = re.sub(r"[^a-z0-9]+", "-", ascii_text.lower()).strip("-")
    if len(out) > limit:
        out = out[:limit].rsplit("-", 1)[0] if "-" in out[:limit] else out[:limit]
    return out


def shown(path: Path | str, limit: int = 80) -> str:
    """A path for a one-line message: printable, and shortened at the front
    so that the file name, the part that matters, survives."""
    text = printable(str(path))
    return text if len(text) <= limit else "..." + text[-(limit - 3) :]


def web_address(url: str) -> bool:
    """Whether ``url`` is an absolute http(s) address with a host: the only
    kind of address a document may give (a ``javascript:`` or ``data:`` one
    would run in the review page were it a link)."""
    try:
        parts = urlsplit(url)
    except ValueError:
        return False
    return parts.scheme.lower() in ("http", "https") and bool(parts.hostname)


def document_id_for(path: Path) -> str:
    """The id of a document without front matter: its file stem as a slug."""
    return slug(path.stem) or "document-" + hashlib.sha256(path.stem.encode()).hexdigest()[:8]


def read_document(path: Path) -> Document:
    """Read one document file; any problem is one InputError line naming the file."""
    kind = READERS.get(path.suffix.lower())
    if kind is None:
        ext = path.suffix or "no extension"
        raise InputError(f"cannot read {shown(path)}: unsupported kind ({ext}); use {SUPPORTED}")
    reader: Callable[[Path], _Parsed] = {
        "markdown": _read_markdown,
        "text": _read_text,
        "html": _read_html,
        "pdf": _read_pdf,
    }[kind]
    parsed = reader(path)
    meta = parsed.meta
    given = _one_line(meta.get("url", ""))
    if given and not web_address(given):
        # Shown as a link on the review page and written into every rule's
        # :source that cites the document: only a page's address.
        raise InputError(
            f"document {shown(path)}: url '{clip(given)}' is not a web address; give the "
            "page's http:// or https:// address, or leave url out"
        )
    doc_id = meta.get("id") or document_id_for(path)
    passages = _passages(doc_id, parsed.blocks)
    if not passages:
        raise InputError(f"document {shown(path)} has no text to index")
    if len(passages) > MAX_PASSAGES:
        raise InputError(
            f"document {shown(path)} has {len(passages)} passages; the limit is {MAX_PASSAGES}"
        )
    return Document(
        id=doc_id,
        title=_one_line(meta.get("title") or parsed.title or path.stem),
        publisher=_one_line(meta.get("publisher") or parsed.publisher),
        url=_one_line(meta.get("url") or parsed.url),
        kind=_one_line(meta.get("kind") or DEFAULT_KIND),
        path=str(path),
        rooms=_list(meta.get("rooms", "")),
        topics=_list(meta.get("topics", "")),
        passages=tuple(passages),
    )


# ---------------------------------------------------------------------------
# What the format readers produce: headings and paragraphs in order.


@dataclass(frozen=True)
class _Block:
    kind: Literal["heading", "paragraph", "page"]
    text: str


@dataclass
class _Parsed:
    blocks: list[_Block]
    meta: dict[str, str] = field(default_factory=dict)
    title: str = ""
    publisher: str = ""
    url: str = ""


def _one_line(text: str) -> str:
    return " ".join(text.split())


def _list(value: str) -> tuple[str, ...]:
    return tuple(item for item in (_one_line(v).lower() for v in value.split(",")) if item)


def _front_matter(text: str, path: Path) -> tuple[dict[str, str], str]:
    """The ``---`` header's fields and the text after it.

    Only flat ``key: value`` lines with the starter corpus's keys: YAML would
    be a dependency for seven string fields, and an unknown key is more likely
    a typo than something to keep."""
    lines = text.split("\n")
    if not lines or lines[0].strip() != "---":
        return {}, text
    try:
        end = next(i for i in range(1, len(lines)) if lines[i].strip() == "---")
    except StopIteration:
        raise InputError(
            f"document {shown(path)}: the front matter opened by '---' on line 1 is never closed"
        ) from None
    meta: dict[str, str] = {}
    for number, line in enumerate(lines[1:end], start=2):
        if not line.strip():
            continue
        key, sep, value = line.partition(":")
        key = key.strip().lower()
        where = f"document {shown(path)} line {number}"
        if not sep or not key:
            raise InputError(f"{where}: front matter takes 'key: value' lines, not '{clip(line)}'")
        if key not in FRONT_MATTER_KEYS:
            near = closest(key, FRONT_MATTER_KEYS)
            hint = f"closest: {', '.join(near)}; " if near else ""
            raise InputError(
                f"{where}: unknown front-matter key '{clip(key)}'; {hint}"
                f"known: {', '.join(FRONT_MATTER_KEYS)}"
            )
        if key in meta:
            raise InputError(f"{where}: front-matter key '{key}' is given twice")
        meta[key] = value.strip()
    doc_id = meta.get("id")
    if doc_id is not None and (not _ID.fullmatch(doc_id) or len(doc_id) > 80):
        fix = slug(doc_id, 80)
        hint = f", e.g. '{fix}'" if fix else ""
        raise InputError(
            f"document {shown(path)}: id '{clip(doc_id)}' must be lowercase letters, digits "
            f"and single '-' (at most 80 characters){hint}"
        )
    return meta, "\n".join(lines[end + 1 :])


def _read_markdown(path: Path) -> _Parsed:
    from markdown_it import MarkdownIt

    meta, body = _front_matter(read_input_file(path, "document", MAX_FILE_BYTES), path)
    tokens = MarkdownIt("commonmark").enable("table").parse(body)
    blocks: list[_Block] = []
    title = ""
    row: list[str] = []
    heading_level = 0
    for i, token in enumerate(tokens):
        if token.type == "heading_open":
            heading_level = int(token.tag[1])
        elif token.type == "inline" and heading_level:
            text = _inline_text(token.children or [])
            # The document's first line as "# Title" names it; later "#"
            # headings and "##", "###" start sections; "####" and below are
            # too fine to split at and read as short paragraphs.
            if not text:
                pass  # an empty heading ("##" alone) starts nothing
            elif heading_level == 1 and not title and not blocks:
                title = text
            elif heading_level <= 3:
                blocks.append(_Block("heading", text))
            else:
                blocks.append(_Block("paragraph", text))
            heading_level = 0
        elif token.type == "tr_open":
            row = []
        elif token.type == "inline" and _inside(tokens, i, "td_open", "th_open"):
            row.append(_inline_text(token.children or []))
        elif token.type == "tr_close":
            blocks.append(_Block("paragraph", " | ".join(c for c in row if c)))
        elif token.type == "inline":
            blocks.append(_Block("paragraph", _inline_text(token.children or [])))
        elif token.type in ("fence", "code_block"):
            blocks.append(_Block("paragraph", token.content))
        elif token.type == "html_block":
            blocks.append(_Block("paragraph", _html_text(token.content)))
    return _Parsed(blocks, meta, title=title)


def _inside(tokens: list[Token], i: int, *openers: str) -> bool:
    return i > 0 and tokens[i - 1].type in openers


def _inline_text(children: list[Token]) -> str:
    """An inline run's words without its markup (emphasis, link targets, code ticks)."""
    parts: list[str] = []
    for child in children:
        kind = child.type
        if kind in ("text", "code_inline", "image"):
            # an image's content is its alt text
            parts.append(child.content)
        elif kind in ("softbreak", "hardbreak", "html_inline"):
            parts.append(" ")
    return _one_line("".join(parts))


def _html_text(fragment: str) -> str:
    from bs4 import BeautifulSoup

    return _one_line(BeautifulSoup(fragment, "html.parser").get_text(" "))


def _read_text(path: Path) -> _Parsed:
    meta, body = _front_matter(read_input_file(path, "document", MAX_FILE_BYTES), path)
    chunks = [c for c in re.split(r"\n[ \t]*\n", body.replace("\r\n", "\n")) if c.strip()]
    blocks: list[_Block] = []
    title = ""
    for i, chunk in enumerate(chunks):
        following = chunks[i + 1] if i + 1 < len(chunks) else ""
        if _heading_like(chunk, following):
            line = _one_line(chunk.strip().splitlines()[0])
            if i == 0 and not title:
                title = line
            else:
                blocks.append(_Block("heading", line))
        else:
            blocks.append(_Block("paragraph", chunk))
    return _Parsed(blocks, meta, title=title)


def _heading_like(chunk: str, following: str) -> bool:
    """A plain-text heading: one short line (at most 10 words) that starts with
    a capital or a digit, ends without sentence punctuation, and is followed by
    a real paragraph; or a line underlined with '===' or '---'."""
    lines = [ln for ln in chunk.strip().splitlines() if ln.strip()]
    if len(lines) == 2 and re.fullmatch(r"\s*(=+|-+)\s*", lines[1]):
        return True
    if len(lines) != 1:
        return False
    line = lines[0].strip()
    words = line.split()
    return (
        0 < len(words) <= 10
        and (line[0].isupper() or line[0].isdigit())
        and line[-1] not in ".,;!?"
        and len(following.split()) >= TINY_WORDS
    )


# Elements whose text is page furniture, not the document's content.
_DROP = (
    "script", "style", "noscript", "template", "svg", "iframe", "object", "canvas",
    "nav", "footer", "aside", "form", "button", "select", "head",
)  # fmt: skip
_SECTION_TAGS = frozenset({"h1", "h2", "h3"})
_BLOCK_TAGS = frozenset({
    "p", "div", "section", "article", "main", "header", "li", "ul", "ol", "dl", "dt", "dd",
    "blockquote", "pre", "table", "thead", "tbody", "tfoot", "tr", "td", "th", "caption",
    "figure", "figcaption", "h4", "h5", "h6", "address", "details", "summary", "hr", "center",
})  # fmt: skip


def _read_html(path: Path) -> _Parsed:
    from bs4 import BeautifulSoup

    raw = read_document_bytes(path)
    # Bytes, not text: BeautifulSoup honours the page's declared charset.
    soup = BeautifulSoup(raw, "html.parser")
    title = _one_line(soup.title.get_text(" ")) if soup.title else ""
    publisher = _meta(soup, "og:site_name") or _meta(soup, "author")
    # The page's own address, when it states one that is a web address (a
    # relative or "javascript:" one is dropped: the page's markup is not the
    # user's word, as a front matter's url is).
    url = next((u for u in (_link_canonical(soup), _meta(soup, "og:url")) if web_address(u)), "")
    for tag in soup.find_all(list(_DROP)):
        tag.decompose()
    root = soup.find("main") or soup.find("article") or soup.find("body") or soup
    blocks = list(_html_blocks(root))
    if not title:
        title = next((b.text for b in blocks if b.kind == "heading"), "")
    return _Parsed(blocks, title=title, publisher=publisher, url=url)


def _meta(soup: BeautifulSoup, name: str) -> str:
    from bs4 import Tag

    tag = soup.find("meta", attrs={"property": name}) or soup.find("meta", attrs={"name": name})
    value = tag.get("content") if isinstance(tag, Tag) else None
    return _one_line(value) if isinstance(value, str) else ""


def _link_canonical(soup: BeautifulSoup) -> str:
    from bs4 import Tag

    tag = soup.find("link", rel="canonical")
    value = tag.get("href") if isinstance(tag, Tag) else None
    return _one_line(value) if isinstance(value, str) else ""


def _html_blocks(root: Tag) -> Iterator[_Block]:
    """Headings and paragraphs in document order.

    BeautifulSoup gives the tree, not the reading blocks, hence this walk: text
    joins the open paragraph until a block element starts or ends.  It keeps
    its own stack instead of recursing, so a deeply nested page cannot
    exhaust Python's recursion limit."""
    from bs4 import Tag
    from bs4.element import NavigableString, PreformattedString

    buffer: list[str] = []

    def flush() -> Iterator[_Block]:
        text = _one_line("".join(buffer))
        buffer.clear()
        if text:
            yield _Block("paragraph", text)

    stack: list[tuple[object, bool]] = [(child, True) for child in reversed(list(root.children))]
    while stack:
        node, entering = stack.pop()
        if isinstance(node, NavigableString):
            if not isinstance(node, PreformattedString):  # comments, doctype, CDATA
                buffer.append(str(node))
            continue
        if not isinstance(node, Tag):
            continue
        name = node.name.lower()
        if name in _SECTION_TAGS:
            yield from flush()
            text = _one_line(node.get_text(" "))
            if text:
                yield _Block("heading", text)
        elif name == "br":
            buffer.append(" ")
        elif name in _BLOCK_TAGS:
            yield from flush()
            if entering:
                stack.append((node, False))
                stack.extend((child, True) for child in reversed(list(node.children)))
        else:  # inline: a, span, strong, em...
            stack.extend((child, True) for child in reversed(list(node.children)))
    yield from flush()


def read_document_bytes(path: Path) -> bytes:
    """A document's bytes, with the checks every user file gets (regular file, size)."""
    return read_input_bytes(path, "document", MAX_FILE_BYTES)


def _read_pdf(path: Path) -> _Parsed:
    from pypdf import PdfReader
    from pypdf.errors import PyPdfError

    raw = read_document_bytes(path)
    name = shown(path)
    logger = logging.getLogger("pypdf")
    level = logger.level
    # pypdf logs a warning for every repaired defect; the user gets one line
    # from us instead (or nothing, when the text came out).
    logger.setLevel(logging.ERROR)
    try:
        reader = PdfReader(io.BytesIO(raw))
        if reader.is_encrypted:
            try:
                opened = bool(reader.decrypt(""))
            except (PyPdfError, NotImplementedError, ValueError):
                opened = False
            if not opened:
                raise InputError(
                    f"PDF {name} is encrypted; save an unprotected copy, or the text as {SUPPORTED}"
                )
        pages = [page.extract_text() or "" for page in reader.pages]
        info = reader.metadata
        title = str(info.title or "") if info else ""
        author = str(info.author or "") if info else ""
    except InputError:
        raise
    except (
        PyPdfError, ValueError, KeyError, TypeError, IndexError, AttributeError,
        AssertionError, ZeroDivisionError, RecursionError, OSError, EOFError,
    ):  # fmt: skip
        # pypdf's own errors and the Python ones a malformed file raises inside it
        raise InputError(f"cannot read PDF {name}: the file is damaged or not a PDF") from None
    finally:
        logger.setLevel(level)
    if not pages:
        raise InputError(f"PDF {name} has no pages")
    if not any(p.strip() for p in pages):
        raise InputError(
            f"PDF {name} has no extractable text (a scanned image?); "
            f"give its text as {SUPPORTED} instead"
        )
    blocks: list[_Block] = []
    for number, text in enumerate(pages, start=1):
        blocks.append(_Block("page", f"{PAGE} {number}"))
        text = text.replace("\u00ad\n", "").replace("-\n", "-")
        blocks.extend(_Block("paragraph", c) for c in re.split(r"\n[ \t]*\n", text) if c.strip())
    # The /Author of a PDF is the nearest thing it records to a publisher.
    return _Parsed(blocks, title=_one_line(title), publisher=_one_line(author))


# ---------------------------------------------------------------------------
# Blocks to passages.


def _passages(doc_id: str, blocks: list[_Block]) -> list[Passage]:
    has_headings = any(b.kind in ("heading", "page") for b in blocks)
    sections: list[tuple[str, list[str]]] = [(INTRODUCTION if has_headings else BODY, [])]
    for block in blocks:
        if block.kind in ("heading", "page"):
            sections.append((block.text, []))
        else:
            text = _one_line(block.text)
            if text:
                sections[-1][1].append(text)
    out: list[Passage] = []
    used: set[str] = set()
    for title, paragraphs in sections:
        pieces = [p for merged in _merge_tiny(paragraphs) for p in _split_long(merged)]
        if not pieces:
            continue
        base = slug(title) or "section"
        section_slug, n = base, 1
        while section_slug in used:
            n += 1
            section_slug = f"{base}-{n}"
        used.add(section_slug)
        out.extend(
            Passage(f"{doc_id}:{section_slug}:{i}", doc_id, title, i, text)
            for i, text in enumerate(pieces, start=1)
        )
    return out


def _words(text: str) -> int:
    return len(text.split())


def _merge_tiny(paragraphs: list[str]) -> list[str]:
    """Paragraphs under TINY_WORDS join the next one; trailing ones the last."""
    out: list[str] = []
    pending: list[str] = []
    for p in paragraphs:
        pending.append(p)
        if _words(p) >= TINY_WORDS or sum(map(_words, pending)) >= TINY_WORDS:
            out.append(" ".join(pending))
            pending = []
    if pending:
        if out:
            out[-1] = out[-1] + " " + " ".join(pending)
        else:
            out.append(" ".join(pending))
    return out


# A sentence ends at . ! or ? (maybe with a closing quote or bracket) before
# a space and a capital, digit or opening quote.  Hand-written because a
# trained splitter (nltk punkt, spaCy) is a heavy dependency for cutting
# the rare over-long paragraph; a wrong cut only moves a passage boundary.
_SENTENCE_END = re.compile(r"(?:(?<=[.!?])|(?<=[.!?][\"')\]]))\s+(?=[\"'(\[]?[A-Z0-9])")


def _split_long(paragraph: str) -> list[str]:
    total = _words(paragraph)
    if total <= SPLIT_ABOVE_WORDS:
        return [paragraph]
    target = total / math.ceil(total / TARGET_WORDS)
    sentences: list[str] = []
    for sentence in _SENTENCE_END.split(paragraph):
        words = sentence.split()
        # A "sentence" without any end (a PDF's run-on text) is cut by words.
        for start in range(0, len(words), TARGET_WORDS):
            sentences.append(" ".join(words[start : start + TARGET_WORDS]))
    pieces: list[str] = []
    current: list[str] = []
    count = 0
    for sentence in sentences:
        n = _words(sentence)
        # Close the piece when the next sentence takes it further from the target.
        if current and abs(count + n - target) > abs(count - target):
            pieces.append(" ".join(current))
            current, count = [], 0
        current.append(sentence)
        count += n
    if current:
        pieces.append(" ".join(current))
    return pieces
