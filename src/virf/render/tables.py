"""One table, two renderings: a rich table for the terminal, a Markdown table for reports.

A command that prints a table and writes it into a Markdown report builds the
rows once, so the two cannot drift apart.  Cells are plain text in both
renderings: nothing in them is read as terminal markup or as Markdown table
syntax.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    from rich.table import Table as RichTable

Align = Literal["left", "right"]


@dataclass(frozen=True)
class Column:
    header: str
    align: Align = "left"


@dataclass(frozen=True)
class TextTable:
    """A title, columns and rows of text cells, one cell per column.

    The title is shown above the terminal table; a Markdown document gives the
    table a heading of its own, so :func:`to_markdown` leaves it out."""

    columns: tuple[Column, ...]
    rows: tuple[tuple[str, ...], ...]
    title: str | None = None

    def __post_init__(self) -> None:
        width = len(self.columns)
        for row in self.rows:
            if len(row) != width:
                raise ValueError(f"a row of {len(row)} cells in a table of {width} columns: {row}")

    @classmethod
    def of(
        cls,
        columns: Sequence[str | Column],
        rows: Iterable[Sequence[str]],
        title: str | None = None,
    ) -> TextTable:
        """Columns given by header alone are left-aligned."""
        return cls(
            tuple(c if isinstance(c, Column) else Column(c) for c in columns),
            tuple(tuple(row) for row in rows),
            title,
        )


def to_rich(table: TextTable) -> RichTable:
    from rich.markup import escape
    from rich.table import Table

    view = Table(title=None if table.title is None else escape(table.title))
    for column in table.columns:
        view.add_column(escape(column.header), justify=column.align)
    for row in table.rows:
        view.add_row(*(escape(cell) for cell in row))
    return view


def _markdown_cell(text: str) -> str:
    # A '|' would end the cell and a line break the row.
    return text.replace("|", "\\|").replace("\n", " ")


def _markdown_row(cells: Iterable[str]) -> str:
    # An empty cell is one space wide: "| a | |".
    return "|" + "|".join(f" {c} " if c else " " for c in map(_markdown_cell, cells)) + "|"


def to_markdown(table: TextTable) -> list[str]:
    """The table as Markdown lines: header, delimiter row, one line per row."""
    delimiter = "|" + "".join("---:|" if c.align == "right" else "---|" for c in table.columns)
    return [
        _markdown_row(c.header for c in table.columns),
        delimiter,
        *(_markdown_row(row) for row in table.rows),
    ]
