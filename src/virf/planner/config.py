"""The user's planner settings file: ``$XDG_CONFIG_HOME/virf/config.toml``
(``~/.config/virf/config.toml`` by default).

```toml
[planner]
api_key = "sk-..."          # used when the key's environment variable is unset
base_url = "http://127.0.0.1:11434/v1"
temperature = 0.0
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

KEYS = ("api_key", "base_url", "temperature", "top_p", "max_tokens", "timeout_s", "seed")


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
