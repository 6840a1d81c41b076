"""The public API's ways to build a tutor, and the one table source behind the
terminal and Markdown renderings."""

from __future__ import annotations

import io

import pytest
from conftest import EXAMPLES_DIR
from rich.console import Console

from virf.api import LogicTutor
from virf.errors import InputError
from virf.render.tables import Column, TextTable, to_markdown, to_rich

WALK = EXAMPLES_DIR / "walkthrough"


def test_a_restricted_tutor_checks_only_its_rules(tutor: LogicTutor) -> None:
    full = tutor.verify_files(WALK / "scene.json", WALK / "plan.txt")
    assert full.status == "UNSAFE"
    found = full.violations[0].name
    without = tutor.restricted(set(tutor.tbox.vocabulary.uscs) - {found})
    assert without.engine is tutor.engine and without.tbox is tutor.tbox
    report = without.verify_files(WALK / "scene.json", WALK / "plan.txt")
    assert all(v.name != found for v in report.violations)
    only = tutor.restricted({found})
    assert only.verify_files(WALK / "scene.json", WALK / "plan.txt").violations[0].name == found


def test_a_restriction_to_an_unknown_concept_is_refused(tutor: LogicTutor) -> None:
    with pytest.raises(InputError, match="not an Unsafe State Concept: NoSuchDanger"):
        tutor.restricted({"NoSuchDanger"})


def test_tutors_over_one_engine_share_it(tutor: LogicTutor) -> None:
    first = LogicTutor.over(tutor.tbox, "fast")
    second = LogicTutor.over(tutor.tbox, first.engine, explain=False)
    assert second.engine is first.engine
    before = first.engine.stats().get("calls", 0)
    second.verify_files(WALK / "scene.json", WALK / "plan.txt")
    assert first.engine.stats()["calls"] > before


def test_one_table_renders_the_same_cells_for_terminal_and_markdown() -> None:
    table = TextTable.of(
        ("name", Column("ms", "right")),
        [("a|b", "1.5"), ("[bold]x[/bold]", "")],
        title="t",
    )
    assert to_markdown(table) == [
        "| name | ms |",
        "|---|---:|",
        "| a\\|b | 1.5 |",
        "| [bold]x[/bold] | |",
    ]
    out = io.StringIO()
    Console(file=out, width=60, color_system=None).print(to_rich(table))
    text = out.getvalue()
    assert "a|b" in text and "[bold]x[/bold]" in text  # plain text, not markup


def test_a_row_of_the_wrong_width_is_refused() -> None:
    with pytest.raises(ValueError, match="a row of 1 cells in a table of 2 columns"):
        TextTable.of(("a", "b"), [("only one",)])
