"""Errors that reach users.  Each carries one line that names the problem."""

from __future__ import annotations

import difflib
import json
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


def clip(term: str, limit: int = 60) -> str:
    """A user's term, shortened for a one-line message."""
    return term if len(term) <= limit else term[: limit - 3] + "..."


def unknown_term(kind: str, term: str, choices: Iterable[str]) -> InputError:
    near = closest(term[:200], choices)
    hint = f"; closest known: {', '.join(near)}" if near else ""
    return InputError(f"unknown {kind} '{clip(term)}'{hint}")


def read_input_file(path: str | Path, what: str) -> str:
    """Read a user's file, turning I/O failures into one-line input errors."""
    p = Path(path)
    try:
        return p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"{what} file not found: {p}") from None
    except UnicodeDecodeError:
        raise InputError(f"{what} file {p} is not UTF-8 text") from None
    except OSError as exc:
        raise InputError(f"cannot read {what} file {p}: {exc.strerror}") from None


def read_json_file(path: str | Path, what: str) -> Any:
    """Read and parse a user's JSON file; every failure is a one-line input error."""
    p = Path(path)
    text = read_input_file(p, what)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(
            f"{what} {p} is not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}"
        ) from None
    except (RecursionError, ValueError):
        raise InputError(f"{what} {p} is not valid JSON (nested too deeply or malformed)") from None
