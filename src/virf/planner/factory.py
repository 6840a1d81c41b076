"""Build an apprentice from the ``--planner`` spec the user typed."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from typing import Any, Final

from virf.errors import InputError, clip
from virf.planner.apprentices import Apprentice, ReplayApprentice, ScriptedApprentice
from virf.planner.chat import BASE_URL_ENV, DEFAULT_API_KEY_ENV, ClientSettings
from virf.planner.clients import OpenAIApprentice
from virf.planner.config import RUN_KEYS, planner_settings
from virf.planner.runlog import RunLog

SPEC_FORMS: Final = "openai:MODEL, local:NAME (or local:PATH.gguf), replay:FILE or scripted"
_CLIENT_FIELDS: Final = frozenset(f.name for f in dataclasses.fields(ClientSettings)) - {"model"}


def make_apprentice(
    spec: str,
    *,
    run_log: RunLog | None = None,
    environ: Mapping[str, str] | None = None,
    **settings: Any,
) -> Apprentice:
    """``openai:MODEL``, ``local:NAME``, ``replay:FILE`` or ``scripted`` -> an apprentice.

    ``settings`` are ``ClientSettings`` fields (``base_url``, ``temperature``…);
    a ``None`` value means "not given", so a command line can pass its options
    through unchanged.  Offline apprentices ignore client settings, because a
    replayed or scripted run must not depend on them.  ``scripted`` takes
    ``replies=[...]``.
    """
    given = {k: v for k, v in settings.items() if v is not None}
    unknown = sorted(set(given) - _CLIENT_FIELDS - {"replies"})
    if unknown:
        raise InputError(
            f"unknown planner setting '{clip(unknown[0])}'; "
            f"choose from {', '.join(sorted(_CLIENT_FIELDS))}"
        )
    kind, sep, rest = spec.strip().partition(":")
    if kind == "openai" and sep:
        if "replies" in given:
            raise InputError("'replies' is a setting of the scripted planner only")
        model = rest.strip()
        if not model:
            raise InputError("no model name: use openai:MODEL, e.g. openai:gpt-4o-mini")
        # The user's config file fills what the command line left open; its
        # key only counts when the key's environment variable is unset.
        env = os.environ if environ is None else environ
        for key, value in planner_settings(env).items():
            if key in RUN_KEYS:  # read by the command that runs the loop
                continue
            if key == "api_key" and env.get(given.get("api_key_env", DEFAULT_API_KEY_ENV)):
                continue
            if key == "base_url" and env.get(BASE_URL_ENV):
                continue
            given.setdefault(key, value)
        return OpenAIApprentice(
            ClientSettings(model=model, **given), run_log=run_log, environ=environ
        )
    if kind == "local" and sep:
        from virf.planner.local import LocalApprentice, LocalSettings

        name = rest.strip()
        if not name:
            raise InputError("no model: use local:smollm2-135m or local:PATH.gguf")
        remote = sorted(set(given) & {"base_url", "api_key", "api_key_env", "top_p", "replies"})
        if remote:
            raise InputError(f"'{remote[0]}' is not a setting of a local planner")
        local = {k: given[k] for k in ("temperature", "seed", "max_tokens") if k in given}
        return LocalApprentice(LocalSettings(model=name, **local), run_log=run_log, environ=environ)
    if kind == "replay" and sep:
        if not rest.strip():
            raise InputError("no replay file: use replay:FILE, e.g. replay:runs/virf.jsonl")
        return ReplayApprentice(rest.strip(), run_log=run_log)
    if kind == "scripted" and not sep:
        return ScriptedApprentice(given.get("replies", []), run_log=run_log)
    raise InputError(f"unknown planner '{clip(spec)}'; choose {SPEC_FORMS}")
