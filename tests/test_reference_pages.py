"""The campaign file reference (docs/campaigns/) and the model reference (docs/model/) as pages
one can read: every page of a section of the campaign file opens with what the section does,
then its keys as a table (key, type, default, meaning) and a complete example; every YAML
example of the reference is a campaign (or a collection) that the validator accepts; every
section of the campaign file has such a page; pages are short, and their headings are real
headings, not bold run-in text."""

from __future__ import annotations

import re
from importlib.util import find_spec
from pathlib import Path

import pytest

from nematic_solids.sweep.spec import SECTIONS, load_campaign
from nematic_solids.sweep.spec.collection import read_collection

DOCS = Path(__file__).resolve().parent.parent / "docs"
CAMPAIGNS = DOCS / "campaigns"

#: page of docs/campaigns/ -> the campaign-file sections (top-level keys) it is the reference of
SECTION_PAGES: dict[str, set[str]] = {
    "file.md": {"name", "description", "model", "parameters", "numerics", "limits"},
    "sweep.md": {"sweep", "seeds"},
    "store.md": {"store"},
    "protocols.md": {"protocol"},
    "chains.md": {"chain"},
    "refinement.md": {"refine"},
    "precision.md": {"precision"},
    "verification.md": {"verify"},
    "continuation.md": {"initial"},
    "execution.md": {"execution"},
    "clusters.md": set(),  # execution.cluster
    "accelerated.md": set(),  # execution.backend, batch, device
    "cost.md": {"prior"},
    "fits.md": {"fits"},
    "figures.md": {"figures"},
    "collection.md": set(),  # a collection file's keys
}
KEYS_HEADER = "| key | type | default | meaning |"
MAX_LINES = 250
YAML_BLOCK = re.compile(r"^```yaml\n(.*?)^```", flags=re.S | re.M)


def reference_pages() -> list[Path]:
    return sorted([*CAMPAIGNS.glob("*.md"), *(DOCS / "model").glob("*.md")])


def examples(page: Path) -> list[str]:
    return YAML_BLOCK.findall(page.read_text(encoding="utf-8"))


def keys_table(text: str) -> list[str]:
    """The first cells of the rows of the page's keys table (after ``## Keys``)."""
    after = text.split("\n## Keys\n", 1)[1]
    rows = re.findall(r"^\| (.*?) \|", after.split("\n## ", 1)[0], flags=re.M)
    return [r for r in rows[1:] if r]  # not the header (its rule has no "| ")


@pytest.mark.parametrize("page", sorted(SECTION_PAGES))
def test_a_section_page_opens_with_what_it_does_its_keys_and_an_example(page):
    text = (CAMPAIGNS / page).read_text(encoding="utf-8")
    lines = text.splitlines()
    assert lines[0].startswith("# "), f"{page}: no title"
    intro = text.split("\n\n", 2)[1]
    assert not intro.startswith(("#", "|", "```", "-")), f"{page}: no opening sentences"
    sentences = len(re.findall(r"[.!?](\s|$)", intro))
    assert sentences <= 2, f"{page}: opens with {sentences} sentences, not one or two"
    headings = re.findall(r"^## (.+)$", text, flags=re.M)
    assert headings[:2] == ["Keys", "Example"], f"{page}: its first headings are {headings[:2]}"
    assert KEYS_HEADER in text.split("\n## Example\n", 1)[0], f"{page}: no keys table"
    assert keys_table(text), f"{page}: an empty keys table"
    example = text.split("\n## Example\n", 1)[1].split("\n## ", 1)[0]
    assert "```yaml\n" in example, f"{page}: no YAML example under Example"


def test_every_section_of_the_campaign_file_has_its_page():
    documented: dict[str, str] = {}
    for page, sections in SECTION_PAGES.items():
        named = " ".join(keys_table((CAMPAIGNS / page).read_text(encoding="utf-8")))
        for section in sections:
            assert re.search(rf"`{section}(\.|`)", named), f"{section} not in {page}'s keys"
            documented[section] = page
    assert not {s.key for s in SECTIONS} - set(documented)


@pytest.mark.parametrize("page", sorted(p.name for p in CAMPAIGNS.glob("*.md")))
def test_every_yaml_example_of_the_reference_validates(page, tmp_path):
    """Each ```yaml block is a campaign file (or a collection file: ``campaigns:``) that the
    validator accepts. A block whose first line is ``# file: NAME.yaml`` is written under that
    name, so that another example of the page can name it (``initial.from``, a collection);
    they are written into a folder beside docs/, as campaigns/ is (``prior:`` names a shipped
    ``../docs/results/NAME/phase.nc``).
    An example of the accelerated backend needs JAX (the ``accel`` extra, which CI installs)."""
    folder = tmp_path / "campaigns"  # as the files of campaigns/ lie: ../docs/results/...
    folder.mkdir()
    (tmp_path / "docs").symlink_to(DOCS)
    blocks = examples(CAMPAIGNS / page)
    paths = []
    for i, block in enumerate(blocks):
        named = re.match(r"# file: (\S+\.yaml)\n", block)
        path = folder / (named.group(1) if named else f"example_{i}.yaml")
        path.write_text(block, encoding="utf-8")
        paths.append(path)
    without_jax = []
    for path in paths:
        if "backend: accelerated" in path.read_text() and find_spec("jax") is None:
            without_jax.append(path.name)  # refused without JAX, saying how to install it
        elif read_collection(path) is None:
            load_campaign(path)  # raises CampaignError, with the file:line, if refused
    if without_jax:
        pytest.skip(f"{page}: {without_jax} need JAX (pip install -e '.[accel]')")


@pytest.mark.parametrize("page", reference_pages(), ids=lambda p: f"{p.parent.name}/{p.name}")
def test_a_reference_page_is_short_with_real_headings(page):
    text = page.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= MAX_LINES, f"{page.name}: longer than {MAX_LINES} lines"
    body = re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)
    run_in = re.findall(r"^(?:[-*] )?\*\*[^*\n]+\*\*", body, flags=re.M)
    assert not run_in, f"{page.name}: bold run-in headings {run_in}; use a heading"
