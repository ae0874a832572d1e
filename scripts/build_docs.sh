#!/usr/bin/env bash
# The documentation site (docs/conf.py): docs/_build/html/index.html, built from scratch with
# warnings as errors; the notebook is executed during the build. CI runs this (.ci/run).
#
#   bash scripts/build_docs.sh               # installs the docs extra into .venv first
#   bash scripts/build_docs.sh --no-install  # the docs extra is installed already
#
# PYTHON=... picks another interpreter (default .venv/bin/python, made by bootstrap.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-.venv/bin/python}
if [ "${1:-}" != "--no-install" ]; then
    # the one note of setuptools on our layout (package-dir maps nematic_solids.* onto model/
    # and sweep/, installed editable through an import finder): filtered by its message
    PYTHONWARNINGS="ignore:Editable installation" "$PY" -m pip install -q -e '.[docs]'
fi
rm -rf docs/_build docs/_generated
start=$(date +%s)
# -q: warnings and errors only (not the extensions' configuration dumps and progress lines)
MPLBACKEND=Agg "$PY" -m sphinx -q -W --keep-going -b html docs docs/_build/html
# the site works offline: no page loads a script, style, image or frame from elsewhere (the
# committed reports under _downloads/ are the program's pages, checked by its own tests)
if grep -rlE '<(script|img|link|iframe|source)[^>]*(src|href)="(https?:)?//' docs/_build/html \
    --include='*.html' --exclude-dir=_downloads; then
    echo "error: the pages above load resources from outside the site" >&2
    exit 1
fi
echo "docs built in $(( $(date +%s) - start )) s: docs/_build/html/index.html"
