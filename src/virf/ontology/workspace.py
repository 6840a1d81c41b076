"""A knowledge workspace as the ontology sees it: a folder whose layered
modules add reviewed axioms to the built-in TBox of one scenario.

The workspace's authoring side (corpus, candidates, decisions) lives in
:mod:`virf.authoring`; this module knows only what loading a TBox with
``--kb DIR`` needs: the marker file, the scenario the workspace is layered on,
and its three modules in import order (core, domain, scenario).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from virf.errors import InputError, clip

MARKER: Final = "virf-kb.json"
FORMAT: Final = 1
LAYERS: Final = ("core", "domain", "scenario")
# Each workspace module is an ontology of its own, named after its layer; one
# workspace is loaded at a time, so the names need not differ between workspaces.
WORKSPACE_BASE: Final = "http://virf.dev/ontology/workspace/"


@dataclass(frozen=True)
class KbLayout:
    """Where a workspace keeps what verification reads."""

    root: Path
    scenario: str

    @property
    def module_dir(self) -> Path:
        return self.root / "modules"

    def module_path(self, layer: str) -> Path:
        if layer not in LAYERS:
            raise InputError(f"unknown layer '{clip(layer)}'; choose from {', '.join(LAYERS)}")
        return self.module_dir / f"{layer}.omn"

    def module_iri(self, layer: str) -> str:
        return f"{WORKSPACE_BASE}{layer}"

    def modules(self) -> tuple[Path, ...]:
        """The layer modules in the order they must be loaded (each imports the one before)."""
        return tuple(self.module_path(layer) for layer in LAYERS)

    @property
    def cache_dir(self) -> Path:
        return self.root / "cache"


def open_layout(root: str | Path) -> KbLayout:
    """The workspace at ``root``, or a one-line error saying how to make one."""
    path = Path(root)
    marker = path / MARKER
    if not marker.is_file():
        hint = "run 'virf kb init DIR' first" if not path.exists() else "it has no " + MARKER
        raise InputError(f"{clip(str(path))} is not a VIRF knowledge workspace; {hint}")
    try:
        config = json.loads(marker.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(f"{marker}: unreadable workspace file ({exc})") from None
    if not isinstance(config, dict) or config.get("format") != FORMAT:
        raise InputError(
            f"{marker}: workspace format {config.get('format') if isinstance(config, dict) else '?'}"
            f" is not {FORMAT}; this VIRF cannot read it"
        )
    scenario = config.get("scenario")
    from virf.ontology.tbox import scenario_names

    if not isinstance(scenario, str) or scenario not in scenario_names():
        raise InputError(
            f"{marker}: scenario {scenario!r} is not one of {', '.join(scenario_names())}"
        )
    layout = KbLayout(path.resolve(), scenario)
    missing = [p.name for p in layout.modules() if not p.is_file()]
    if missing:
        raise InputError(f"workspace {path} lacks its module {missing[0]} (in {layout.module_dir})")
    return layout
