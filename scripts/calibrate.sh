#!/usr/bin/env bash
# The calibration study of docs/results.md: the Fig. 2 jump at reduced size (campaigns/
# calibration.yaml) for the default constants and for each omitted constant varied on its own.
# Resumable like any campaign (rerun to finish); prints the table at the end.
#   bash scripts/calibrate.sh            # every variant
#   bash scripts/calibrate.sh C=2 s=20   # only these variants (and the baseline)
set -euo pipefail
cd "$(dirname "$0")/.."
NEMATIC=${NEMATIC:-.venv/bin/nematic}
PY=${PY:-.venv/bin/python}
if [ "$#" -gt 0 ]; then
  variants=("$@")
else
  variants=(C=2 C=5 s=5 s=20 zeta=0.5 zeta=2 kappa=5 kappa=20
            noise_amplitude=0.03 noise_amplitude=0.1 noise_modes=8)
fi
names=(calib-base)
"$NEMATIC" run campaigns/calibration.yaml --name calib-base || true
for v in "${variants[@]}"; do
  name="calib-${v/=/-}"
  names+=("$name")
  "$NEMATIC" run campaigns/calibration.yaml --set "$v" --name "$name" || true
done
"$PY" scripts/calibration_table.py "${names[@]/#/results/}"
