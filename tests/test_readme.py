"""The README's set-up, and the Python snippets of the user guide's *One simulation* page
(docs/guide/one_simulation.md), run as written."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import matplotlib
import pytest

README = Path(__file__).resolve().parent.parent / "README.md"
PAGE = README.parent / "docs" / "guide" / "one_simulation.md"
SNIPPETS = re.findall(r"```python\n(.*?)```", PAGE.read_text(), flags=re.S)


def test_the_page_has_python_snippets():
    assert len(SNIPPETS) >= 2


def test_the_readme_gives_the_two_commands():
    text = README.read_text()
    assert "bash scripts/bootstrap.sh && .venv/bin/nematic run campaigns/quickstart.yaml" in text
    assert "bash scripts/bootstrap.sh && .venv/bin/python -m pytest" in text


@pytest.mark.parametrize("index", range(len(SNIPPETS)))
def test_readme_snippet_runs(index):
    matplotlib.use("Agg")
    namespace: dict = {}
    exec(compile(SNIPPETS[index], f"{PAGE.name} python snippet {index + 1}", "exec"), namespace)
    if "final" in namespace:  # the py-pde snippet: the grid came from the 96^2 state
        assert namespace["final"].data.shape == (3, 96, 96)
        assert namespace["eq"].numerics.resolution == 96
    if "ds" in namespace:
        assert namespace["ds"].attrs["status"] == "ok"
        assert namespace["ds"].sizes["x"] == 96


def test_the_setup_puts_nematic_on_path_before_the_docs_use_it():
    """The docs write plain ``nematic``: the README's set-up says how it gets on PATH, and
    bootstrap.sh's last line says it too."""
    text = README.read_text()
    bash = "\n".join(re.findall(r"```bash\n(.*?)```", text, flags=re.S))
    assert "source .venv/bin/activate" in bash
    assert (Path(sys.executable).parent / "nematic").exists()  # activate puts this dir on PATH
    bootstrap = (README.parent / "scripts" / "bootstrap.sh").read_text()
    assert "source .venv/bin/activate" in bootstrap
