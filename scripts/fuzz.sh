#!/usr/bin/env bash
# Fuzzes the hostile-input readers with cargo-fuzz (libFuzzer) on nightly.
#
#   scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET...]   fuzz (default 30 s each, all targets)
#   scripts/fuzz.sh --replay [TARGET...]               run the committed corpora once (CI)
#
# Targets (fuzz/fuzz_targets/): refdb, mapfile, scanio, bag (ROS 2 bags, MCAP),
# cdr (the LaserScan CDR decoder); the harnesses are in
# fuzz/src/lib.rs. Installs the nightly toolchain and cargo-fuzz if missing.
#
# Fuzzing starts from the committed seeds in fuzz/corpus/<target>/ and adds
# new inputs to a scratch corpus, fuzz/target/corpus-work/<target>/ (kept
# between runs, never committed). Crashes, timeouts and out-of-memory inputs
# land in fuzz/artifacts/<target>/; minimize one with
#   (cd fuzz && cargo +nightly fuzz tmin -a <target> artifacts/<target>/<file>)
# and save it under tests/fuzz/<target>/ with a test in tests/fuzz_regressions.rs.
#
# Builds use -a (debug assertions, so integer overflow panics) and ASan.
# fuzz/dict/<target>.dict, when present, is passed as a libFuzzer dictionary.
# libFuzzer limits: -rss_limit_mb=2048 (also the largest single allocation),
# -timeout=$FUZZ_TIMEOUT seconds per input (default 60).
#
# Prints executions and time per target; exits non-zero if any target found
# a crash, timeout or out-of-memory input (or failed to build).
set -uo pipefail

root="$(cd "$(dirname "$0")/.." && pwd)"
fuzz="$root/fuzz"
timeout_s="${FUZZ_TIMEOUT:-60}"

replay=0
seconds=30
if [[ "${1:-}" == "--replay" ]]; then
    replay=1
    shift
elif [[ "${1:-}" =~ ^[0-9]+$ ]]; then
    seconds="$1"
    shift
elif [[ "${1:-}" == "-h" || "${1:-}" == "--help" ]]; then
    sed -n '2,/^set -/p' "$0" | sed '$d; s/^# \{0,1\}//'
    exit 0
fi

# --- toolchain
if ! rustup toolchain list | grep -q '^nightly'; then
    echo "fuzz.sh: installing the nightly toolchain" >&2
    rustup toolchain install nightly --profile minimal || exit 2
fi
if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "fuzz.sh: installing cargo-fuzz" >&2
    cargo install cargo-fuzz --locked || exit 2
fi

cd "$fuzz" || exit 2
if [[ $# -gt 0 ]]; then
    targets=("$@")
else
    mapfile -t targets < <(cargo +nightly fuzz list)
fi

echo "fuzz.sh: building ${targets[*]}" >&2
mkdir -p "$fuzz/target/logs"
if ! cargo +nightly fuzz build -a >"$fuzz/target/build.log" 2>&1; then
    tail -30 "$fuzz/target/build.log" >&2
    echo "fuzz.sh: build failed" >&2
    exit 2
fi

failed=()
summary=()
for t in "${targets[@]}"; do
    log="$fuzz/target/logs/$t.log"
    mkdir -p "$fuzz/artifacts/$t"
    before=$(find "$fuzz/artifacts/$t" -type f | wc -l)
    start=$SECONDS
    if [[ $replay == 1 ]]; then
        echo "fuzz.sh: replaying corpus/$t" >&2
        cargo +nightly fuzz run -a "$t" "corpus/$t" -- \
            -runs=0 -rss_limit_mb=2048 -timeout="$timeout_s" >"$log" 2>&1
        rc=$?
    else
        work="$fuzz/target/corpus-work/$t"
        mkdir -p "$work"
        echo "fuzz.sh: fuzzing $t for ${seconds}s (log: ${log#"$root"/})" >&2
        dict=()
        [[ -f "$fuzz/dict/$t.dict" ]] && dict=(-dict="$fuzz/dict/$t.dict")
        cargo +nightly fuzz run -a "$t" "$work" "corpus/$t" -- \
            -max_total_time="$seconds" -rss_limit_mb=2048 -timeout="$timeout_s" \
            -print_final_stats=1 "${dict[@]}" >"$log" 2>&1
        rc=$?
    fi
    after=$(find "$fuzz/artifacts/$t" -type f | wc -l)
    # libFuzzer's last status line: "#N  DONE  cov: ... exec/s: X rss: ..."
    # (or the last "#N  NEW/pulse ..." line before a crash), then
    # "Done N runs in T second(s)" and, with -print_final_stats, the
    # "stat::number_of_executed_units" / "stat::average_exec_per_sec" lines.
    last=$(grep -E '^#[0-9]+' "$log" | tail -1)
    execs=$(sed -nE 's/^stat::number_of_executed_units: *([0-9]+).*/\1/p' "$log" | tail -1)
    [[ -n "$execs" ]] || execs=$(sed -nE 's/^#([0-9]+).*/\1/p' <<<"$last")
    rate=$(sed -nE 's/^stat::average_exec_per_sec: *([0-9]+).*/\1/p' "$log" | tail -1)
    [[ -n "$rate" ]] || rate=$(sed -nE 's/.*exec\/s: ([0-9]+).*/\1/p' <<<"$last")
    cov=$(sed -nE 's/.*cov: ([0-9]+).*/\1/p' <<<"$last")
    secs=$(sed -nE 's/^Done [0-9]+ runs in ([0-9]+) second.*/\1/p' "$log" | tail -1)
    # Without "Done" (a crash), the wall time of the run (build excluded
    # when it was already up to date).
    [[ -n "$secs" ]] || secs=$((SECONDS - start))
    status="ok"
    if [[ $rc != 0 || $after -gt $before ]]; then
        status="FAILED (exit $rc)"
        failed+=("$t")
        grep -E 'panicked at|ERROR: (libFuzzer|AddressSanitizer)|SUMMARY:|Test unit written to' "$log" | head -8 >&2
    fi
    summary+=("$(printf '%-8s %12s execs %6s s %8s exec/s  cov %-6s %s' \
        "$t" "${execs:-?}" "${secs:-?}" "${rate:-?}" "${cov:-?}" "$status")")
done

echo
printf '%s\n' "${summary[@]}"
if [[ ${#failed[@]} -gt 0 ]]; then
    echo "fuzz.sh: failures in: ${failed[*]} (inputs in fuzz/artifacts/, logs in fuzz/target/logs/)" >&2
    exit 1
fi
