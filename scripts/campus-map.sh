#!/usr/bin/env bash
# Localizes the shared Freiburg campus log (outdoors, 2,008 scans, 180°,
# 360 beams, reach about 80 m) on a map made from its own corrected poses
# (scripts/map-from-log.py --max-range 80), and simulated scans on that map,
# to measure how the method does outdoors (docs/results.md, "Outdoors: the
# Freiburg campus"). Nothing is fitted on it. Needs ../shared (logs) and
# numpy (python/target/venv, made by scripts/python-test.sh, or PYTHON=...).
#
#   scripts/campus-map.sh [OUT_DIR]   (default build-artifacts/campus-map)
#
# Three databases of the same map: `mapc build` defaults (30 m reach),
# --range-max 80, and --range-max 80 --unknown-free. About 4 minutes on 2
# cores after the release build; the databases take about 450 MB.
set -euo pipefail
cd "$(dirname "$0")/.."
O=${1:-build-artifacts/campus-map}
# shellcheck source=scripts/experiment-env.sh
source scripts/experiment-env.sh campus-map.sh logs/freiburg-campus
mkdir -p "$O"
L="$S/logs/freiburg-campus/freiburg-campus-corrected.log.gz"
"$PY" scripts/map-from-log.py "$L" "$O" campus --max-range 80
$M build -q "$O/campus.yaml" -o "$O/default.refdb"
$M build -q "$O/campus.yaml" --range-max 80 -o "$O/r80.refdb"
$M build -q "$O/campus.yaml" --range-max 80 --unknown-free -o "$O/r80-unknown-free.refdb"
sets=()
for d in default r80 r80-unknown-free; do
  $M localize -q --no-verify "$O/$d.refdb" "$L" --truth "$O/campus-truth.txt" > "$O/$d.jsonl"
  sets+=("campus-$d=$O/$d.jsonl")
done
python3 scripts/score-answers.py --truth given "${sets[@]}"
echo "simulated scans on the r80 database (200 poses, seed 1):"
for v in "180 361" "360 362"; do
  set -- $v
  $M eval -q --no-verify "$O/r80.refdb" --poses 200 --experiments static --fov "$1" --beams "$2" \
    --range-max 80 --no-figures --out "$O/eval-$1" > /dev/null
  python3 - "$O/eval-$1/report.json" "$1" << 'EOF'
import json, sys
r = json.load(open(sys.argv[1]))
s = r["summaries"]["static"]
print(f"  {sys.argv[2]:>3} deg static: accepted and correct {100 * s['success_rate']:.1f}%, "
      f"false accepts {100 * s['false_accept_rate']:.1f}%, "
      f"right site among the coarse candidates {100 * s['correct_site_recall']:.1f}%")
EOF
done
