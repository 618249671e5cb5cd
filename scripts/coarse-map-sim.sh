#!/usr/bin/env bash
# Scans simulated on the shared maps of 0.05 m cells by
# scripts/independent-sim.py, localized on those maps resampled to 0.1 m
# cells (scripts/resample-map.py --coarser): a world finer than its map,
# as every real map is. Prints accepted-and-correct / false accepts per
# map and class (docs/results.md, "Coarse maps: beams past the cell's
# face"). Needs ../shared (maps) and numpy (python/target/venv, made by
# scripts/python-test.sh, or PYTHON=...).
#
#   scripts/coarse-map-sim.sh [OUT_DIR] [POSES]
#                             (default build-artifacts/coarse-map-sim, 300)
#
# Intel and ACES at 180 degrees (361 beams), ACES at 360 degrees (360
# beams); 30 m reach; seed 5 (SEED=...), the same scans as
# scripts/independent-sim.sh. About 15 minutes on 2 cores after the
# release build (the simulator is plain numpy).
set -euo pipefail
cd "$(dirname "$0")/.."
O=${1:-build-artifacts/coarse-map-sim}
N=${2:-300}
# shellcheck source=scripts/experiment-env.sh
source scripts/experiment-env.sh coarse-map-sim.sh maps
mkdir -p "$O"
classes="static noise people clutter shifted"
sets=()
for spec in intel:180:361 aces:180:361 aces:360:360; do
  IFS=: read -r m fov beams <<< "$spec"
  coarse="$m-0.1"
  if [ ! -s "$O/$coarse.refdb" ]; then
    "$PY" scripts/resample-map.py "$S/maps/$m/$m.yaml" "$O" "$coarse" --coarser
    $M build -q "$O/$coarse.yaml" -o "$O/$coarse.refdb"
  fi
  d="$O/$m-$fov"
  "$PY" scripts/independent-sim.py "$S/maps/$m/$m.yaml" "$d" --poses "$N" --seed "${SEED:-5}" \
    --fov "$fov" --beams "$beams" --classes "${classes// /,}" 2> /dev/null
  for c in $classes; do
    $M localize -q --no-verify "$O/$coarse.refdb" "$d/$c-scans.jsonl" --truth "$d/$c-truth.txt" \
      > "$d/$c.jsonl"
    sets+=("$m-$fov-$c=$d/$c.jsonl")
  done
done
python3 scripts/score-answers.py --truth given "${sets[@]}"
