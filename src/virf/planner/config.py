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
from typing import Any

from virf.errors import InputError
from virf.planner.deadline import DEFAULT_DEADLINE_S, deadline_seconds

KEYS = (
    "api_key",
    "base_url",
    "temperature",
    "top_p",
    "max_tokens",
    "timeout_s",
    "seed",
    "deadline_s",
)
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
    if not isinstance(table, dict):
        raise InputError(f"config file {path}: [planner] must be a table")
    unknown = sorted(set(table) - set(KEYS))
    if unknown:
        raise InputError(
            f"config file {path}: unknown [planner] key '{unknown[0]}'; choose from {', '.join(KEYS)}"
        )
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
