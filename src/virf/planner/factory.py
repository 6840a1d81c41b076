"""Build an apprentice from the ``--planner`` spec the user typed.

:func:`make_apprentice` reads the spec (:class:`~virf.planner.spec.PlannerSpec`)
and hands it to its kind's builder; the builders of the built-in kinds are
here, named by :data:`virf.planner.spec.BUILTIN`.
"""

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
from virf.planner.spec import PlannerSpec

_CLIENT_FIELDS: Final = frozenset(f.name for f in dataclasses.fields(ClientSettings)) - {"model"}


def make_apprentice(
    spec: str | PlannerSpec,
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
    return PlannerSpec.parse(spec).build(given, run_log=run_log, environ=environ)


def openai_apprentice(
    spec: PlannerSpec,
    settings: Mapping[str, Any],
    *,
    run_log: RunLog | None,
    environ: Mapping[str, str] | None,
) -> Apprentice:
    given = dict(settings)
    if "replies" in given:
        raise InputError("'replies' is a setting of the scripted planner only")
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
    assert spec.argument is not None  # the kind takes a model name
    return OpenAIApprentice(
        ClientSettings(model=spec.argument, **given), run_log=run_log, environ=environ
    )


def local_apprentice(
    spec: PlannerSpec,
    settings: Mapping[str, Any],
    *,
    run_log: RunLog | None,
    environ: Mapping[str, str] | None,
) -> Apprentice:
    from virf.planner.local import LocalApprentice, LocalSettings

    remote = sorted(set(settings) & {"base_url", "api_key", "api_key_env", "top_p", "replies"})
    if remote:
        raise InputError(f"'{remote[0]}' is not a setting of a local planner")
    local = {
        k: settings[k] for k in ("temperature", "seed", "max_tokens", "constrain") if k in settings
    }
    assert spec.argument is not None  # the kind takes a model name or file
    return LocalApprentice(
        LocalSettings(model=spec.argument, **local), run_log=run_log, environ=environ
    )


def replay_apprentice(
    spec: PlannerSpec,
    settings: Mapping[str, Any],
    *,
    run_log: RunLog | None,
    environ: Mapping[str, str] | None,
) -> Apprentice:
    assert spec.argument is not None  # the kind takes a file
    return ReplayApprentice(spec.argument, run_log=run_log)


def scripted_apprentice(
    spec: PlannerSpec,
    settings: Mapping[str, Any],
    *,
    run_log: RunLog | None,
    environ: Mapping[str, str] | None,
) -> Apprentice:
    return ScriptedApprentice(settings.get("replies", []), run_log=run_log)
