#!/usr/bin/env bash
# The wheels benchmarks/device_check.sh installs on a machine without network (JAX with CUDA,
# numpy, scipy, xarray, numba, pandas, matplotlib, typer, rich and pyyaml there already): this
# project's own wheel, and py-pde (which the model's PDE and the reference import) with the needs
# of it that such a machine lacks (sympy, mpmath, tqdm), at the versions installed here.
#   bash benchmarks/device_wheels.sh            # -> benchmarks/device_wheels/ (git-ignored)
# Carry that folder with the repository to the machine; at most 40 MB (checked).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-.venv/bin/python}
out=benchmarks/device_wheels
rm -rf "$out"
mkdir -p "$out"
"$PY" -m pip wheel -q --no-deps --wheel-dir "$out" .
for pkg in py-pde sympy mpmath tqdm; do
    version=$("$PY" -c "import importlib.metadata as m; print(m.version('$pkg'))")
    "$PY" -m pip download -q --no-deps --only-binary=:all: --dest "$out" "$pkg==$version"
done
size=$(du -sm "$out" | cut -f1)
ls -1 "$out"
echo "$out: ${size} MB"
if [ "$size" -gt 40 ]; then
    echo "the wheels take ${size} MB, over the 40 MB that the device machine may carry" >&2
    exit 1
fi
