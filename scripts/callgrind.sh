#!/usr/bin/env bash
# Instructions per localization query, counted by callgrind (deterministic:
# the same binary, database and seeds give the same counts on any machine of
# the same architecture; unlike wall time it does not depend on load).
#
#   scripts/callgrind.sh [-n N] [--beams "362 1081"] [--conditions "static dynamic"]
#                        [--profile] [--keep]
#
# 1. builds `query-count` (crate bench/, release profile) and with it the
#    benchmark database: the Intel map (../shared/maps/intel/intel.yaml,
#    default BuildConfig; a synthetic office if the shared data is absent,
#    which query-count then says on stderr) -> target/refloc-bench/intel.refdb;
# 2. for each scanner (362 = 362 beams over 360 deg, 1081 = 1081 beams over
#    270 deg, 361 = 361 beams over 180 deg) and each condition (static =
#    exact ranges; dynamic = 5 mm noise + 60 short outliers), runs
#    `query-count --n 0` and `--n N` under `valgrind --tool=callgrind`. Both
#    load the database, simulate the same fixed set of 50 seeded scans and
#    allocate the scratch; the second also localizes N of them (query i =
#    scan i mod 50, one thread). Instructions per query =
#    (Ir(N) - Ir(0)) / N, so loading and simulation are excluded. N should be
#    a multiple of 50 (default 50: every scan once). A third run with
#    --dump-before on localize gives each query's own count: their median, 90th
#    percentile and maximum are printed too (a few queries that examine
#    many candidates make the mean much larger than the median);
# 3. with --profile, also runs the N queries of each set with collection
#    switched on only inside refloc::localize::localize and prints the
#    functions that take the most instructions (inclusive and self, per
#    query), with callgrind_annotate.
#
# Output files go to target/refloc-bench/callgrind/ (removed at the end
# unless --keep). valgrind is installed with apt-get when missing and we are
# root. Exit status: 0 on success, 2 on a setup error.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
N=50
BEAMS="362 1081"
CONDITIONS="static dynamic"
PROFILE=0
KEEP=0
while [ $# -gt 0 ]; do
    case $1 in
        -n) N=$2; shift ;;
        --beams) BEAMS=$2; shift ;;
        --conditions) CONDITIONS=$2; shift ;;
        --profile) PROFILE=1 ;;
        --keep) KEEP=1 ;;
        -h | --help) sed -n '2,32p' "$0"; exit 0 ;;
        *) echo "unknown option $1" >&2; exit 2 ;;
    esac
    shift
done
die() { printf 'error: %s\n' "$*" >&2; exit 2; }
[[ $N =~ ^[0-9]+$ ]] && [ "$N" -gt 0 ] || die "-n must be a positive integer"

if ! command -v valgrind >/dev/null; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        echo "== installing valgrind" >&2
        (apt-get update -q && apt-get install -y -q valgrind) >&2 || die "could not install valgrind"
    else
        die "valgrind is not installed (apt-get install valgrind)"
    fi
fi

echo "== building query-count (release)" >&2
cargo build --release -q --manifest-path "$ROOT/Cargo.toml" -p refloc-bench --bin query-count
TARGET=$(cargo metadata --format-version 1 --no-deps --manifest-path "$ROOT/Cargo.toml" |
    sed -n 's/.*"target_directory":"\([^"]*\)".*/\1/p')
BIN=$TARGET/release/query-count
OUT=$TARGET/refloc-bench
WORK=$OUT/callgrind
mkdir -p "$WORK"
DB=$OUT/intel.refdb
echo "== building the database -> $DB" >&2
"$BIN" --write-db "$DB"

# Total instructions of one run under callgrind.
count() { # count NAME ARGS...
    local name=$1
    shift
    valgrind --tool=callgrind --callgrind-out-file="$WORK/$name.out" "$@" \
        >"$WORK/$name.log" 2>&1 || { cat "$WORK/$name.log" >&2; die "valgrind run $name failed"; }
    sed -n 's/^summary: *//p' "$WORK/$name.out"
}

# Each query's own count: with --dump-before, callgrind writes a profile
# part at every entry into localize_with_prior (`localize` itself is inlined, so
# it has no entry to dump at); with N+1 queries, part 1 is the set-up
# and parts 2..N+1 hold queries 0..N-1 alone (each with the few instructions
# of the loop until the next entry). A dump on *leaving* localize is not
# used: callgrind does not see every return, and splits some queries.
each() { # each NAME ARGS... -> "median p90 max" of the per-query counts
    local name=$1
    shift
    rm -f "$WORK/$name.out"*
    valgrind --tool=callgrind --callgrind-out-file="$WORK/$name.out" \
        --dump-before='refloc::localize::localize_with_prior' "$@" >"$WORK/$name.log" 2>&1 ||
        { cat "$WORK/$name.log" >&2; die "valgrind run $name failed"; }
    for k in $(seq 2 $((N + 1))); do
        [ -s "$WORK/$name.out.$k" ] || die "valgrind run $name: no part $k"
        sed -n 's/^totals: *//p' "$WORK/$name.out.$k"
    done | sort -n | awk '{ a[NR] = $1 }
        END { i = int(0.9 * (NR - 1) + 0.5) + 1
              printf "%d %d %d\n", (a[int((NR + 1) / 2)] + a[int(NR / 2) + 1]) / 2, a[i], a[NR] }'
}

echo "valgrind: $(valgrind --version); N = $N queries per set"
echo "Ir/query = (Ir(N) - Ir(0)) / N; median / p90 / max: each query's own count"
printf '%-6s %-8s %14s %14s %12s %12s %12s %12s\n' beams cond "Ir(N)" "Ir(0)" "Ir/query" \
    median p90 max
for b in $BEAMS; do
    for c in $CONDITIONS; do
        base=$(count "$b-$c-0" "$BIN" --db "$DB" --beams "$b" --condition "$c" --n 0)
        full=$(count "$b-$c-$N" "$BIN" --db "$DB" --beams "$b" --condition "$c" --n "$N")
        per=$(( (full - base) / N ))
        read -r med p90 max < <(each "$b-$c-each" "$BIN" --db "$DB" --beams "$b" \
            --condition "$c" --n $((N + 1)))
        printf '%-6s %-8s %14d %14d %12d %12d %12d %12d\n' "$b" "$c" "$full" "$base" "$per" \
            "$med" "$p90" "$max"
    done
done

if [ "$PROFILE" = 1 ]; then
    for b in $BEAMS; do
        for c in $CONDITIONS; do
            name=$b-$c-profile
            valgrind --tool=callgrind --callgrind-out-file="$WORK/$name.out" \
                --toggle-collect='refloc::localize::localize*' \
                "$BIN" --db "$DB" --beams "$b" --condition "$c" --n "$N" >"$WORK/$name.log" 2>&1 ||
                { cat "$WORK/$name.log" >&2; die "valgrind run $name failed"; }
            total=$(sed -n 's/^summary: *//p' "$WORK/$name.out")
            echo
            echo "== $b beams, $c: instructions inside refloc::localize, per query (total $(( total / N )))"
            # Inlined code makes callgrind_annotate list a function once per
            # source file its code comes from; dropping the inlined-file
            # switches (fi=/fe=) gives one line per function, and a correct
            # inclusive cost.
            awk -f - "$WORK/$name.out" "$WORK/$name.out" >"$WORK/$name.merged" <<'AWK'
NR == FNR {
    if (match($0, /^(fl|fi|fe|cfi|cfl)=\([0-9]+\) /)) {
        id = substr($0, 1, RLENGTH - 1); sub(/^[a-z]+=/, "", id)
        name[id] = substr($0, RLENGTH + 1)
    }
    next
}
/^(fi|fe)=/ { next }
/^(fl|cfi|cfl)=\([0-9]+\)$/ { k = $0; sub(/^[a-z]+=/, "", k); print $0 " " name[k]; next }
{ print }
AWK
            echo "-- inclusive (function and what it calls)"
            callgrind_annotate --auto=no --inclusive=yes "$WORK/$name.merged" 2>/dev/null |
                awk -v n="$N" -v t="$total" '
                    /^ *[0-9,]+ \(/ && /:/ {
                        ir = $1; gsub(",", "", ir)
                        f = $0; sub(/ \[[^]]*\]$/, "", f); sub(/^[^:]*:/, "", f)
                        if (f !~ /^(refloc|libm)::/ || f ~ /^refloc::localize::localize$/) next
                        if (!(f in seen) || ir > seen[f]) seen[f] = ir
                    }
                    END { for (f in seen) printf "%12.0f %5.1f%%  %s\n", seen[f] / n, 100 * seen[f] / t, f }' |
                sort -rn | head -20
            echo "-- self (instructions in the function body, inlined code included)"
            callgrind_annotate --auto=no --inclusive=no "$WORK/$name.merged" 2>/dev/null |
                awk -v n="$N" -v t="$total" '
                    /^ *[0-9,]+ \(/ && /:/ {
                        ir = $1; gsub(",", "", ir)
                        f = $0; sub(/ \[[^]]*\]$/, "", f); sub(/^[^:]*:/, "", f)
                        self[f] += ir
                    }
                    END { for (f in self) printf "%12.0f %5.1f%%  %s\n", self[f] / n, 100 * self[f] / t, f }' |
                sort -rn | head -15
        done
    done
fi
[ "$KEEP" = 1 ] || rm -rf "$WORK"
