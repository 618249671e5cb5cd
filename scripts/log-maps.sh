#!/usr/bin/env bash
# Localizes each shared real log on maps made from that log's own corrected
# poses (scripts/map-from-log.py), where the map agrees with the truth, and
# prints accepted-and-correct / false accepts against the given truth
# (docs/results.md, "Maps made from the logs themselves"). Needs ../shared
# (logs) and numpy (the Python package's venv, python/target/venv, made by
# scripts/python-test.sh, or PYTHON=...).
#
#   scripts/log-maps.sh [OUT_DIR]   (default build-artifacts/log-maps)
#
# Two settings per log:
#   self  the map from every scan; every scan localized on it;
#   half  two maps, from the first and from the second half of the scans;
#         each scan localized on the map of the other half (another time of
#         the same building: people, doors, and places that half never saw).
# About 2 minutes on 2 cores after the release build.
set -euo pipefail
cd "$(dirname "$0")/.."
O=${1:-build-artifacts/log-maps}
# shellcheck source=scripts/experiment-env.sh
source scripts/experiment-env.sh log-maps.sh logs
mkdir -p "$O"
for m in intel aces csail; do
  L="$S/logs/$m/$m-corrected.log.gz"
  n=$(zcat "$L" | grep -c '^FLASER')
  h=$((n / 2))
  "$PY" scripts/map-from-log.py "$L" "$O" "$m-self"
  "$PY" scripts/map-from-log.py "$L" "$O" "$m-h1" --map-scans ":$h"
  "$PY" scripts/map-from-log.py "$L" "$O" "$m-h2" --map-scans "$h:"
  for p in self h1 h2; do
    $M build -q "$O/$m-$p.yaml" -o "$O/$m-$p.refdb"
    $M localize -q --no-verify "$O/$m-$p.refdb" "$L" --truth "$O/$m-self-truth.txt" > "$O/$m-$p.jsonl"
  done
  # Each scan on the map of the half it is not in.
  { tail -n +$((h + 1)) "$O/$m-h1.jsonl"; head -n "$h" "$O/$m-h2.jsonl"; } > "$O/$m-half.jsonl"
done
sets=()
for m in intel aces csail; do
  for s in self half; do sets+=("$m-$s=$O/$m-$s.jsonl"); done
done
python3 scripts/score-answers.py --truth given "${sets[@]}"
