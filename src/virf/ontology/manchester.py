"""Manchester syntax, read and written in one place.

Reading: the little of a class expression a drafted axiom needs before OWLAPI
sees it (which names it uses, in which role, and the same expression with
names replaced), and the header of a module document (its IRI and imports).  OWLAPI's parser
stays the judge of whether a text parses; this only finds the names, so they
can be matched to the vocabulary first.

Writing: module documents (prefixes, the ontology header), frames with their
sections and annotations, and literals.  The generated kitchen module and a
knowledge workspace's layer modules are written with it, so quoting and
layout are decided once.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Final, Literal

from virf.errors import InputError, clip
from virf.ontology.iri import NS, OWL

KEYWORDS: Final = frozenset(
    {
        "and",
        "or",
        "not",
        "some",
        "only",
        "value",
        "min",
        "max",
        "exactly",
        "that",
        "inverse",
        "Self",
    }
)
# A property name stands right before one of these (or after ``inverse``).
_RESTRICTIONS: Final = frozenset({"some", "only", "value", "min", "max", "exactly", "Self"})
_TOKEN: Final = re.compile(
    r"\s*(?:(?P<name>[A-Za-z_][A-Za-z0-9_\-]*(?::[A-Za-z_][A-Za-z0-9_\-]*)?|:[A-Za-z_][A-Za-z0-9_\-]*)"
    r"|(?P<number>[0-9]+)|(?P<punct>[(){},])|(?P<bad>\S))"
)
MAX_AXIOM_CHARS: Final = 4000
# OWL's own top and bottom classes, which Manchester writes without a prefix.
BUILTIN: Final = {"Thing": "owl:Thing", "Nothing": "owl:Nothing"}

Role = Literal["class", "property", "individual"]


@dataclass(frozen=True)
class Token:
    kind: Literal["name", "keyword", "number", "punct"]
    text: str


def tokens(expression: str) -> list[Token]:
    """The tokens of a class expression; names lose any ``prefix:``."""
    if len(expression) > MAX_AXIOM_CHARS:
        raise InputError(f"axiom is longer than {MAX_AXIOM_CHARS} characters")
    out: list[Token] = []
    for m in _TOKEN.finditer(expression):
        if m.group("bad") is not None:
            raise InputError(
                f"axiom has an unexpected character '{clip(m.group('bad'))}' in "
                f"'{clip(expression)}'; write a Manchester class expression such as "
                "Microwave and (hasState some OnState)"
            )
        if m.group("name") is not None:
            prefix, _, text = m.group("name").rpartition(":")
            if prefix and f"{prefix}:{text}" not in ("owl:Thing", "owl:Nothing"):
                raise InputError(
                    f"axiom uses '{clip(m.group('name'))}': write the ontology's own names "
                    "without a prefix (Microwave, hasState)"
                )
            out.append(Token("keyword" if text in KEYWORDS else "name", text))
        elif m.group("number") is not None:
            out.append(Token("number", m.group("number")))
        elif m.group("punct") is not None:
            out.append(Token("punct", m.group("punct")))
    if not out:
        raise InputError("axiom is empty; write a Manchester class expression")
    _balanced(out, expression)
    return out


def _balanced(toks: list[Token], expression: str) -> None:
    """Unbalanced brackets found here name the problem in the reviewer's own
    text; OWLAPI would point into the module the axiom was wrapped in."""
    depth: list[str] = []
    pairs = {")": "(", "}": "{"}
    for tok in toks:
        if tok.kind != "punct" or tok.text == ",":
            continue
        if tok.text in "({":
            depth.append(tok.text)
        elif not depth or depth.pop() != pairs[tok.text]:
            raise InputError(f"axiom has an unmatched '{tok.text}' in '{clip(expression)}'")
    if depth:
        raise InputError(f"axiom has an unclosed '{depth[-1]}' in '{clip(expression)}'")


def names(expression: str) -> dict[str, Role]:
    """Each name the expression uses, with the role its position gives it."""
    toks = tokens(expression)
    roles: dict[str, Role] = {}
    in_braces = False
    for i, tok in enumerate(toks):
        if tok.kind == "punct" and tok.text in "{}":
            in_braces = tok.text == "{"
            continue
        if tok.kind != "name" or tok.text in BUILTIN:
            continue
        nxt = toks[i + 1] if i + 1 < len(toks) else None
        prev = toks[i - 1] if i > 0 else None
        role: Role
        if (nxt is not None and nxt.kind == "keyword" and nxt.text in _RESTRICTIONS) or (
            prev is not None and prev.kind == "keyword" and prev.text == "inverse"
        ):
            role = "property"
        elif in_braces or (prev is not None and prev.kind == "keyword" and prev.text == "value"):
            role = "individual"
        else:
            role = "class"
        roles.setdefault(tok.text, role)
    return roles


def render(expression: str, rename: Mapping[str, str] | None = None, prefix: str = "") -> str:
    """The expression on one line, names renamed and given ``prefix``."""
    rename = rename or {}
    parts: list[str] = []
    for tok in tokens(expression):
        text = tok.text
        if tok.kind == "name" and text in BUILTIN and text not in rename:
            text = BUILTIN[text]
        elif tok.kind == "name":
            text = prefix + rename.get(text, text)
        if parts and (tok.text in ")}," or parts[-1] in ("(", "{")):
            parts[-1] += text
        else:
            parts.append(text)
    return " ".join(parts).replace(" ,", ",")


def shape(expression: str) -> tuple[str, ...]:
    """The expression with every name blanked: two axioms of the same shape
    differ only in the names they use (an edit that aligns names is minor)."""
    return tuple("N" if t.kind == "name" else t.text for t in tokens(expression))


def conjuncts(expression: str, prefix: str = "") -> list[str]:
    """The parts of a top-level conjunction, each on one line with names given
    ``prefix`` (``A and (p value v)`` -> ``['A', '(p value v)']``); the whole
    expression when it is not one."""
    parts: list[list[Token]] = [[]]
    for tok, depth in _depths(tokens(expression)):
        if depth == 0 and tok.kind == "keyword" and tok.text == "and":
            parts.append([])
            continue
        parts[-1].append(tok)
    if any(not p for p in parts) or any(
        t.kind == "keyword" and t.text in ("or", "that") and d == 0
        for p in parts
        for t, d in _depths(p)
    ):
        return [render(expression, prefix=prefix)]
    return [render(" ".join(t.text for t in p), prefix=prefix) for p in parts]


def _depths(toks: list[Token]) -> list[tuple[Token, int]]:
    out = []
    depth = 0
    for tok in toks:
        if tok.kind == "punct" and tok.text in "({":
            depth += 1
        elif tok.kind == "punct" and tok.text in ")}":
            depth -= 1
        out.append((tok, depth))
    return out


# ---------------------------------------------------------------------- documents, read
# A module names itself and its imports first, before any frame:
# 'Ontology: <IRI> [<version IRI>]', then one 'Import: <IRI>' a line.
_ONTOLOGY: Final = re.compile(r"^Ontology:\s*<([^>]*)>", re.MULTILINE)
_IMPORT: Final = re.compile(r"\s*Import:\s*<([^>]*)>\s*$")
_FRAME: Final = re.compile(r"\s*[A-Za-z]+:")


@dataclass(frozen=True)
class Header:
    """What a module document's header says: its IRI and the IRIs it imports."""

    iri: str
    imports: tuple[str, ...]


def header_of(document: str, name: str) -> Header:
    """The header of a module document (``name``, its file, is what an error
    names); ValueError when it has no ``Ontology: <IRI>`` or a header line
    that is neither an import, a comment nor the start of what follows."""
    found = _ONTOLOGY.search(document)
    if found is None:
        raise ValueError(f"{name} has no 'Ontology: <IRI>' header")
    imports = []
    for line in document[found.end() :].splitlines()[1:]:
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        hit = _IMPORT.match(line)
        if hit is None:
            if _FRAME.match(line):
                break  # the imports are over: annotations or the first frame
            raise ValueError(f"{name}: cannot read the header line {line.strip()!r}")
        imports.append(hit.group(1))
    return Header(found.group(1), tuple(imports))


# ---------------------------------------------------------------------- documents, written
PREFIXES: Final = (
    ("", NS),
    ("owl", OWL),
    ("rdf", "http://www.w3.org/1999/02/22-rdf-syntax-ns#"),
    ("rdfs", "http://www.w3.org/2000/01/rdf-schema#"),
    ("xsd", "http://www.w3.org/2001/XMLSchema#"),
)
# The frame keyword that declares a name in the role an expression gives it.
FRAME_OF_ROLE: Final[Mapping[Role, str]] = {
    "class": "Class",
    "property": "ObjectProperty",
    "individual": "Individual",
}
_INDENT: Final = "    "
# An annotation as (property, text): the property a name of ours ("id") or a
# prefixed one ("rdfs:comment"), the text written as a string literal.
Annotation = tuple[str, str]


def literal(text: str) -> str:
    """``text`` as a string literal."""
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def term(name: str) -> str:
    """A name of ours with the empty prefix (``Pot`` -> ``:Pot``); a name
    that already has a prefix (``rdfs:comment``, ``owl:Thing``) as it is."""
    return name if ":" in name else f":{name}"


def value(prop: str, individual: str) -> str:
    """``:prop value :individual``."""
    return f"{term(prop)} value {term(individual)}"


def some(prop: str, filler: str) -> str:
    """``:prop some (filler)``, ``filler`` a written class expression."""
    return f"{term(prop)} some ({filler})"


def prefixes() -> str:
    """The prefix declarations a module starts with, one a line."""
    return "".join(f"Prefix: {p}: <{iri}>\n" for p, iri in PREFIXES)


def annotation_list(annotations: Iterable[Annotation]) -> str:
    """Annotations on one line: ``:id "X", rdfs:comment "Y"``."""
    return ", ".join(f"{term(p)} {literal(text)}" for p, text in annotations)


def annotations_section(pairs: Sequence[Annotation], *, one_line: bool = False) -> str:
    """A frame's ``Annotations:`` section: on the keyword's line, or one
    annotation a line below it."""
    if one_line:
        return f"{_INDENT}Annotations: {annotation_list(pairs)}"
    lines = ",\n".join(f"{_INDENT * 2}{term(p)} {literal(text)}" for p, text in pairs)
    return f"{_INDENT}Annotations:\n{lines}"


@dataclass(frozen=True)
class Axiom:
    """A written class expression in a frame's section, with the annotations
    of the axiom it makes (its id, comment and source)."""

    expression: str
    annotations: tuple[Annotation, ...] = ()

    def written(self, indent: str) -> str:
        if not self.annotations:
            return f"{indent}{self.expression}"
        return (
            f"{indent}Annotations: {annotation_list(self.annotations)}\n{indent}{self.expression}"
        )


def section(keyword: str, axioms: Sequence[Axiom | str], *, one_line: bool = False) -> str:
    """A frame's section (``SubClassOf:``, ``EquivalentTo:``, ``Types:``): its
    expressions on the keyword's line (none annotated), or one a line below it."""
    items = [Axiom(a) if isinstance(a, str) else a for a in axioms]
    if one_line:
        if any(a.annotations for a in items):
            raise ValueError(f"an annotated axiom of {keyword} needs a line of its own")
        return f"{_INDENT}{keyword}: " + ", ".join(a.expression for a in items)
    return f"{_INDENT}{keyword}:\n" + ",\n".join(a.written(_INDENT * 2) for a in items)


def frame(keyword: str, name: str, *sections: str) -> str:
    """A frame (``Class: :Pot``) and its sections, each as written by
    :func:`annotations_section` or :func:`section`."""
    return "\n".join([f"{keyword}: {term(name)}", *sections])


def axiom_frame(keyword: str, axiom: Axiom) -> str:
    """A frame that is one axiom (``DisjointClasses:``), its annotations and
    expression indented below the keyword."""
    return f"{keyword}:\n{axiom.written(_INDENT)}"


def ontology(iri: str, imports: Sequence[str] = (), annotations: Sequence[Annotation] = ()) -> str:
    """The ontology header: its IRI, its imports and its annotations."""
    lines = [f"Ontology: <{iri}>", *(f"{_INDENT}Import: <{i}>" for i in imports)]
    if annotations:
        lines.append(annotations_section(annotations))
    return "\n".join(lines)


def document(
    iri: str,
    imports: Sequence[str],
    annotations: Sequence[Annotation],
    *body: str,
) -> str:
    """A whole module: prefixes, its header, a blank line, then ``body``."""
    return "\n".join([prefixes(), ontology(iri, imports, annotations), "", *body])
