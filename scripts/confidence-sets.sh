#!/usr/bin/env bash
# Builds the answer sets that scripts/fit-confidence.py fits and tests the
# confidence model on (docs/confidence.md): the shared real logs against
# their truth, simulated scans of several maps (`mapc eval --dump`), and
# scans localized on another building's map. Needs ../shared (maps, logs).
#
#   scripts/confidence-sets.sh [OUT_DIR]   (default build-artifacts/conf)
#
# Prints the --train and --test arguments for scripts/fit-confidence.py.
# Seed 11 makes the fitting sets, seed 12 the held-out ones. About 7
# minutes on 2 cores after the release build.
set -euo pipefail
cd "$(dirname "$0")/.."
S=${SHARED:-../shared}
O=${1:-build-artifacts/conf}
M=target/release/mapc
if [ ! -d "$S/maps" ] || [ ! -d "$S/logs" ]; then
  echo "confidence-sets.sh: needs the shared maps and logs at $S (set SHARED=...)" >&2
  exit 2
fi
cargo build --release -q -p mapc
mkdir -p "$O"
db() { [ -s "$O/$1.refdb" ] || $M build -q "$S/maps/$1/$1.yaml" -o "$O/$1.refdb"; }
for m in intel aces csail tb3-world nav2-warehouse willow-full; do db $m; done
# Synthetic offices (clean, rectilinear, alike), held out.
for seed in 21 22 31 32; do
  n=office-s$seed
  [ -s "$O/$n.refdb" ] || {
    $M synth -q --kind office --width 400 --height 400 --seed $seed --out "$O/synth" --name $n > /dev/null
    $M build -q "$O/synth/$n.yaml" -o "$O/$n.refdb"
  }
done
for m in intel aces csail; do
  $M localize -q "$O/$m.refdb" "$S/logs/$m/$m-corrected.log.gz" \
    --truth "$S/logs/$m/$m-poses-in-map.txt" > "$O/real-$m.jsonl"
done
# dump NAME DB SEED POSES EXPERIMENTS [eval options]: the simulated scans
# and truth of `mapc eval --dump` in $O/dump-NAME.
dump() {
  local name=$1 dbn=$2 seed=$3 poses=$4 exps=$5; shift 5
  $M eval -q "$O/$dbn.refdb" --experiments "$exps" --poses "$poses" --seed "$seed" \
    --dump "$O/dump-$name" --out "$O/dump-$name/report" --no-figures "$@" > /dev/null
}
# sim NAME DB SEED POSES [eval options]: static and dynamic scans localized
# on DB against their truth.
sim() {
  local name=$1 dbn=$2 seed=$3 poses=$4; shift 4
  local d="$O/dump-$name"
  dump "$name" "$dbn" "$seed" "$poses" static,dynamic "$@"
  for e in static dynamic; do
    $M localize -q "$O/$dbn.refdb" "$d/$e-scans.jsonl" --truth "$d/$e-truth.txt" \
      > "$O/sim-$name-$e.jsonl"
  done
}
# dist NAME DB SEED POSES [eval options]: every class of the disturbance
# suite (people, furniture, doors, shifted map, missing returns, range
# noise, angular jitter, motion, mount error) localized on DB against its
# truth, in $O/dist-NAME-CLASS.jsonl.
dist() {
  local name=$1 dbn=$2 seed=$3 poses=$4; shift 4
  local d="$O/dump-dist-$name"
  dump "dist-$name" "$dbn" "$seed" "$poses" disturbances "$@"
  for f in "$d"/*-scans.jsonl; do
    local e
    e=$(basename "$f" -scans.jsonl)
    $M localize -q "$O/$dbn.refdb" "$f" --truth "$d/$e-truth.txt" > "$O/dist-$name-$e.jsonl"
  done
}
sim intel360 intel 11 300
dist intel360 intel 11 100
dist willow360 willow-full 12 100
sim intel180 intel 11 300 --fov 180 --beams 361
sim tb3 tb3-world 11 200
sim office22 office-s22 11 200
sim office32 office-s32 12 200
sim warehouse180 nav2-warehouse 12 200 --fov 180 --beams 361
sim willow360 willow-full 12 200
# wrong map: scans simulated on one building, localized on another.
dump aces aces 11 300 static
dump csail csail 12 300 static
$M localize -q "$O/intel.refdb" "$O/dump-aces/static-scans.jsonl" > "$O/wrong-aces-on-intel.jsonl"
$M localize -q "$O/aces.refdb" "$O/dump-csail/static-scans.jsonl" > "$O/wrong-csail-on-aces.jsonl"
dump office21 office-s21 11 200 static
dump office31 office-s31 12 200 static
$M localize -q "$O/office-s22.refdb" "$O/dump-office21/static-scans.jsonl" > "$O/wrong-office21-on-22.jsonl"
$M localize -q "$O/office-s32.refdb" "$O/dump-office31/static-scans.jsonl" > "$O/wrong-office31-on-32.jsonl"
T=(real:$O/real-intel.jsonl real:$O/real-aces.jsonl)
for n in intel360 intel180 tb3; do T+=(sim:$O/sim-$n-static.jsonl sim:$O/sim-$n-dynamic.jsonl); done
for f in "$O"/dist-intel360-*.jsonl; do T+=(sim:$f); done
T+=(wrong:$O/wrong-aces-on-intel.jsonl)
H=(real:$O/real-csail.jsonl)
for n in warehouse180 willow360 office22 office32; do H+=(sim:$O/sim-$n-static.jsonl sim:$O/sim-$n-dynamic.jsonl); done
for f in "$O"/dist-willow360-*.jsonl; do H+=(sim:$f); done
H+=(wrong:$O/wrong-csail-on-aces.jsonl)
# Scans of one synthetic office on another's map: reported, not fitted on
# (a room of one fits the same-sized room of the other, so no single-scan
# feature can reject them all; fitting on them costs real right answers).
H+=(wrong:$O/wrong-office21-on-22.jsonl wrong:$O/wrong-office31-on-32.jsonl)
echo "--train ${T[*]} --test ${H[*]}"
