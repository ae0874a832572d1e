"""Sphinx configuration of the documentation site (build: scripts/build_docs.sh).

The site is built offline: the Markdown pages are read by myst-parser, the API reference is
generated from the docstrings (autodoc + napoleon), the command-line reference from the typer
application (``typer ... utils docs``, the source of ``nematic --help``) and the notebook is
executed by myst-nb at every build.
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
# the package (nematic_solids) comes from the environment's install (scripts/build_docs.sh
# installs the checkout, editable); the notebook's kernel draws without a display
os.environ.setdefault("MPLBACKEND", "Agg")
# the notebook's kernel (ipykernel) logs errors only: its note that it listens on a local TCP
# port without encryption is not the build's business; an error in a cell fails the build
_profile = DOCS / "_generated" / "ipython" / "profile_default"
_profile.mkdir(parents=True, exist_ok=True)
(_profile / "ipython_kernel_config.py").write_text('c.IPKernelApp.log_level = "ERROR"\n')
os.environ["IPYTHONDIR"] = str(_profile.parent)
# the root logger shows warnings and errors of the libraries that log there; configured here,
# before the theme's accessible-pygments calls logging.basicConfig(level=INFO) on import (which
# would print nbclient's "Executing notebook" line)
logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")

project = "Active nematic solids"
author = "the active-nematic-solids developers"
copyright = "the active-nematic-solids developers"

extensions = [
    "myst_nb",  # Markdown (myst-parser) and notebooks
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx-mathjax-offline",  # MathJax 3 copied into the site (no CDN)
]

exclude_patterns = ["_build", "_generated", "**.ipynb_checkpoints"]
source_suffix = {".md": "myst-nb", ".ipynb": "myst-nb", ".rst": "restructuredtext"}

# text as written: "--set" stays two hyphens (the command reference), quotes stay straight
smartquotes = False

# --- Markdown ---
myst_enable_extensions = ["dollarmath", "amsmath"]
myst_heading_anchors = 4

# --- notebooks: executed at every build; an error fails the build ---
nb_execution_mode = "force"
nb_execution_raise_on_error = True
nb_execution_timeout = 600
nb_execution_show_tb = True

# --- API reference ---
autodoc_member_order = "bysource"
# names that the modules import for type checking only, as the signatures show them
autodoc_type_aliases = {
    "Campaign": "nematic_solids.sweep.campaign.Campaign",
    "Expansion": "nematic_solids.sweep.expand.Expansion",
}
# every cross-reference must resolve (warnings are errors): the project's own types are
# documented here; other libraries' types (no intersphinx: the site builds offline), module
# references (docs/architecture.md maps the modules) and the internals the docstrings name
# stay plain text
nitpicky = True
nitpick_ignore_regex = [
    (
        r"py:.*",
        r"(numpy|np|xarray|xr|pandas|pd|pathlib|collections\.abc|typing|jax|jaxlib|pde)\..*",
    ),
    (r"py:class", r"Path|Array|ArrayLike|NDArray|PDEBase|optional"),
    # py-pde's own annotation of a boundary condition (a subclass of its SwiftHohenbergPDE)
    (r"py:class", r"BoundariesData"),
    # the grid's points and runs (sweep.expand) appear in signatures, documented with Expansion
    (r"py:class", r"(nematic_solids\.sweep\.expand\.)?(GridPoint|RunSpec)"),
    (r"py:meth", r"~?Mechanics\..*"),
    (r"py:mod", r"nematic_solids\..*"),
    (r"py:.*", r"nematic_solids\.sweep\.spec\.yaml_input\..*"),
    (
        r"py:.*",
        r"nematic_solids\.model\.(observables|split|krylov|initial|mechanics|tensors|time_scales|accelerated\.etdrk4)\..*",
    ),
]
autodoc_typehints = "description"
autodoc_default_options: dict[str, bool] = {}
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_ivar = True

# --- HTML ---
html_theme = "furo"
html_title = project
# no footer links to the theme's and Sphinx's sites: the pages reference nothing outside the site
html_show_sphinx = False
html_static_path: list[str] = []


def _cli_page() -> None:
    """docs/_generated/cli.md, written by typer from the ``nematic`` application
    (:data:`nematic_solids.sweep.cli.app`): the texts of ``nematic --help`` and ``nematic COMMAND
    --help``."""
    out = DOCS / "_generated" / "cli.md"
    out.parent.mkdir(exist_ok=True)
    command = [
        sys.executable,
        "-m",
        "typer",
        "--app",
        "app",
        "nematic_solids.sweep.cli",
        "utils",
        "docs",
    ]
    done = subprocess.run(
        [*command, "--name", "nematic", "--output", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        raise RuntimeError(f"the command reference could not be generated:\n{done.stderr}")


_cli_page()
