#!/usr/bin/env bash
# The joint calibration of docs/results.md ("Calibration"): campaigns/calibration.yaml (Fig. 2's
# jump at K = 5e-5, alpha_cr(K) and Fig. 3's lambda_peak(alpha - B) at each K) for the model's
# defaults and for each setting given, then the table (scripts/calibration_table.py).
# A setting is NAME=VALUE[,NAME=VALUE...] (any parameter); its folder is results/calib-<setting>
# with '=' written '-' and ',' written '_'. Resumable like any campaign (rerun to finish).
#   bash scripts/calibrate.sh                                 # the settings of docs/results.md
#   bash scripts/calibrate.sh initial=per_node,zeta=0.5       # only these (and the defaults)
set -euo pipefail
cd "$(dirname "$0")/.."
NEMATIC=${NEMATIC:-.venv/bin/nematic}
PY=${PY:-.venv/bin/python}
if [ "$#" -gt 0 ]; then
  settings=("$@")
else
  settings=(noise_modes=16 noise_modes=24 noise_modes=32 noise_modes=48 noise_modes=63
            initial=per_node)
fi
names=(calib-defaults)
"$NEMATIC" run campaigns/calibration.yaml --name calib-defaults || true
for setting in "${settings[@]}"; do
  name="calib-$(echo "$setting" | sed 's/=/-/g; s/,/_/g')"
  names+=("$name")
  args=()
  IFS=',' read -ra pairs <<< "$setting"
  for pair in "${pairs[@]}"; do args+=(--set "$pair"); done
  "$NEMATIC" run campaigns/calibration.yaml "${args[@]}" --name "$name" || true
done
"$PY" scripts/calibration_table.py --json results/calibration_table.json "${names[@]/#/results/}"
