#!/usr/bin/env bash
# The accelerated backend's device check (benchmarks/device_check.py: agreement with the numpy
# reference, float64 and float32 timings at 128^2-512^2, one table and a JSON file; exit 1 if the
# agreement fails), for a machine with JAX (and CUDA) installed and no network: what the check
# needs and the machine lacks is installed, without dependencies and without an index, from the
# wheels that `bash benchmarks/device_wheels.sh` put in benchmarks/device_wheels/.
#   bash benchmarks/device_check.sh [--out FILE] [--budget SECONDS]   # on the GPU machine
#   bash benchmarks/device_check.sh --tiny                             # CI, on the CPU
# PYTHON chooses the interpreter (default: .venv/bin/python if there is one, else python3).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -z "${PYTHON:-}" ]; then
    if [ -x .venv/bin/python ]; then PYTHON=.venv/bin/python; else PYTHON=python3; fi
fi
wheels=benchmarks/device_wheels
# module to import -> the wheel that provides it (installed only where the import fails)
for pair in nematic_solids.model.parameters:active_nematic_solids pde:py_pde sympy:sympy \
    mpmath:mpmath tqdm:tqdm; do
    module=${pair%%:*}
    wheel=${pair##*:}
    if "$PYTHON" -c "import $module" >/dev/null 2>&1; then
        continue
    fi
    found=$(ls "$wheels"/"$wheel"-*.whl 2>/dev/null | head -1 || true)
    if [ -z "$found" ]; then
        echo "device check: $module cannot be imported and $wheels/ has no $wheel wheel;" \
            "build the folder with: bash benchmarks/device_wheels.sh" >&2
        exit 2
    fi
    "$PYTHON" -m pip install -q --no-deps --no-index "$found"
done
exec "$PYTHON" benchmarks/device_check.py "$@"
