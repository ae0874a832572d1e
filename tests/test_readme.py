"""The README's Python snippets run as written."""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib
import pytest

README = Path(__file__).resolve().parent.parent / "README.md"
SNIPPETS = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)


def test_the_readme_has_python_snippets():
    assert len(SNIPPETS) >= 2


@pytest.mark.parametrize("index", range(len(SNIPPETS)))
def test_readme_snippet_runs(index):
    matplotlib.use("Agg")
    namespace: dict = {}
    exec(compile(SNIPPETS[index], f"README.md python snippet {index + 1}", "exec"), namespace)
    if "final" in namespace:  # the py-pde snippet: the grid came from the 48^2 state
        assert namespace["final"].data.shape == (3, 48, 48)
        assert namespace["eq"].numerics.resolution == 48
    if "ds" in namespace:
        assert namespace["ds"].attrs["status"] == "ok"
        assert namespace["ds"].sizes["x"] == 48
