#!/usr/bin/env bash
# Localizes each shared real log on maps of 0.025 m and 0.1 m cells and
# prints accepted-and-correct / false accepts against the locally corrected
# truth (docs/results.md, "Maps of other resolutions"): the shared map
# resampled (scripts/resample-map.py: cells split in four, or 2 x 2 merged)
# and a map made from the log itself at that cell
# (scripts/map-from-log.py --res). Needs ../shared (maps, logs) and numpy
# (python/target/venv, made by scripts/python-test.sh, or PYTHON=...).
#
#   scripts/resolution-maps.sh [OUT_DIR]   (default build-artifacts/resolution-maps)
#
# About 5 minutes on 2 cores after the release build.
set -euo pipefail
cd "$(dirname "$0")/.."
O=${1:-build-artifacts/resolution-maps}
# shellcheck source=scripts/experiment-env.sh
source scripts/experiment-env.sh resolution-maps.sh maps logs
mkdir -p "$O"
for m in intel aces csail; do
  L="$S/logs/$m/$m-corrected.log.gz"
  "$PY" scripts/resample-map.py "$S/maps/$m/$m.yaml" "$O" "$m-resampled-0.025" --finer
  "$PY" scripts/resample-map.py "$S/maps/$m/$m.yaml" "$O" "$m-resampled-0.1" --coarser
  for r in 0.025 0.1; do
    "$PY" scripts/map-from-log.py "$L" "$O" "$m-made-$r" --res "$r"
    for kind in resampled made; do
      n="$m-$kind-$r"
      truth="$S/logs/$m/$m-poses-in-map.txt"
      [ "$kind" = made ] && truth="$O/$n-truth.txt"
      $M build -q "$O/$n.yaml" -o "$O/$n.refdb"
      $M localize -q --no-verify "$O/$n.refdb" "$L" --truth "$truth" > "$O/$n.jsonl"
    done
  done
done
sets=()
for m in intel aces csail; do
  for kind in resampled made; do
    for r in 0.025 0.1; do sets+=("$m $kind $r m=$O/$m-$kind-$r.jsonl"); done
  done
done
python3 scripts/score-answers.py --truth corrected "${sets[@]}"
