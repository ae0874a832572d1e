#!/usr/bin/env bash
# Set up everything on a fresh machine: a virtual environment in .venv with the package
# (editable) and its test extras, then the model's numba kernels compiled once, in parallel
# processes (one per core, at most 8; 'bash scripts/bootstrap.sh --jobs N' to choose), cached
# on disk in model/compiled/__pycache__, so that no run, and no campaign worker, compiles them
# again.
# Idempotent: a second call only checks that it is up to date (the kernels load in seconds).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
    "$PY" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip
# the one note of setuptools on our layout (package-dir maps nematic_solids.* onto model/ and
# sweep/, installed editable through an import finder) is filtered by its message; pip's own
# warnings and every error still show
PYTHONWARNINGS="ignore:Editable installation" .venv/bin/python -m pip install --quiet -e '.[test]'
.venv/bin/python -m nematic_solids.model.warmup "$@"
echo "ready: .venv/bin/nematic (or 'source .venv/bin/activate' to put nematic on your PATH)"
