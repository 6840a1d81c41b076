"""Planner specs, read once into a typed value, and the registry of planner kinds.

A spec is what ``--planner`` (and ``--critic``, ``--vlm``, ``--drafter``)
takes: ``KIND:ARGUMENT`` (``openai:gpt-4o-mini``, ``local:smollm2-135m``,
``replay:runs/virf.jsonl``), or a bare ``KIND`` for a kind that takes no
argument (``scripted``).  It is parsed where it enters into a
:class:`PlannerSpec`; what a spec means (which apprentice to build, whether a
model is asked over HTTP, which file the planner's answers come from) is then
asked of its :class:`PlannerKind`, never of the string's prefix.

The kinds are registered as the reasoning engines are (:mod:`virf.reasoning`):
each built-in kind names its builder by where it lives, imported only when a
planner of that kind is built, so this module loads no client and the builders
can import it without a cycle; :func:`register` adds more (a plugin, a test
double).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib import import_module
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from virf.errors import InputError, clip, closest

if TYPE_CHECKING:
    from virf.planner.apprentices import Apprentice
    from virf.planner.runlog import RunLog

__all__ = [
    "BUILTIN",
    "Builder",
    "PlannerKind",
    "PlannerSpec",
    "planner_kind",
    "planner_kinds",
    "register",
    "spec_forms",
]


class Builder(Protocol):
    """Makes the apprentice a spec names.  ``settings`` are the client
    settings given (none of them ``None``); a builder refuses the ones its
    kind has no use for, or ignores them where a run must not depend on them."""

    def __call__(
        self,
        spec: PlannerSpec,
        settings: Mapping[str, Any],
        *,
        run_log: RunLog | None,
        environ: Mapping[str, str] | None,
    ) -> Apprentice: ...


@dataclass(frozen=True)
class PlannerKind:
    """One kind of planner: how its specs are written and how it is built."""

    name: str
    # What follows the colon, as the list of forms names it ("MODEL"); None
    # for a kind written without one.
    argument: str | None
    form: str  # the kind in the list of valid forms: "local:NAME (or local:PATH.gguf)"
    missing: str  # the error for the kind written without its argument
    builder: str | Builder  # "module:attr", imported when first used, or the builder
    # A model asked over HTTP: the server and the user's config are part of a run.
    over_http: bool = False
    # Takes sampling settings (temperature, seed, max_tokens): they are part of a run.
    sampling: bool = False
    # The file whose content decides the answers (a recording, a model's
    # weights), when the argument names one: a run is identified by that
    # content rather than by the path.
    source: Callable[[str], Path | None] | None = None

    def __post_init__(self) -> None:
        if not self.name or ":" in self.name or self.name != self.name.strip():
            raise ValueError(f"a planner kind needs a name without ':' or spaces: {self.name!r}")

    def spell(self, argument: str | None) -> str:
        """The spec of this kind with ``argument``, or its form when none is given."""
        if self.argument is None:
            return self.name
        return f"{self.name}:{argument}" if argument else self.form.split(" ", 1)[0]

    def build(
        self,
        spec: PlannerSpec,
        settings: Mapping[str, Any],
        *,
        run_log: RunLog | None = None,
        environ: Mapping[str, str] | None = None,
    ) -> Apprentice:
        builder = self.builder
        if isinstance(builder, str):
            module, _, attr = builder.partition(":")
            builder = getattr(import_module(module), attr)
        apprentice: Apprentice = builder(spec, settings, run_log=run_log, environ=environ)
        return apprentice


def _replay_file(argument: str) -> Path:
    return Path(argument)


def _model_file(argument: str) -> Path | None:
    # A packaged model is named by its package; only a GGUF path is a file.
    return Path(argument).expanduser() if argument.lower().endswith(".gguf") else None


# The built-in kinds, in the order the list of valid forms gives them.
BUILTIN: dict[str, PlannerKind] = {
    kind.name: kind
    for kind in (
        PlannerKind(
            "openai",
            "MODEL",
            "openai:MODEL",
            "no model name: use openai:MODEL, e.g. openai:gpt-4o-mini",
            "virf.planner.factory:openai_apprentice",
            over_http=True,
            sampling=True,
        ),
        PlannerKind(
            "local",
            "NAME",
            "local:NAME (or local:PATH.gguf)",
            "no model: use local:smollm2-135m or local:PATH.gguf",
            "virf.planner.factory:local_apprentice",
            sampling=True,
            source=_model_file,
        ),
        PlannerKind(
            "replay",
            "FILE",
            "replay:FILE",
            "no replay file: use replay:FILE, e.g. replay:runs/virf.jsonl",
            "virf.planner.factory:replay_apprentice",
            source=_replay_file,
        ),
        PlannerKind(
            "scripted",
            None,
            "scripted",
            "",
            "virf.planner.factory:scripted_apprentice",
        ),
    )
}
_REGISTRY: dict[str, PlannerKind] = {}


def register(kind: PlannerKind) -> None:
    """Add a planner kind beyond the built-in ones (a plugin, a test double);
    one of the same name replaces a built-in kind."""
    _REGISTRY[kind.name] = kind


def planner_kinds() -> list[str]:
    """Every kind's name: the built-in ones first, in their order."""
    return [*BUILTIN, *(name for name in _REGISTRY if name not in BUILTIN)]


def _lookup(name: str) -> PlannerKind | None:
    return _REGISTRY.get(name) or BUILTIN.get(name)


def spec_forms() -> str:
    """The valid forms, for a message: ``openai:MODEL, ..., replay:FILE or scripted``."""
    forms = [kind.form for name in planner_kinds() if (kind := _lookup(name)) is not None]
    return forms[0] if len(forms) == 1 else f"{', '.join(forms[:-1])} or {forms[-1]}"


def planner_kind(name: str) -> PlannerKind:
    """The kind named ``name``; an unknown name is a one-line input error."""
    found = _lookup(name)
    if found is None:
        raise _unknown(name, name, None)
    return found


def _unknown(typed: str, name: str, argument: str | None) -> InputError:
    found = _lookup(name)
    if found is not None:  # a kind that takes no argument, written with one
        guesses = [found.spell(None)]
    else:
        guesses = [
            kind.spell(argument)
            for near in closest(name, planner_kinds())
            if (kind := _lookup(near)) is not None
        ]
    hint = f" (did you mean {' or '.join(clip(g) for g in guesses)}?)" if guesses else ""
    return InputError(f"unknown planner '{clip(typed)}'; choose {spec_forms()}{hint}")


def _check(name: str, argument: str | None, typed: str) -> None:
    found = _lookup(name)
    if found is None or (found.argument is None and argument is not None):
        raise _unknown(typed, name, argument)
    if found.argument is not None and not argument:
        raise InputError(found.missing)


@dataclass(frozen=True)
class PlannerSpec:
    """A checked planner spec.  ``argument`` is what follows the colon (the
    model, the file), ``None`` for a kind written without one; ``str(spec)``
    is the canonical spelling, which :meth:`parse` reads back to an equal spec.
    """

    kind: str
    argument: str | None = None

    def __post_init__(self) -> None:
        if self.argument is not None:
            # The canonical spelling has no spaces around the argument.
            object.__setattr__(self, "argument", self.argument.strip())
        _check(self.kind, self.argument, str(self))

    @classmethod
    def parse(cls, text: str | PlannerSpec) -> PlannerSpec:
        """``KIND:ARGUMENT`` or ``KIND`` (spaces around the whole and around
        the argument are dropped); an unknown kind or a missing or surplus
        argument is a one-line input error naming the valid forms."""
        if isinstance(text, PlannerSpec):
            return text
        if not isinstance(text, str):
            raise InputError(f"a planner spec must be text, not {type(text).__name__}")
        name, colon, rest = text.strip().partition(":")
        argument = rest.strip() if colon else None
        _check(name, argument, text.strip())
        return cls(name, argument)

    def __str__(self) -> str:
        return self.kind if self.argument is None else f"{self.kind}:{self.argument}"

    @property
    def kind_info(self) -> PlannerKind:
        return planner_kind(self.kind)

    @property
    def over_http(self) -> bool:
        """Whether the planner is a model asked over HTTP."""
        return self.kind_info.over_http

    @property
    def sampling(self) -> bool:
        """Whether the planner takes sampling settings."""
        return self.kind_info.sampling

    def source_file(self) -> Path | None:
        """The file whose content decides this planner's answers (a replay
        file, a GGUF model), or ``None`` when it is not a file."""
        source = self.kind_info.source
        if source is None or self.argument is None:
            return None
        return source(self.argument)

    def build(
        self,
        settings: Mapping[str, Any],
        *,
        run_log: RunLog | None = None,
        environ: Mapping[str, str] | None = None,
    ) -> Apprentice:
        """The apprentice this spec names (see :func:`virf.planner.make_apprentice`)."""
        return self.kind_info.build(self, settings, run_log=run_log, environ=environ)
