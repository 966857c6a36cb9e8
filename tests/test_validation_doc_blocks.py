"""Generated blocks of the documentation: replaced whole between their markers, never half-written."""

from pathlib import Path

import pytest

from fmvmg_sim.errors import InputError
from fmvmg_sim.validation.doc_blocks import read_block, replace_block

DOCS = Path(__file__).resolve().parents[1] / "docs"


def test_replace_block_keeps_the_prose_and_the_markers(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("intro\n<!-- generated: t (python make.py); do not edit -->\nold\n<!-- end generated: t -->\n"
                    "outro\n<!-- generated: tt (x) -->\nother\n<!-- end generated: tt -->\n")
    replace_block(page, "t", "| a |\n|---|\n| 1 |")
    text = page.read_text()
    assert "| 1 |\n<!-- end generated: t -->\noutro" in text
    assert "old" not in text and read_block(page, "tt") == "other\n" and read_block(page, "t") == "| a |\n|---|\n| 1 |\n"
    replace_block(page, "t", "new\n")
    assert read_block(page, "t") == "new\n" and text.count("outro") == 1


def test_missing_block_is_refused_and_nothing_is_written(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("no markers here\n")
    with pytest.raises(InputError, match="no generated block 'x'"):
        replace_block(page, "x", "table")
    assert page.read_text() == "no markers here\n"


def test_the_results_page_holds_its_generated_tables():
    """The simulated tables of the results page are the evaluation script's output, each between its markers."""
    page = DOCS / "compensation_results.md"
    assert "| method | filter τ (s) |" in read_block(page, "compensate-eval")
    assert "paper 000, Table 2" in read_block(page, "papers")
