"""The user's planner settings file: ``$XDG_CONFIG_HOME/virf/config.toml``
(``~/.config/virf/config.toml`` by default).

```toml
[planner]
api_key = "sk-..."          # used when the key's environment variable is unset
base_url = "http://127.0.0.1:11434/v1"
temperature = 0.0
timeout_s = 120             # one model reply, start to end
deadline_s = 600            # a whole `virf plan` run
```

Command-line options win over the file, and an API key in the environment wins
over one in the file, as the ecosystem expects.
"""

from __future__ import annotations

import os
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any

from virf.errors import InputError, Record, Says
from virf.planner.deadline import DEFAULT_DEADLINE_S, deadline_seconds

_TEXT = Says("{what}: [planner] {key} must be a string, not {value}")


class PlannerSettings(Record):
    """The ``[planner]`` table.  The numbers are left to ``ClientSettings`` and
    ``deadline_seconds``, which check command-line values too and whose
    messages name the valid range."""

    when_not_object = "{what}: [planner] must be a table"
    when_unknown_key = "{what}: unknown [planner] key '{key}'; choose from {keys}"

    api_key: Annotated[str | None, _TEXT] = None
    base_url: Annotated[str | None, _TEXT] = None
    temperature: Any = None
    top_p: Any = None
    max_tokens: Any = None
    timeout_s: Any = None
    seed: Any = None
    deadline_s: Any = None


KEYS = tuple(PlannerSettings.model_fields)
# Settings of the run rather than of the model client.
RUN_KEYS = frozenset({"deadline_s"})


def config_path(environ: Mapping[str, str] | None = None) -> Path:
    env = os.environ if environ is None else environ
    root = env.get("XDG_CONFIG_HOME") or str(Path(env.get("HOME", "~")).expanduser() / ".config")
    return Path(root) / "virf" / "config.toml"


def planner_settings(environ: Mapping[str, str] | None = None) -> dict[str, Any]:
    """The ``[planner]`` table of the user's config file ({} when there is none)."""
    path = config_path(environ)
    if not path.is_file():
        return {}
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise InputError(f"config file {path} cannot be read: {exc}") from None
    table = data.get("planner", {})
    PlannerSettings.parse(table, f"config file {path}")
    # The table as written: only the keys it sets, in its order.
    return dict(table)


def run_deadline(given: float | None, environ: Mapping[str, str] | None = None) -> float:
    """Seconds a whole ``virf plan`` run may take: the command line's value,
    else ``deadline_s`` from the config file, else ``DEFAULT_DEADLINE_S``."""
    if given is not None:
        return deadline_seconds(given, "--deadline")
    value = planner_settings(environ).get("deadline_s")
    if value is None:
        return DEFAULT_DEADLINE_S
    return deadline_seconds(value, f"config file {config_path(environ)}: deadline_s")
