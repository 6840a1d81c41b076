"""The examples VIRF ships, wherever it runs from.

A checkout keeps them in ``examples/`` beside ``src/`` (the README, the
Makefile and the tests name them there); a built wheel carries a copy as
package data, ``virf/examples`` (setup.py's build step), which
:mod:`importlib.resources` finds in an installed package.
"""

from __future__ import annotations

import importlib.resources
from pathlib import Path

import virf


def bundled_examples() -> Path | None:
    """The checkout's ``examples/`` when this package runs from a source
    checkout (``src/virf`` next to ``pyproject.toml`` and ``examples``), else
    the copy an installed wheel carries; None when there is neither."""
    root = Path(virf.__file__).resolve().parent.parent.parent
    checkout = root / "examples"
    if (root / "pyproject.toml").is_file() and checkout.is_dir():
        return checkout
    shipped = importlib.resources.files(virf) / "examples"
    # Only a package installed as files has a folder to hand out (a zipped
    # one would need extracting, and VIRF is never installed that way).
    if isinstance(shipped, Path) and shipped.is_dir():
        return shipped
    return None
