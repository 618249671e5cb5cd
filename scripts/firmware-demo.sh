#!/usr/bin/env bash
# Firmware proof: refloc localizing laser scans on an emulated Cortex-M4F.
#
#   scripts/firmware-demo.sh [--budget]
#
# 1. installs what is missing: the thumbv7em-none-eabihf Rust target and
#    QEMU (Debian package qemu-system-arm, through apt-get);
# 2. builds mapc and refloc-scangen (examples/scangen, in the root workspace);
# 3. synthesizes an office map, compiles it to examples/firmware/data/map.refdb
#    and simulates scans at seeded poses into examples/firmware/data/scans.rs;
# 4. builds examples/firmware and runs it under QEMU (mps2-an386), which
#    exits with the firmware's status: 0 when every scan was accepted within
#    0.3 m / 5 deg of its true pose;
# 5. checks that the poses printed by the firmware are the ones the same
#    code computed on this host, that the debug build (overflow checks on)
#    passes too, and that nothing in the ELF allocates;
# 6. prints the flash/RAM use; with --budget also the largest map that fits
#    a 2 MiB flash / 256 KiB RAM part (see examples/firmware/README.md).
#
# Idempotent: inputs are regenerated only when they change. Exit status 0
# on success, 1 on a failed check, 2 on a setup error.
set -euo pipefail
# These builds use the per-workspace target directories this script reads from.
unset CARGO_TARGET_DIR

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
FW=$ROOT/examples/firmware
# Host tools (examples/scangen and mapc) are members of the root workspace.
HOST_TARGET=${CARGO_TARGET_DIR:-$ROOT/target}
DATA=$FW/data
TARGET=thumbv7em-none-eabihf
ELF=$FW/target/$TARGET/release/refloc-firmware
BUDGET=0
for a in "$@"; do
    case $a in
        --budget) BUDGET=1 ;;
        -h | --help) sed -n '2,21p' "$0"; exit 0 ;;
        *) echo "unknown option $a" >&2; exit 2 ;;
    esac
done

say() { printf '== %s\n' "$*"; }
die() { printf 'error: %s\n' "$*" >&2; exit "${2:-2}"; }

as_root() {
    if [ "$(id -u)" = 0 ]; then "$@"; elif command -v sudo >/dev/null; then sudo "$@"; else
        die "need root (or sudo) to run: $*"; fi
}

# --- 1. tools --------------------------------------------------------------
if ! rustup target list --installed 2>/dev/null | grep -qx "$TARGET"; then
    say "installing the $TARGET Rust target"
    rustup target add "$TARGET"
fi
if ! command -v qemu-system-arm >/dev/null; then
    say "installing qemu-system-arm (apt-get)"
    as_root apt-get update -qq
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends qemu-system-arm >/dev/null
fi

# --- 2. host tools ---------------------------------------------------------
say "building mapc and refloc-scangen (release)"
cargo build --release -q --manifest-path "$ROOT/Cargo.toml" -p refloc-scangen -p mapc --bins
MAPC=$HOST_TARGET/release/mapc
SCANGEN=$HOST_TARGET/release/refloc-scangen

# --- 3. inputs -------------------------------------------------------------
say "compiling the map and simulating scans"
mkdir -p "$DATA"
"$MAPC" -q synth --kind office --width 400 --height 300 --seed 3 -o "$DATA" --name office >/dev/null
"$MAPC" -q build "$DATA/office.yaml" -o "$DATA/map.refdb.new" --beams 362
if cmp -s "$DATA/map.refdb.new" "$DATA/map.refdb"; then rm "$DATA/map.refdb.new"; else mv "$DATA/map.refdb.new" "$DATA/map.refdb"; fi
"$SCANGEN" firmware "$DATA/map.refdb" "$DATA" --seed 7 2>"$DATA/host.log" || { cat "$DATA/host.log"; die "scan generation failed"; }

# --- 4. firmware -----------------------------------------------------------
say "building the firmware ($TARGET, release)"
(cd "$FW" && cargo build --release -q)
say "running it on QEMU mps2-an386 (Cortex-M4F)"
set +e
timeout 300 qemu-system-arm -machine mps2-an386 -cpu cortex-m4 -nographic \
    -semihosting-config enable=on,target=native -kernel "$ELF" | tee "$DATA/qemu.log"
status=${PIPESTATUS[0]}
set -e
[ "$status" = 124 ] && die "QEMU timed out" 1

# --- 5. checks -------------------------------------------------------------
fail=0
if [ "$status" != 0 ]; then
    echo "FAIL: the firmware exited with status $status"
    fail=1
fi
# Same code, same IEEE single-precision arithmetic: the Cortex-M4F must print
# the poses the host computed (1 mm / 1 mrad allows for formatting only).
if ! awk '
    FNR == NR { if ($2 == "error") e[$1] = "error"; else { x[$1] = $2; y[$1] = $3; t[$1] = $4; a[$1] = $5 }; n++; next }
    $1 == "RESULT" {
        seen++
        i = $2
        if ($3 == "error" || e[i] == "error") { if ($3 != e[i]) { print "FAIL: scan " i ": firmware and host disagree on the error"; bad++ }; next }
        dx = $3 - x[i]; dy = $4 - y[i]; dt = $5 - t[i]
        if (dx < 0) dx = -dx; if (dy < 0) dy = -dy; if (dt < 0) dt = -dt
        if (dx > 1e-3 || dy > 1e-3 || dt > 1e-3 || $6 != a[i]) {
            print "FAIL: scan " i ": firmware " $3 " " $4 " " $5 " " $6 ", host " x[i] " " y[i] " " t[i] " " a[i]; bad++
        }
    }
    END {
        if (seen != n) { print "FAIL: the firmware printed " seen " results, expected " n; bad++ }
        if (!bad) print "ok: the firmware poses match the host poses (" n " scans)"
        exit bad > 0
    }' "$DATA/expected.txt" "$DATA/qemu.log"; then
    fail=1
fi

# The dev profile keeps overflow checks and debug assertions: run it too, so
# that 32-bit overflows in refloc (usize is 32 bits here) panic, and fail.
say "running the debug build (overflow checks on)"
(cd "$FW" && cargo build -q)
if timeout 300 qemu-system-arm -machine mps2-an386 -cpu cortex-m4 -nographic \
    -semihosting-config enable=on,target=native -kernel "$FW/target/$TARGET/debug/refloc-firmware" >"$DATA/qemu-debug.log" 2>&1; then
    echo "ok: the debug build passes too"
else
    cat "$DATA/qemu-debug.log"
    echo "FAIL: the debug build failed"
    fail=1
fi

nm_tool=$(command -v arm-none-eabi-nm || command -v nm || command -v llvm-nm || true)
if [ -n "$nm_tool" ]; then
    if "$nm_tool" "$ELF" | grep -Eq '__rust_alloc|__rdl_alloc|__rg_alloc|\bmalloc\b'; then
        echo "FAIL: the firmware links an allocator"
        fail=1
    else
        echo "ok: no allocator symbols in the ELF"
    fi
fi

# --- 6. sizes --------------------------------------------------------------
size_tool=$(command -v arm-none-eabi-size || command -v size || command -v llvm-size || true)
refdb_bytes=$(wc -c <"$DATA/map.refdb")
scans_bytes=$(awk '/^static RANGES_[0-9]+: \[f32; [0-9]+\]/ { gsub(/[^0-9]/, "", $4); s += 4 * $4 } END { print s + 0 }' "$DATA/scans.rs")
scratch_bytes=$(sed -n 's/^pub(crate) const SCRATCH_BYTES: usize = \([0-9]*\);/\1/p' "$DATA/scans.rs")
stack_peak=$(sed -n 's/^stack peak: \([0-9]*\) bytes.*/\1/p' "$DATA/qemu.log")
if [ -n "$size_tool" ]; then
    read -r text data bss _ < <("$size_tool" "$ELF" | awk 'NR == 2')
    code=$((text + data - refdb_bytes - scans_bytes))
    ram_other=$((data + bss - scratch_bytes + 2 * ${stack_peak:-0}))
    echo
    echo "flash: text $text + data $data bytes = .refdb $refdb_bytes + test scans $scans_bytes + code and constants $code"
    echo "RAM:   data $data + bss $bss bytes (refloc scratch $scratch_bytes) + stack peak ${stack_peak:-?} bytes"
    if [ "$BUDGET" = 1 ]; then
        say "flash/RAM budget (2 MiB / 256 KiB) from synthetic office maps"
        B=$FW/target/budget
        mkdir -p "$B"
        dbs=()
        for s in 400x300 800x600 1200x800; do
            "$MAPC" -q synth --kind office --width "${s%x*}" --height "${s#*x}" --seed 3 -o "$B" --name "office-$s" >/dev/null
            for beams in 362 1081; do
                "$MAPC" -q build "$B/office-$s.yaml" -o "$B/office-$s-b$beams.refdb" --beams "$beams"
                dbs+=("$B/office-$s-b$beams.refdb")
            done
        done
        (cd "$B" && "$SCANGEN" budget --code "$code" --ram-other "$ram_other" "${dbs[@]#"$B"/}")
    fi
else
    echo "(no size tool found: install binutils to see flash/RAM use)"
fi

if [ "$fail" != 0 ]; then
    echo "firmware demo: FAILED"
    exit 1
fi
echo "firmware demo: passed"
