"""Errors that reach users.  Each carries one line that names the problem."""

from __future__ import annotations

import difflib
import json
import unicodedata
from collections.abc import Iterable
from pathlib import Path
from typing import Any


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


def read_input_file(path: str | Path, what: str, limit: int = MAX_FILE_BYTES) -> str:
    """Read a user's file, turning I/O failures into one-line input errors.

    Only regular files are read, and at most ``limit`` bytes: a FIFO would block
    forever and a device such as /dev/zero would never end."""
    p = Path(path)
    try:
        if not p.exists():
            raise InputError(f"{what} file not found: {p}")
        if not p.is_file():
            raise InputError(f"{what} path {p} is not a regular file")
        with p.open("rb") as fh:
            raw = fh.read(limit + 1)
        if len(raw) > limit:
            size = f"{limit // 2**20} MiB" if limit >= 2**20 else f"{limit} bytes"
            raise InputError(f"{what} file {p} is larger than {size}")
        # utf-8-sig: a byte-order mark (Windows editors write one) is not text.
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(f"{what} file {p} is not UTF-8 text") from None
    except OSError as exc:
        raise InputError(f"cannot read {what} file {p}: {exc.strerror}") from None


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


def read_json_file(path: str | Path, what: str) -> Any:
    """Read and parse a user's JSON file; every failure is a one-line input error."""
    p = Path(path)
    return parse_json(read_input_file(p, what), f"{what} {p}")
