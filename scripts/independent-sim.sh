#!/usr/bin/env bash
# Localizes scans of scripts/independent-sim.py (a simulator with no refloc
# code: the world is the map's occupied cells, people and boxes stand in the
# free space, every disturbed class also has range noise; since 2026-12-07
# also map obstacles erased, a world shifted against the map and scans
# taken while turning and driving) on databases made
# with `mapc build` defaults, and prints accepted-and-correct / false
# accepts per map and class (docs/results.md, "An independent simulator").
# Needs ../shared (maps) and numpy (python/target/venv, made by
# scripts/python-test.sh, or PYTHON=...).
#
#   scripts/independent-sim.sh [OUT_DIR] [POSES]
#                              (default build-artifacts/independent-sim, 300)
#
# Intel, CSAIL and ACES at 360 degrees (360 beams), Intel and ACES at 180
# degrees (361 beams); 30 m reach; seed 5 (SEED=...). About 25 minutes on
# 2 cores after the release build (the simulator is plain numpy).
set -euo pipefail
cd "$(dirname "$0")/.."
O=${1:-build-artifacts/independent-sim}
N=${2:-300}
# shellcheck source=scripts/experiment-env.sh
source scripts/experiment-env.sh independent-sim.sh maps
mkdir -p "$O"
classes="static noise people clutter dropouts removed shifted motion"
sets=()
for spec in intel:360:360 csail:360:360 aces:360:360 intel:180:361 aces:180:361; do
  IFS=: read -r m fov beams <<< "$spec"
  d="$O/$m-$fov"
  [ -s "$O/$m.refdb" ] || $M build -q "$S/maps/$m/$m.yaml" -o "$O/$m.refdb"
  "$PY" scripts/independent-sim.py "$S/maps/$m/$m.yaml" "$d" --poses "$N" --seed "${SEED:-5}" --fov "$fov" \
    --beams "$beams" --classes "${classes// /,}" 2> /dev/null
  for c in $classes; do
    $M localize -q --no-verify "$O/$m.refdb" "$d/$c-scans.jsonl" --truth "$d/$c-truth.txt" > "$d/$c.jsonl"
    sets+=("$m-$fov-$c=$d/$c.jsonl")
  done
done
python3 scripts/score-answers.py --truth given "${sets[@]}"
