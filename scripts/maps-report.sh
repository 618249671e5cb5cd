#!/usr/bin/env bash
# Builds every map in ../shared/maps with `mapc build` and prints one table
# row per map: cells, sites, coverage, build time (wall), peak RSS, file size.
# Usage: scripts/maps-report.sh [OUT_DIR]   (default build-artifacts/maps)
set -euo pipefail
cd "$(dirname "$0")/.."
shared=../shared/maps
if [ ! -d "$shared" ]; then
    echo "maps-report: $shared not found (the shared public maps live beside the repository)" >&2
    exit 2
fi
out=${1:-build-artifacts/maps}
mkdir -p "$out"
cargo build --release -p mapc -q
printf "| map | cells | sites | coverage | build time | peak RSS | .refdb size |\n|---|---|---|---|---|---|---|\n"
for yaml in "$shared"/*/*.yaml; do
    name=$(basename "$(dirname "$yaml")")
    log="$out/$name.log"
    /usr/bin/time -v ./target/release/mapc build "$yaml" -o "$out/$name.refdb" > "$log" 2>&1
    cells=$(grep -m1 "grid " "$log" | awk '{print $2 " x " $4}')
    sites=$(grep -m1 "  sites" "$log" | awk '{print $2}')
    cov=$(grep -m1 "coverage" "$log" | awk '{print $2}')
    t=$(grep -m1 "build time" "$log" | awk '{print $3 " s"}')
    rss=$(grep -m1 "Maximum resident" "$log" | awk '{printf "%.0f MB", $6/1024}')
    size=$(grep -m1 "file size" "$log" | sed 's/.*(\(.*\))/\1/')
    printf "| %s | %s | %s | %s | %s | %s | %s |\n" "$name" "$cells" "$sites" "$cov" "$t" "$rss" "$size"
done
