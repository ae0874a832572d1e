"""The documentation site's table of contents (docs/conf.py; built by scripts/build_docs.sh,
which CI runs): every page under docs/ is in a toctree, so none is left out of the site's
navigation, and every toctree entry is a page."""

from __future__ import annotations

import re
from pathlib import Path

DOCS = Path(__file__).resolve().parent.parent / "docs"
#: folders of docs/ that hold no pages of their own (build output, generated, committed results)
NOT_PAGES = {"_build", "_generated", "results", "figures", ".ipynb_checkpoints"}
TOCTREE = re.compile(r"```\{toctree\}\n(.*?)```", flags=re.S)


def pages() -> set[str]:
    found = set()
    for path in DOCS.rglob("*"):
        rel = path.relative_to(DOCS)
        if path.suffix in (".md", ".rst", ".ipynb") and not NOT_PAGES & set(rel.parts):
            found.add(rel.with_suffix("").as_posix())
    return found


def toctree_entries() -> dict[str, set[str]]:
    """Page -> the pages its toctrees list (paths relative to docs/, no suffix)."""
    out: dict[str, set[str]] = {}
    for page in pages():
        path = next(DOCS.glob(page + ".*"))
        if path.suffix != ".md":
            continue
        entries = set()
        for block in TOCTREE.findall(path.read_text()):
            for line in block.splitlines():
                line = line.strip()
                if line and not line.startswith(":"):
                    entries.add((Path(page).parent / line).as_posix().removeprefix("./"))
        out[page] = entries
    return out


def test_every_page_is_in_a_toctree():
    listed = set().union(*toctree_entries().values())
    orphans = pages() - listed - {"index"}
    assert not orphans, f"pages in no toctree (add them to docs/index.md): {sorted(orphans)}"


def test_every_toctree_entry_is_a_page():
    missing = {
        f"{page}: {entry}"
        for page, entries in toctree_entries().items()
        for entry in entries
        if entry not in pages()
    }
    assert not missing, f"toctree entries that are no page: {sorted(missing)}"


def test_the_api_reference_documents_the_installed_package():
    """autodoc imports what its directives name: ``nematic_solids.model...`` and
    ``nematic_solids.sweep...``, never the folders as top-level packages ``model`` and
    ``sweep`` (which the build's working folder would let it import beside the installed
    package)."""
    targets = [
        (path.name, target)
        for path in (DOCS / "api").glob("*")
        for target in re.findall(r"^\.\. auto\w+:: (\S+)", path.read_text(), flags=re.M)
    ]
    assert targets
    bad = [t for t in targets if not t[1].startswith("nematic_solids.")]
    assert not bad, bad
