#!/usr/bin/env bash
# Scaling study of the map compiler and of the query (issue 7): how build
# time, peak memory, database size and query cost grow with the map.
#
#   scripts/scaling.sh [--sizes "1000 2000 4000 8000 16000"] [--kind office]
#                      [--seed 1] [--resolution 0.05] [--poses 100]
#                      [--eval-runs 3] [--callgrind N] [--out DIR]
#                      [--figure PNG] [--keep] [--reuse] [--plot-only]
#
# For each size S (cells per side; default 1k to 16k at 0.05 m, i.e. 50 m to
# 800 m square):
#  1. `mapc synth --kind office --width S --height S --seed 1`: a synthetic
#     office (fixed seed, so the same map every run);
#  2. `mapc build --timings` under `/usr/bin/time -v`: wall time, CPU time
#     (user + system), peak resident set (max RSS), .refdb size, number of
#     sites, and the per-step CPU times `--timings` prints;
#  3. `mapc eval <refdb> --poses P --experiments static --threads 1`, run
#     --eval-runs times: median query time of each run (one thread), the
#     lowest of the medians is reported (load from other processes only
#     adds time), with the mean and the success rate of that run;
#  4. with --callgrind N (default 20; 0 skips it): `query-count` (crate
#     bench/) localizes N + 1 fixed simulated scans (one thread) under
#     callgrind with a dump on every entry into refloc::localize::localize,
#     so that parts 2 .. N + 1 each hold one whole query (part 1 is the
#     loading and the scan simulation): median and mean instructions per
#     query over those N (deterministic, unlike the wall time), and the
#     share of them in the coarse ranking (refloc::coarse::rank_sites,
#     which correlates the query's histogram with every site's).
#
# Builds run one at a time (the machine is shared; the 16k x 16k build
# peaks at about 6 GiB and takes about 8 minutes on 2 cores, its callgrind
# run about 5 minutes; the whole default run about 25 minutes and 3 GiB of
# disk with --keep). Output in DIR (default
# build-artifacts/scaling): scaling.csv, scaling.png, table.txt, and per
# size the build and eval logs (maps/ and refdb/ are removed unless
# --keep). The plot is also copied to --figure (default
# docs/figures/scaling.png; "none" skips it). --reuse skips the synth and
# build of a size whose database and build log a previous --keep run left
# in DIR (to redo the query measurements only); --plot-only measures
# nothing and redraws the table and plot from DIR/scaling.csv. Needs
# python3 with matplotlib for the plot (installed with pip when missing);
# /usr/bin/time and valgrind are installed with apt-get when missing and we
# are root. Results and their reading: docs/scaling.md.
# Exit status: 0 on success, 2 on a setup error.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
SIZES="1000 2000 4000 8000 16000"
KIND=office
SEED=1
RES=0.05
POSES=100
EVAL_RUNS=3
CG=20
OUT=$ROOT/build-artifacts/scaling
FIGURE=$ROOT/docs/figures/scaling.png
KEEP=0
REUSE=0
PLOT_ONLY=0
while [ $# -gt 0 ]; do
    case $1 in
        --sizes) SIZES=$2; shift ;;
        --kind) KIND=$2; shift ;;
        --seed) SEED=$2; shift ;;
        --resolution) RES=$2; shift ;;
        --poses) POSES=$2; shift ;;
        --eval-runs) EVAL_RUNS=$2; shift ;;
        --callgrind) CG=$2; shift ;;
        --out) OUT=$2; shift ;;
        --figure) FIGURE=$2; shift ;;
        --keep) KEEP=1 ;;
        --reuse) REUSE=1 ;;
        --plot-only) PLOT_ONLY=1 ;;
        -h | --help) sed -n '2,43p' "$0"; exit 0 ;;
        *) echo "unknown option $1" >&2; exit 2 ;;
    esac
    shift
done
die() { printf 'error: %s\n' "$*" >&2; exit 2; }
for v in "$SEED" "$POSES" "$EVAL_RUNS" "$CG"; do
    [[ $v =~ ^[0-9]+$ ]] || die "--seed, --poses, --eval-runs and --callgrind take integers"
done
[ "$EVAL_RUNS" -ge 1 ] || die "--eval-runs must be at least 1"
for s in $SIZES; do [[ $s =~ ^[0-9]+$ ]] || die "--sizes: '$s' is not a number of cells"; done

# Tools.
apt_install() { # apt_install PROGRAM PACKAGE
    command -v "$1" >/dev/null && return 0
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        echo "== installing $2" >&2
        (apt-get update -q && apt-get install -y -q "$2") >&2 || die "could not install $2"
    else
        die "$1 is not installed (apt-get install $2)"
    fi
}
PLOT=1
if ! python3 -c 'import matplotlib' 2>/dev/null; then
    echo "== installing matplotlib (pip)" >&2
    python3 -m pip install -q matplotlib >&2 || {
        echo "warning: no matplotlib: the plot is skipped" >&2
        PLOT=0
    }
fi
CSV=$OUT/scaling.csv

measure() {
    [ -x /usr/bin/time ] || { apt_install /usr/bin/time time; }
    [ "$CG" -eq 0 ] || apt_install valgrind valgrind

    echo "== building mapc$([ "$CG" -eq 0 ] || echo ' and query-count') (release)" >&2
    cargo build --release -q --manifest-path "$ROOT/Cargo.toml" -p mapc
    [ "$CG" -eq 0 ] ||
        cargo build --release -q --manifest-path "$ROOT/Cargo.toml" -p refloc-bench --bin query-count
    TARGET=$(cargo metadata --format-version 1 --no-deps --manifest-path "$ROOT/Cargo.toml" |
        sed -n 's/.*"target_directory":"\([^"]*\)".*/\1/p')
    MAPC=$TARGET/release/mapc
    QC=$TARGET/release/query-count

    mkdir -p "$OUT/maps" "$OUT/refdb" "$OUT/logs"
    STEPS="load edt gvd.specks gvd.candidates gvd.thin gvd.prune gvd.graph sites.place sites.coverage compile.dist compile.scans compile.fit compile.hists compile.windows compile.sections index write verify"
    {
        printf 'size,width,height,cells,resolution_m,seed,sites,refdb_bytes,build_wall_s,build_cpu_s,'
        printf 'peak_rss_bytes,rss_bytes_per_cell,wall_us_per_cell,cpu_us_per_cell,'
        printf 'query_median_ms,query_mean_ms,query_success,query_false_accept,'
        printf 'ir_median,ir_mean,ir_coarse_share'
        for s in $STEPS; do printf ',cpu_%s' "${s//./_}"; done
        printf '\n'
    } >"$CSV"

    # Seconds from /usr/bin/time's "h:mm:ss" or "m:ss.ss".
    to_seconds() { awk -F: '{ s = 0; for (i = 1; i <= NF; i++) s = s * 60 + $i; printf "%.2f", s }'; }

    for S in $SIZES; do
        name=$KIND-${S}x$S-s$SEED
        db=$OUT/refdb/$name.refdb
        blog=$OUT/logs/$name.build.log
        if [ "$REUSE" = 1 ] && [ -s "$db" ] && grep -q 'Exit status: 0' "$blog" 2>/dev/null; then
            echo "== $name: reusing $db and its build log" >&2
        else
            echo "== $name: synth" >&2
            yaml=$("$MAPC" -q synth --kind "$KIND" --width "$S" --height "$S" --resolution "$RES" \
                --seed "$SEED" --out "$OUT/maps" --name "$name")
            echo "== $name: build" >&2
            # The 16k x 16k database (2.6 GiB) is over the default
            # --max-db-bytes (1 GiB): allow 16 GiB.
            /usr/bin/time -v "$MAPC" build "$yaml" -o "$db" --timings \
                --max-db-bytes 17179869184 >"$blog" 2>&1 ||
                { cat "$blog" >&2; die "mapc build $yaml failed"; }
        fi
        wall=$(sed -n 's/.*Elapsed (wall clock) time (h:mm:ss or m:ss): *//p' "$blog" | to_seconds)
        user=$(sed -n 's/.*User time (seconds): *//p' "$blog")
        sys=$(sed -n 's/.*System time (seconds): *//p' "$blog")
        rss_kb=$(sed -n 's/.*Maximum resident set size (kbytes): *//p' "$blog")
        sites=$(sed -n 's/^  sites  *\([0-9]*\).*/\1/p' "$blog")
        bytes=$(stat -c %s "$db")
        cells=$((S * S))
        cpu=$(awk -v u="$user" -v s="$sys" 'BEGIN { printf "%.2f", u + s }')
        steps=$(for s in $STEPS; do
            awk -v k="$s" '$1 == k && NF == 4 { v = $3 } END { printf ",%s", (v == "" ? "" : v) }' "$blog"
        done)

        echo "== $name: eval ($EVAL_RUNS x $POSES poses, one thread)" >&2
        best=""
        for r in $(seq 1 "$EVAL_RUNS"); do
            edir=$OUT/logs/$name.eval$r
            "$MAPC" -q eval "$db" --poses "$POSES" --experiments static --threads 1 --no-figures \
                --out "$edir" >"$OUT/logs/$name.eval$r.log" 2>&1 ||
                { cat "$OUT/logs/$name.eval$r.log" >&2; die "mapc eval $db failed"; }
            line=$(python3 -c '
import json, sys
s = json.load(open(sys.argv[1]))["summaries"]["static"]
print(s["median_time_us"] / 1000, s["mean_time_us"] / 1000, s["success_rate"], s["false_accept_rate"])
    ' "$edir/report.json")
            if [ -z "$best" ] || awk -v a="${line%% *}" -v b="${best%% *}" 'BEGIN { exit !(a < b) }'; then
                best=$line
            fi
        done
        read -r qmed qmean qok qfa <<<"$best"

        irmed="" irmean="" coarse=""
        if [ "$CG" -gt 0 ]; then
            echo "== $name: callgrind ($CG queries)" >&2
            cgdir=$OUT/logs/$name.callgrind
            rm -rf "$cgdir"
            mkdir -p "$cgdir"
            # (A dump when leaving localize, or collection toggled on inside it,
            # splits some queries into several parts: callgrind does not always
            # see the return. Entries are seen reliably.)
            valgrind --tool=callgrind --callgrind-out-file="$cgdir/cg.out" \
                --dump-before='refloc::localize::localize' \
                "$QC" --db "$db" --n $((CG + 1)) >"$cgdir/valgrind.log" 2>&1 ||
                { cat "$cgdir/valgrind.log" >&2; die "callgrind on $db failed"; }
            parts=$(for k in $(seq 2 $((CG + 1))); do echo "$cgdir/cg.out.$k"; done)
            for f in $parts; do [ -s "$f" ] || die "callgrind on $db: no part $f"; done
            read -r irmed irmean < <(for f in $parts; do
                sed -n 's/^totals: *//p' "$f"
            done | sort -n | awk '{ a[NR] = $1; t += $1 }
                END { printf "%d %d\n", (a[int((NR + 1) / 2)] + a[int(NR / 2) + 1]) / 2, t / NR }')
            coarse=$(for f in $parts; do
                t=$(sed -n 's/^totals: *//p' "$f")
                c=$(callgrind_annotate --auto=no --inclusive=yes "$f" 2>/dev/null |
                    awk '/refloc::coarse::rank_sites \[/ { gsub(",", "", $1); print $1; exit }')
                echo "$t ${c:-0}"
            done | awk '{ t += $1; c += $2 } END { printf "%.3f", (t > 0 ? c / t : 0) }')
        fi

        awk -v OFS=, -v S="$S" -v cells=$cells -v res="$RES" -v seed="$SEED" -v sites="$sites" \
            -v bytes="$bytes" -v wall="$wall" -v cpu="$cpu" -v rss=$((rss_kb * 1024)) \
            -v qmed="$qmed" -v qmean="$qmean" -v qok="$qok" -v qfa="$qfa" \
            -v irmed="$irmed" -v irmean="$irmean" -v coarse="$coarse" -v steps="$steps" 'BEGIN {
            printf "%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%.2f,%.4f,%.4f,%.3f,%.3f,%s,%s,%s,%s,%s%s\n",
                S, S, S, cells, res, seed, sites, bytes, wall, cpu, rss, rss / cells,
                1e6 * wall / cells, 1e6 * cpu / cells, qmed, qmean, qok, qfa, irmed, irmean, coarse, steps
        }' >>"$CSV"
        echo "   sites $sites, wall ${wall} s, cpu ${cpu} s, peak RSS $((rss_kb / 1024)) MiB," \
            "$(awk -v r=$((rss_kb * 1024)) -v c=$cells 'BEGIN { printf "%.1f", r / c }') B/cell," \
            "query median ${qmed} ms${irmed:+, Ir median $irmed}" >&2
        [ "$KEEP" = 1 ] || rm -f "$db" "$OUT/maps/$name.pgm" "$OUT/maps/$name.yaml"
    done
    [ "$KEEP" = 1 ] || rmdir "$OUT/maps" "$OUT/refdb" 2>/dev/null || true
}

if [ "$PLOT_ONLY" = 1 ]; then
    [ -s "$CSV" ] || die "--plot-only: no $CSV"
else
    measure
fi

# Table (stdout and table.txt).
python3 - "$CSV" >"$OUT/table.txt" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
def f(v, fmt):
    return fmt.format(float(v)) if v not in ("", None) else "-"
head = ["size", "cells", "sites", "refdb MiB", "build wall s", "build CPU s", "wall us/cell",
        "CPU us/cell", "peak RSS MiB", "RSS B/cell", "query median ms", "query mean ms",
        "success", "Ir/query median", "Ir/query mean", "coarse share"]
out = []
for r in rows:
    out.append([
        f"{r['width']}x{r['height']}", f"{int(r['cells']):,}", f"{int(r['sites']):,}",
        f(int(r["refdb_bytes"]) / 2**20, "{:.1f}"), f(r["build_wall_s"], "{:.1f}"),
        f(r["build_cpu_s"], "{:.1f}"), f(r["wall_us_per_cell"], "{:.2f}"),
        f(r["cpu_us_per_cell"], "{:.2f}"), f(int(r["peak_rss_bytes"]) / 2**20, "{:.0f}"),
        f(r["rss_bytes_per_cell"], "{:.1f}"), f(r["query_median_ms"], "{:.2f}"),
        f(r["query_mean_ms"], "{:.2f}"), f(100 * float(r["query_success"]), "{:.0f}%"),
        f(float(r["ir_median"]) / 1e6, "{:.1f} M") if r["ir_median"] else "-",
        f(float(r["ir_mean"]) / 1e6, "{:.1f} M") if r["ir_mean"] else "-",
        f(100 * float(r["ir_coarse_share"]), "{:.0f}%") if r["ir_coarse_share"] else "-",
    ])
print("| " + " | ".join(head) + " |")
print("|" + "|".join(" ---: " for _ in head) + "|")
for o in out:
    print("| " + " | ".join(o) + " |")
PY
cat "$OUT/table.txt"

if [ "$PLOT" = 1 ]; then
    python3 - "$CSV" "$OUT/scaling.png" <<'PY'
import csv, sys
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
rows = list(csv.DictReader(open(sys.argv[1])))
num = lambda k: [float(r[k]) if r[k] else float("nan") for r in rows]
cells, sites = num("cells"), num("sites")
mc = [c / 1e6 for c in cells]
fig, ax = plt.subplots(2, 2, figsize=(11, 8.5))

import math

def linear_ref(a, xs, ys, label, at=0):
    # A line of slope 1 (log-log) through point `at`.
    k = ys[at] / xs[at]
    a.plot(xs, [k * x for x in xs], ":", color="grey", label=label)

def exponents(a, xs, ys):
    # The local exponent d log y / d log x between consecutive points.
    for (x0, y0), (x1, y1) in zip(zip(xs, ys), zip(xs[1:], ys[1:])):
        if min(x0, y0, x1, y1) > 0 and x1 != x0:
            e = math.log(y1 / y0) / math.log(x1 / x0)
            a.annotate("%.2f" % e, (math.sqrt(x0 * x1), math.sqrt(y0 * y1)),
                       textcoords="offset points", xytext=(4, -12), fontsize=8)

a = ax[0][0]
a.loglog(mc, num("build_wall_s"), "o-", label="wall")
a.loglog(mc, num("build_cpu_s"), "s-", label="CPU (user + sys)")
linear_ref(a, mc, num("build_cpu_s"), "slope 1 (linear) through the smallest map")
exponents(a, mc, num("build_cpu_s"))
a.set_xlabel("cells (millions)"); a.set_ylabel("mapc build (s)")
a.set_title("Build time (labels: local exponent of CPU time)"); a.legend(); a.grid(True, which="both", alpha=0.3)

a = ax[0][1]
a.semilogx(mc, num("rss_bytes_per_cell"), "o-", label="peak RSS / cell")
a.semilogx(mc, [int(r["refdb_bytes"]) / float(r["cells"]) for r in rows], "s-",
           label=".refdb bytes / cell")
a.axhline(64, color="red", ls="--", label="target 64 B/cell")
a.set_ylim(0, 70)
a.set_xlabel("cells (millions)"); a.set_ylabel("bytes per cell")
a.set_title("Peak memory of mapc build"); a.legend(); a.grid(True, which="both", alpha=0.3)

a = ax[1][0]
a.loglog(sites, num("query_median_ms"), "o-", label="median (mapc eval, static, 1 thread)")
a.loglog(sites, num("query_mean_ms"), "s-", label="mean")
linear_ref(a, sites, num("query_median_ms"), "slope 1 (linear) through the largest map",
           at=len(rows) - 1)
exponents(a, sites, num("query_median_ms"))
a.set_xlabel("sites"); a.set_ylabel("query time (ms)")
a.set_title("Query time (labels: local exponent of the median)"); a.legend(); a.grid(True, which="both", alpha=0.3)

a = ax[1][1]
ir = num("ir_median")
if any(x == x for x in ir):
    share = num("ir_coarse_share")
    a.loglog(sites, [x / 1e6 for x in ir], "o-", label="median per query")
    a.loglog(sites, [x / 1e6 for x in num("ir_mean")], "s-", label="mean per query")
    a.loglog(sites, [m / 1e6 * s for m, s in zip(num("ir_mean"), share)], "^-",
             label="mean, coarse ranking only")
    linear_ref(a, sites, [x / 1e6 for x in ir], "slope 1 (linear) through the largest map",
               at=len(rows) - 1)
    exponents(a, sites, [x / 1e6 for x in ir])
    a.set_xlabel("sites"); a.set_ylabel("instructions (millions)")
    a.set_title("Instructions per query, callgrind (labels: exponent)"); a.legend()
    a.grid(True, which="both", alpha=0.3)
else:
    a.axis("off")
fig.suptitle("Scaling: synthetic offices, %s to %s cells at %s m" % (
    rows[0]["width"] + "x" + rows[0]["height"], rows[-1]["width"] + "x" + rows[-1]["height"],
    rows[0]["resolution_m"]))
fig.tight_layout()
fig.savefig(sys.argv[2], dpi=100)
PY
    echo "plot: $OUT/scaling.png" >&2
    if [ "$FIGURE" != none ]; then
        mkdir -p "$(dirname "$FIGURE")"
        cp "$OUT/scaling.png" "$FIGURE"
        echo "plot: $FIGURE" >&2
    fi
fi
echo "csv: $CSV" >&2
