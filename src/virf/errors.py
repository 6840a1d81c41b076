"""Errors that reach users.  Each carries one line that names the problem."""

from __future__ import annotations

import difflib
import json
import unicodedata
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType, UnionType
from typing import Annotated, Any, ClassVar, Final, Self, Union, get_args, get_origin

from pydantic import BaseModel, ConfigDict, ValidationError


class VirfError(Exception):
    """Base class for errors VIRF reports to a user without a traceback."""


class InputError(VirfError):
    """The user's scene, plan or option is malformed or names an unknown term."""


class EnvironmentProblem(VirfError):
    """Something outside VIRF is missing (Java, the reasoner jars)."""


def closest(term: str, choices: Iterable[str], n: int = 3) -> list[str]:
    """The nearest known names to ``term``, case-insensitively, best first."""
    pool = sorted(set(choices))
    lowered = {c.lower(): c for c in pool}
    hits = difflib.get_close_matches(term.lower(), list(lowered), n=n, cutoff=0.5)
    return [lowered[h] for h in hits]


# Control, format (zero-width, bidi overrides), separator, surrogate, private
# and unassigned characters: invisible or able to break a message's one line or
# rewrite the terminal it is printed on.
_HIDDEN = frozenset({"Cc", "Cf", "Zl", "Zp", "Cs", "Co", "Cn"})


def hidden_char(text: str) -> str | None:
    """The first character of ``text`` that is not visible text, if any (tab counts as space)."""
    for ch in text:
        if ch != "\t" and unicodedata.category(ch) in _HIDDEN:
            return ch
    return None


def printable(text: str) -> str:
    """``text`` with every hidden character escaped (``\\x1b``, ``\\u200b``),
    so a message stays one line and cannot drive the terminal."""
    return "".join(
        _escape(ch) if ch != "\t" and unicodedata.category(ch) in _HIDDEN else ch for ch in text
    )


def _escape(ch: str) -> str:
    code = ord(ch)
    if code < 0x100:
        return f"\\x{code:02x}"
    return f"\\u{code:04x}" if code < 0x10000 else f"\\U{code:08x}"


def clip(term: str, limit: int = 60) -> str:
    """A user's term, shortened and made printable for a one-line message."""
    return printable(term if len(term) <= limit else term[: limit - 3] + "...")


def unknown_term(kind: str, term: str, choices: Iterable[str]) -> InputError:
    near = closest(term[:200], choices)
    hint = f"; closest known: {', '.join(near)}" if near else ""
    return InputError(f"unknown {kind} '{clip(term)}'{hint}")


# The largest user file VIRF reads (scenes, plans, answers, replays, benchmark
# files): far above any real input, far below what would exhaust memory.
MAX_FILE_BYTES = 32 * 1024 * 1024


def read_input_bytes(path: str | Path, what: str, limit: int = MAX_FILE_BYTES) -> bytes:
    """Read a user's file as bytes, turning I/O failures into one-line input errors.

    Only regular files are read, and at most ``limit`` bytes: a FIFO would block
    forever and a device such as /dev/zero would never end."""
    p = Path(path)
    try:
        if not p.exists():
            raise InputError(f"{what} file not found: {printable(str(p))}")
        if not p.is_file():
            raise InputError(f"{what} path {printable(str(p))} is not a regular file")
        with p.open("rb") as fh:
            raw = fh.read(limit + 1)
    except OSError as exc:
        raise InputError(f"cannot read {what} file {printable(str(p))}: {exc.strerror}") from None
    if len(raw) > limit:
        size = f"{limit // 2**20} MiB" if limit >= 2**20 else f"{limit} bytes"
        raise InputError(f"{what} file {printable(str(p))} is larger than {size}")
    return raw


def text_of(raw: bytes, what: str) -> str:
    """``raw`` as UTF-8 text; ``what`` names it in the error line."""
    try:
        # utf-8-sig: a byte-order mark (Windows editors write one) is not text.
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(f"{what} is not UTF-8 text") from None


def read_input_file(path: str | Path, what: str, limit: int = MAX_FILE_BYTES) -> str:
    """Read a user's text file (UTF-8) with :func:`read_input_bytes`' checks."""
    raw = read_input_bytes(path, what, limit)
    return text_of(raw, f"{what} file {printable(str(path))}")


def _no_duplicate_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise InputError(
                f"duplicate key '{clip(key, 40)}' (the later value would hide the first)"
            )
        out[key] = value
    return out


def _no_constant(name: str) -> Any:
    raise InputError(f"{name} is not a JSON number")


def parse_json(text: str, what: str) -> Any:
    """Strict JSON: no duplicate keys (one would silently win), no NaN or Infinity."""
    try:
        return json.loads(text, object_pairs_hook=_no_duplicate_keys, parse_constant=_no_constant)
    except InputError as exc:
        raise InputError(f"{what} is not valid JSON: {exc}") from None
    except json.JSONDecodeError as exc:
        raise InputError(
            f"{what} is not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}"
        ) from None
    except (RecursionError, ValueError):
        raise InputError(f"{what} is not valid JSON (nested too deeply or malformed)") from None


def json_of(raw: bytes, what: str) -> Any:
    """The one reader of JSON bytes a user sends: the CLI's files
    (:func:`read_json_file`) and the service's request bodies (:mod:`virf.web`).
    UTF-8 (a byte-order mark dropped), then strict JSON (:func:`parse_json`);
    every failure is one line naming ``what``."""
    return parse_json(text_of(raw, what), what)


def read_json_file(path: str | Path, what: str) -> Any:
    """Read and parse a user's JSON file; every failure is a one-line input error."""
    p = Path(path)
    return json_of(read_input_bytes(p, what), f"{what} {printable(str(p))}")


# ---------------------------------------------------------------------------
# Documents users write (scenes, replay lines, settings, benchmark files) are
# checked for shape by pydantic models at the edge; the readers then build the
# internal types.  One formatter turns pydantic's error list into the single
# line a user gets.


class Says:
    """Field metadata: the message for a problem with this field, instead of
    the generic one for pydantic's error type.  ``by_type`` words particular
    error types (``too_long="..."``); ``message`` covers the rest, and a
    missing field when its record words none.  Placeholders: see
    ``validation_message``."""

    __slots__ = ("by_type", "message")

    def __init__(self, message: str, **by_type: str) -> None:
        self.message = message
        self.by_type = by_type

    def __repr__(self) -> str:
        return f"Says({self.message!r})"

    def for_type(self, error_type: str) -> str:
        return self.by_type.get(error_type, self.message)


class Record(BaseModel):
    """A closed JSON object of a user's document: strict types (no "3" for 3,
    no 1 for true), no keys it does not declare.  The ``when_*`` templates
    word the problems of the object itself."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)

    when_not_object: ClassVar[str] = "{where} must be a JSON object, not {value}"
    # None: the missing field's own ``Says`` message, else "needs '<key>'".
    when_missing: ClassVar[str | None] = None
    when_unknown_key: ClassVar[str] = "{where}: unknown key '{key}'; expected {expected}"
    # How an entry of this kind is named inside a document: its path
    # (``instances[3]``), or e.g. "{what}: {path}" to lead with the file.
    located_as: ClassVar[str] = "{path}"

    @classmethod
    def parse(cls, data: object, what: str) -> Self:
        """``data`` checked against this model; any problem is one InputError line."""
        try:
            return cls.model_validate(data)
        except ValidationError as exc:
            raise InputError(validation_message(exc, what, cls, data)) from None


# Wording for pydantic's error types on fields without a ``Says``.
_GENERIC: Final[Mapping[str, str]] = MappingProxyType(
    {
        "string_type": "{field} must be a string, not {value}",
        "bool_type": "{field} must be true or false, not {value}",
        "int_type": "{field} must be an integer, not {value}",
        "float_type": "{field} must be a number, not {value}",
        "list_type": "{field} must be a list, not {value}",
        "dict_type": "{field} must be a JSON object, not {value}",
        "literal_error": "{field} must be {expected}, not {value}",
        "greater_than_equal": "{field} must be at least {ge}, not {value}",
        "less_than_equal": "{field} must be at most {le}, not {value}",
        "string_too_short": "{field} must not be empty",
        "string_too_long": "{field} must be at most {max_length} characters",
        "too_long": "{field} has {actual_length} entries; the limit is {max_length}",
    }
)


@dataclass(frozen=True)
class _Problem:
    """One pydantic error, placed in the document: the innermost record it
    concerns (``record``, at ``loc[:record_end]``, ``depth`` records deep)
    and the field, if any."""

    error: Mapping[str, Any]
    record: type[Record]
    record_end: int
    depth: int
    field: str | None

    @property
    def kind(self) -> str:
        # A key that is not valid text (a lone surrogate from a JSON escape)
        # cannot be a declared one either.
        if self.field is None and self.error["type"] in ("extra_forbidden", "string_unicode"):
            return "unknown_key"
        if self.field is None:
            return "not_object"
        return "missing" if self.error["type"] == "missing" else "field"

    @property
    def key(self) -> str:
        """The field or key at fault ('' for the record itself)."""
        if self.error["type"] == "string_unicode" and self.field is None:
            return str(self.error["input"])
        loc = self.error["loc"]
        return str(loc[self.record_end]) if len(loc) > self.record_end else ""

    @property
    def record_loc(self) -> tuple[int | str, ...]:
        return tuple(self.error["loc"][: self.record_end])

    def rank(self, index: int) -> tuple[int, int, int]:
        # The document's own problems before its entries' (a wrong top-level
        # key before a bad entry), and within one object an unknown key first
        # (usually the misspelling of a missing one), then missing keys.
        return (self.depth, _KIND_ORDER[self.kind], index)


_KIND_ORDER: Final[Mapping[str, int]] = MappingProxyType(
    {"unknown_key": 0, "not_object": 0, "missing": 1, "field": 2}
)


def _place(
    model: type[Record], loc: tuple[int | str, ...], error_type: str
) -> tuple[type[Record], int, int, str | None]:
    """The innermost record on ``loc``: (class, end of its location, nesting
    depth, field name or None when the error is the record's own)."""
    record, end, depth = model, 0, 0
    while end < len(loc):
        name = loc[end]
        info = record.model_fields.get(name) if isinstance(name, str) else None
        if info is None:  # an undeclared key
            return record, end, depth, None
        rest = loc[end + 1 :]
        nested = (
            None if error_type == "missing" and not rest else _nested_record(info.annotation, rest)
        )
        if nested is None:
            return record, end, depth, str(name)
        record, steps = nested
        end, depth = end + 1 + steps, depth + 1
    return record, end, depth, None


def _nested_record(annotation: Any, rest: tuple[int | str, ...]) -> tuple[type[Record], int] | None:
    """The record inside a field's type that ``rest`` reaches (through lists,
    dicts and Optional), with the number of steps taken; None if ``rest``
    ends in the field itself."""
    steps = 0
    tp = annotation
    while True:
        origin = get_origin(tp)
        if origin is Annotated:
            tp = get_args(tp)[0]
        elif origin in (Union, UnionType) and len(options := _not_none(tp)) == 1:
            tp = options[0]
        elif isinstance(tp, type) and issubclass(tp, Record):
            return tp, steps
        elif rest[steps:] and origin is list and isinstance(rest[steps], int):
            tp, steps = get_args(tp)[0], steps + 1
        elif rest[steps:] and origin is dict:
            tp, steps = get_args(tp)[1], steps + 1
        else:
            return None


def _not_none(union: Any) -> list[Any]:
    return [a for a in get_args(union) if a is not type(None)]


def _path(loc: tuple[int | str, ...]) -> str:
    """A location as a reader writes it: ``instances[3]``, ``corrections[0].twin``."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{clip(part, 40)}" if out else clip(part, 40)
    return out


def _shown(value: Any) -> str:
    """A user's value for a message: as JSON, shortened, one line."""
    try:
        text = json.dumps(value)
    except (TypeError, ValueError):  # a Python caller's non-JSON object
        text = repr(value)
    return clip(text, 40)


class _Raw(dict[str, str]):
    """The raw fields of the record at fault, for templates that quote a
    sibling (``{record[file]}``); absent ones read as None, as ``.get`` would."""

    def __missing__(self, key: str) -> str:
        return "None"


def _raw_record(data: object, loc: tuple[int | str, ...]) -> _Raw:
    for part in loc:
        try:
            data = data[part]  # type: ignore[index]
        except (KeyError, IndexError, TypeError):
            return _Raw()
    if not isinstance(data, dict):
        return _Raw()
    return _Raw({str(k): clip(str(v), 40) for k, v in data.items()})


def validation_message(
    exc: ValidationError, what: str, model: type[Record], data: object = None
) -> str:
    """The one line a user gets for ``exc``, raised by ``model`` on ``data``.

    Of all the problems pydantic found, the outermost is told (a stray key of
    the document before a bad entry), in the words of the field's ``Says``,
    the record's ``when_*`` template, or the generic wording of the error type.
    Templates may use ``{what}`` (the document), ``{where}`` (``what`` for the
    document itself, else the entry's path such as ``instances[3]``),
    ``{field}`` (``where`` and the quoted key), ``{key}``, ``{value}`` (the
    value as JSON), ``{text}`` (the value as text), ``{expected}`` (the
    record's keys sorted, or a literal's choices), ``{keys}`` (the keys in
    declaration order), ``{closest}`` (``; closest: k`` for an unknown key),
    ``{record[k]}`` (a sibling value) and the error's context
    (``{max_length}``, ``{actual_length}``, ``{ge}``...).
    """
    errors = exc.errors(include_url=False)
    placed = [_Problem(e, *_place(model, tuple(e["loc"]), e["type"])) for e in errors]
    problem = min(enumerate(placed), key=lambda ip: ip[1].rank(ip[0]))[1]
    if problem.kind == "unknown_key":
        # Of several unknown keys of one object, the first in sorted order,
        # so the message does not depend on the file's key order.
        here = problem.record_loc
        problem = min(
            (p for p in placed if p.kind == "unknown_key" and p.record_loc == here),
            key=lambda p: p.key,
        )
    error, record = problem.error, problem.record
    loc = tuple(error["loc"])
    where = (
        what
        if problem.record_end == 0
        else record.located_as.format(what=what, path=_path(loc[: problem.record_end]))
    )
    key = problem.key
    says = None
    if problem.field is not None:
        metadata = record.model_fields[problem.field].metadata
        says = next((m for m in metadata if isinstance(m, Says)), None)
    if problem.kind == "not_object":
        template = record.when_not_object
    elif problem.kind == "unknown_key":
        template = record.when_unknown_key
    elif problem.kind == "missing":
        template = record.when_missing or (says.message if says else "{where} needs '{key}'")
    elif says is not None:
        template = says.for_type(str(error["type"]))
    else:
        template = _GENERIC.get(str(error["type"]), "{field} is not valid: {msg}")
    ctx = {k: str(v) for k, v in (error.get("ctx") or {}).items()}
    near = closest(key, record.model_fields, n=1) if problem.kind == "unknown_key" else []
    values = {
        **ctx,
        "what": what,
        "where": where,
        "key": clip(key, 40),
        # "scene 'name' must..." for the document, "instances[3]: 'class_name' must..." inside
        "field": f"{where}{' ' if problem.record_end == 0 else ': '}'{clip(key, 40)}'",
        "value": _shown(error.get("input")),
        "text": clip(str(error.get("input"))),
        "expected": ctx.get("expected") or ", ".join(sorted(record.model_fields)),
        "keys": ", ".join(record.model_fields),
        "closest": f"; closest: {near[0]}" if near else "",
        "msg": str(error.get("msg", "")),
        "record": _raw_record(data, loc[: problem.record_end]),
    }
    return template.format(**values)
