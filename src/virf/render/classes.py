"""The table of ``virf kb classes``: one row per class, its knowledge in words."""

from __future__ import annotations

from virf.ontology.classes import ClassInfo
from virf.ontology.suggest import Ranked
from virf.render.tables import Column, TextTable


def _materials(info: ClassInfo) -> str:
    parts = []
    if info.materials:
        parts.append(", ".join(info.materials))
    if info.typical_materials:
        parts.append("typically " + ", ".join(info.typical_materials))
    if info.possible_materials:
        parts.append("maybe " + ", ".join(info.possible_materials))
    return "; ".join(parts)


def _affordances(info: ClassInfo) -> str:
    parts = [", ".join(info.affordances)] if info.affordances else []
    if info.may_afford:
        parts.append("some: " + ", ".join(info.may_afford))
    return "; ".join(parts)


def class_table(rows: list[tuple[ClassInfo, Ranked | None]], title: str) -> TextTable:
    """Name (and synonyms), kind, parents, materials, affordances, properties;
    with a search, the score first."""
    searched = any(match is not None for _, match in rows)
    columns: list[str | Column] = [
        "class",
        "kind",
        "parents",
        "materials",
        "affordances",
        "properties",
    ]
    if searched:
        columns.insert(1, Column("score", "right"))
    out = []
    for info, match in rows:
        name = info.name + (f" (also {', '.join(info.synonyms)})" if info.synonyms else "")
        cells = [
            name,
            info.kind,
            ", ".join(info.parents),
            _materials(info),
            _affordances(info),
            ", ".join(info.properties),
        ]
        if searched:
            cells.insert(1, "" if match is None else f"{match.score:.2f}")
        out.append(cells)
    return TextTable.of(columns, out, title=title)
