#!/usr/bin/env bash
# Tests the refloc C ABI (crates/refloc-capi) from C.
#
#   scripts/capi-test.sh [--update-header]
#
# 1. builds mapc and refloc-scangen (examples/scangen), compiles a synthetic
#    office map and simulates one scan with its true pose;
# 2. builds the refloc-capi staticlib (release) and asks rustc which native
#    libraries a C program must link with it;
# 3. regenerates include/refloc.h with cbindgen (installed with `cargo
#    install` when missing) and fails if the committed header is stale
#    (--update-header writes it instead);
# 4. compiles tests/c/localize_test.c with the system C compiler (-Wall
#    -Wextra -Werror, C11; the header is also compiled as C++ when g++ is
#    there) and runs it: it opens the map, localizes the scan as ranges and
#    as points, checks the pose and the error paths, and counts the
#    library's allocation calls (there must be none; the linker's --wrap
#    routes them to the test); then runs it again under AddressSanitizer and
#    UBSan when the compiler has them.
#
# Exit status: 0 on success, 1 on a failed check, 2 on a setup error.
set -euo pipefail
# These builds use the per-workspace target directories this script reads from.
unset CARGO_TARGET_DIR

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
CAPI=$ROOT/crates/refloc-capi
# Host tools (examples/scangen and mapc) are members of the root workspace.
HOST_TARGET=${CARGO_TARGET_DIR:-$ROOT/target}
OUT=$CAPI/target/capi-test
CBINDGEN_VERSION=0.29
UPDATE=0
for a in "$@"; do
    case $a in
        --update-header) UPDATE=1 ;;
        -h | --help) sed -n '2,21p' "$0"; exit 0 ;;
        *) echo "unknown option $a" >&2; exit 2 ;;
    esac
done
say() { printf '== %s\n' "$*"; }
die() { printf 'error: %s\n' "$*" >&2; exit "${2:-2}"; }
CC=${CC:-cc}
command -v "$CC" >/dev/null || CC=gcc
command -v "$CC" >/dev/null || die "no C compiler (cc or gcc) found"

# --- 1. inputs -------------------------------------------------------------
say "building mapc and refloc-scangen (release)"
cargo build --release -q --manifest-path "$ROOT/Cargo.toml" -p refloc-scangen -p mapc --bins
MAPC=$HOST_TARGET/release/mapc
mkdir -p "$OUT"
say "compiling a map and simulating a scan"
"$MAPC" -q synth --kind office --width 400 --height 300 --seed 5 -o "$OUT" --name office >/dev/null
"$MAPC" -q build "$OUT/office.yaml" -o "$OUT/map.refdb" --beams 362
"$HOST_TARGET/release/refloc-scangen" capi "$OUT/map.refdb" "$OUT/scan.txt" --seed 11 2>"$OUT/host.log" ||
    { cat "$OUT/host.log"; die "scan generation failed"; }

# --- 2. the library --------------------------------------------------------
say "building the refloc-capi staticlib (release)"
native=$(cd "$CAPI" && cargo rustc --release -q --lib --crate-type staticlib -- --print native-static-libs 2>&1 |
    sed -n 's/.*native-static-libs: *//p' | tail -n 1)
# The crate's target dir: its own, or the root one once it is a member.
tdir=$(cd "$CAPI" && cargo metadata -q --no-deps --format-version 1 | sed -n 's/.*"target_directory":"\([^"]*\)".*/\1/p')
LIB=${tdir:-$CAPI/target}/release/librefloc_capi.a
[ -f "$LIB" ] || die "$LIB was not built"
echo "native libraries to link: ${native:-(none)}"

# --- 3. the header ---------------------------------------------------------
if ! command -v cbindgen >/dev/null; then
    say "installing cbindgen $CBINDGEN_VERSION (cargo install)"
    cargo install --locked -q cbindgen --version "^$CBINDGEN_VERSION"
fi
(cd "$CAPI" && cbindgen -q --config cbindgen.toml --crate refloc-capi --output "$OUT/refloc.h" .)
if [ "$UPDATE" = 1 ]; then
    cp "$OUT/refloc.h" "$CAPI/include/refloc.h"
    echo "wrote crates/refloc-capi/include/refloc.h"
elif ! diff -u "$CAPI/include/refloc.h" "$OUT/refloc.h"; then
    die "crates/refloc-capi/include/refloc.h is stale: run scripts/capi-test.sh --update-header" 1
else
    echo "ok: include/refloc.h matches src/lib.rs"
fi

# --- 4. the C test ---------------------------------------------------------
say "compiling and running tests/c/localize_test.c"
# --wrap routes the library's allocation calls to counting wrappers in the
# test (REFLOC_TRACK_ALLOC): it checks that there are none.
WRAP=-Wl,--wrap=malloc,--wrap=calloc,--wrap=realloc,--wrap=posix_memalign,--wrap=aligned_alloc,--wrap=memalign
# shellcheck disable=SC2086 # $native is a list of linker flags
"$CC" -std=c11 -O2 -Wall -Wextra -Werror -pedantic -DREFLOC_TRACK_ALLOC -I "$CAPI/include" \
    "$CAPI/tests/c/localize_test.c" "$LIB" $WRAP $native -lm -o "$OUT/localize_test"
if command -v g++ >/dev/null; then
    printf '#include "refloc.h"\nint main(void) { refloc_db db; return (int)sizeof db - REFLOC_DB_SIZE; }\n' >"$OUT/cxx.cpp"
    g++ -std=c++11 -Wall -Wextra -Werror -I "$CAPI/include" "$OUT/cxx.cpp" -o "$OUT/cxx" && "$OUT/cxx"
    echo "ok: the header compiles as C++"
fi
"$OUT/localize_test" "$OUT/map.refdb" "$OUT/scan.txt"

# The same test under AddressSanitizer and UBSan, where the compiler has them.
# shellcheck disable=SC2086
if "$CC" -std=c11 -g -O1 -fsanitize=address,undefined -fno-omit-frame-pointer -I "$CAPI/include" \
    "$CAPI/tests/c/localize_test.c" "$LIB" $native -lm -o "$OUT/localize_test_asan" 2>/dev/null; then
    say "running it again under AddressSanitizer and UBSan"
    if ! "$OUT/localize_test_asan" "$OUT/map.refdb" "$OUT/scan.txt" >"$OUT/asan.log" 2>&1; then
        cat "$OUT/asan.log"
        die "the sanitized test failed" 1
    fi
    tail -n 1 "$OUT/asan.log"
else
    echo "(no sanitizer runtime: skipped the ASan/UBSan run)"
fi
