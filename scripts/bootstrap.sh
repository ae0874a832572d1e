#!/usr/bin/env bash
# Set up everything on a fresh machine: a virtual environment in .venv with the package
# (editable) and its test extras. Idempotent: a second call only checks that it is up to date.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
    "$PY" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -e '.[test]'
