"""The command line's help and the reference name everything the registries hold: every
registered figure and fit in ``nematic figures --help`` (which the command reference
docs/_generated/cli.md is generated from) and under its own heading in docs/campaigns/, and
every top-level section of the campaign file in the campaign file's table; ``nematic run
--help`` fits an 80-column terminal without cutting a word."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from nematic_solids.sweep.analysis.registry import REGISTRY as FITS
from nematic_solids.sweep.cli import COMMANDS, app
from nematic_solids.sweep.figures.registry import REGISTRY as FIGURES
from nematic_solids.sweep.spec import SECTIONS

DOCS = Path(__file__).resolve().parent.parent / "docs" / "campaigns"


def help_text(*command: str, columns: int = 80) -> str:
    result = CliRunner().invoke(app, [*command, "--help"], env={"COLUMNS": str(columns)})
    assert result.exit_code == 0, result.output
    return result.output


def flat(text: str) -> str:
    return " ".join(text.split())


def headings(page: str) -> set[str]:
    """The names in backticks that open the page's headings (``## `fig2` (paper Fig. 2)``)."""
    text = (DOCS / page).read_text()
    return set(re.findall(r"^#+ `([^`]+)`", text, flags=re.M))


def test_figures_help_names_every_registered_figure_and_fit():
    text = flat(help_text("figures"))
    only = text[text.index("--only") :]
    missing = [name for name in FIGURES if not re.search(rf"\b{name}\b", only)]
    assert not missing, f"figures missing from `nematic figures --help`: {missing}"
    missing = [name for name in FITS if not re.search(rf"\b{name}\b", only)]
    assert not missing, f"fits missing from `nematic figures --help`: {missing}"
    assert "{figures}" not in text
    assert "{fits}" not in text


@pytest.mark.parametrize(
    ("registry", "page"), [(FIGURES, "figures.md"), (FITS, "fits.md")], ids=["figures", "fits"]
)
def test_every_registered_name_has_its_heading_in_the_reference(registry, page):
    documented = headings(page)
    assert not set(registry) - documented, f"registered, not in docs/campaigns/{page}"
    assert not documented - set(registry), f"in docs/campaigns/{page}, not registered"


def test_every_section_of_the_campaign_file_is_in_its_table():
    text = (DOCS / "file.md").read_text()
    rows = " ".join(re.findall(r"^\| (`[^|]+)\|", text, flags=re.M))
    named = set(re.findall(r"`([a-z_]+)(?:\.[a-z_]+)?`", rows))
    missing = sorted({s.key for s in SECTIONS} - named)
    assert not missing, f"sections of the campaign file not in docs/campaigns/file.md: {missing}"


@pytest.mark.parametrize("command", list(COMMANDS))
def test_help_fits_80_columns_without_cutting_words(command):
    text = help_text(command)
    assert all(len(line) <= 80 for line in text.splitlines())
    assert "…" not in text  # a word cut to fit a column
    assert not re.search(r"\w-\n\s+\w", text), "a word or option split at its hyphen"
    if command == "run":
        assert len(text.splitlines()) <= 64  # a screen; the details are in docs/campaigns/
