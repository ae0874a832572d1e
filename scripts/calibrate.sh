#!/usr/bin/env bash
# The joint calibration of docs/results.md ("Calibration"): campaigns/calibration.yaml (Fig. 2's
# jump at K = 5e-5, alpha_cr(K) and Fig. 3's lambda_peak(alpha - B) at each K) for each setting,
# then the table and the trade-off figure (scripts/calibration_table.py).
# A setting is NAME=VALUE[,NAME=VALUE...] (any parameter), applied on top of the scan's base
# (band 16, zeta = 1, kappa = 10; the other constants at the model's defaults), so a setting
# names the same runs whatever the model's defaults are. Its folder is results/calib-<setting>
# with '=' written '-' and ',' written '_'. Resumable like any campaign (rerun to finish).
#   bash scripts/calibrate.sh                                 # the settings of docs/results.md
#   bash scripts/calibrate.sh initial=per_node,zeta=0.5       # only these
set -euo pipefail
cd "$(dirname "$0")/.."
NEMATIC=${NEMATIC:-.venv/bin/nematic}
PY=${PY:-.venv/bin/python}
BASE="noise_modes=16,zeta=1,kappa=10"
CHOSEN="noise_modes=32,zeta=0.5,kappa=20"   # the model's defaults (docs/model/constants.md)
if [ "$#" -gt 0 ]; then
  settings=("$@")
else
  settings=(initial=per_node noise_modes=16 noise_modes=24 noise_modes=32 noise_modes=48
            noise_modes=24,zeta=0.7 noise_modes=24,zeta=0.5 noise_modes=32,zeta=0.5
            noise_modes=32,zeta=0.4 noise_modes=48,zeta=0.5 noise_modes=48,zeta=0.4
            noise_modes=32,zeta=0.5,s=5 noise_modes=32,zeta=0.5,s=20
            noise_modes=32,zeta=0.5,C=2 "$CHOSEN" noise_modes=40,zeta=0.5,s=5)
fi
names=()
for setting in "${settings[@]}"; do
  name="calib-$(echo "$setting" | sed 's/=/-/g; s/,/_/g')"
  names+=("results/$name")
  declare -A value=()
  order=()
  IFS=',' read -ra pairs <<< "$BASE,$setting"
  for pair in "${pairs[@]}"; do
    key=${pair%%=*}
    [ -n "${value[$key]+set}" ] || order+=("$key")
    value[$key]=${pair#*=}
  done
  args=()
  for key in "${order[@]}"; do args+=(--set "$key=${value[$key]}"); done
  unset value
  "$NEMATIC" run campaigns/calibration.yaml "${args[@]}" --name "$name" || true
done
"$PY" scripts/calibration_table.py --json results/calibration_table.json \
  --figure results/calibration_tradeoff.png \
  --chosen "calib-$(echo "$CHOSEN" | sed 's/=/-/g; s/,/_/g')" "${names[@]}"
