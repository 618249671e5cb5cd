#!/usr/bin/env bash
# Peers side by side on the same map and scans; prints one table.
# See bench/peers/README.md. Run from anywhere:  bench/peers/run.sh
#
# Environment (defaults):
#   MAP=<shared>/maps/intel/intel.yaml   N_QUERIES=30   E1_TRIALS=500   SEED=1
#   MRPT_PARTICLES=300000   MRPT_STEPS=30   SCAN_SET=dynamic (or static)
#   REPEAT=11 (timed runs per compile stage)   SKIP_MRPT=0   SKIP_INSTALL=0
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$ROOT"
SHARED="${SHARED:-$ROOT/../shared}"
[ -d "$SHARED/maps" ] || SHARED=/work/shared
MAP="${MAP:-$SHARED/maps/intel/intel.yaml}"
N_QUERIES="${N_QUERIES:-30}"
E1_TRIALS="${E1_TRIALS:-500}"
SEED="${SEED:-1}"
MRPT_PARTICLES="${MRPT_PARTICLES:-300000}"
MRPT_STEPS="${MRPT_STEPS:-30}"
SCAN_SET="${SCAN_SET:-dynamic}"
REPEAT="${REPEAT:-11}"
WORK="$ROOT/build-artifacts/peers"
VENV="$ROOT/build-artifacts/peers-venv"
MRPT_VERSION="1:2.5.8+ds-2"   # Debian 12 (bookworm)

note() { echo "[peers] $*" >&2; }
[ -f "$MAP" ] || { note "map not found: $MAP"; exit 2; }

# ---- installs (pinned) -------------------------------------------------------
if [ "${SKIP_INSTALL:-0}" != 1 ]; then
  if ! command -v pf-localization >/dev/null || ! command -v carmen2rawlog >/dev/null \
     || ! command -v ros-map-yaml2mrpt >/dev/null; then
    note "installing mrpt-apps=$MRPT_VERSION (apt)"
    SUDO=""; [ "$(id -u)" = 0 ] || SUDO=sudo
    $SUDO apt-get update -q >/dev/null
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends \
      "mrpt-apps=$MRPT_VERSION" >/dev/null
  fi
  stamp="$VENV/.peers-$(cat bench/peers/requirements.txt bench/peers/constraints.txt | sha256sum | cut -c1-16)"
  if [ ! -f "$stamp" ]; then
    note "creating $VENV (pip: $(tr '\n' ' ' < bench/peers/requirements.txt))"
    python3 -m venv "$VENV" || { note "python3 -m venv failed: apt-get install python3-venv"; exit 2; }
    "$VENV/bin/pip" install -q --upgrade pip >/dev/null
    "$VENV/bin/pip" install -q -r bench/peers/requirements.txt -c bench/peers/constraints.txt
    touch "$stamp"
  fi
fi
PY="$VENV/bin/python"

# ---- our side: build, dump the shared inputs, time our stages ----------------
note "cargo build --release -p mapc"
cargo build --release -q -p mapc
MAPC="$ROOT/target/release/mapc"
rm -rf "$WORK"; mkdir -p "$WORK"
note "mapc build $MAP"
"$MAPC" -q build "$MAP" -o "$WORK/map.refdb"
note "mapc stages (1 thread, then all threads), $REPEAT runs each"
"$MAPC" -q --threads 1 stages "$MAP" --out "$WORK/stages-1t" --repeat "$REPEAT" >/dev/null
"$MAPC" -q stages "$MAP" --out "$WORK/stages-2t" --repeat "$REPEAT" >/dev/null
note "mapc eval: $N_QUERIES $SCAN_SET scans, $E1_TRIALS E1 pairs (1 thread), dumped to $WORK/data"
"$MAPC" --threads 1 eval "$WORK/map.refdb" --poses "$N_QUERIES" --seed "$SEED" \
  --experiments "$SCAN_SET,e1" --e1-trials "$E1_TRIALS" --no-figures \
  --out "$WORK/eval" --dump "$WORK/data" 2> "$WORK/eval.log"
cat "$WORK/eval.log" >&2
note "mapc localize on the dumped scans"
"$MAPC" localize "$WORK/map.refdb" "$WORK/data/$SCAN_SET-scans.jsonl" \
  --truth "$WORK/data/$SCAN_SET-truth.txt" --no-candidates > "$WORK/ours-localize.jsonl" 2> "$WORK/localize.log"
cat "$WORK/localize.log" >&2

# ---- the peers, sequentially, one thread each --------------------------------
skip=(); [ "${SKIP_MRPT:-0}" = 1 ] && skip=(--skip-mrpt)
PYTHONDONTWRITEBYTECODE=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 "$PY" bench/peers/peers.py \
  --work "$WORK" --map-name "$(basename "$MAP" .yaml)" --scan-set "$SCAN_SET" --repeat "$REPEAT" \
  --mrpt-particles "$MRPT_PARTICLES" --mrpt-steps "$MRPT_STEPS" "${skip[@]}"
note "machine: $(nproc) cores, $(lscpu | sed -n 's/^Model name: *//p'); $(date -u +%Y-%m-%d)"
note "table: $WORK/table.md; details: $WORK/results.json"
