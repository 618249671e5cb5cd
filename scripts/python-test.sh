#!/usr/bin/env bash
# Builds and installs the Python package (python/, PyO3 + maturin) into a
# fresh virtual environment and runs its pytest tests.
#
#   scripts/python-test.sh
#
# The bag tests write ROS 2 bags at test time with the independent `mcap`
# and `mcap-ros2-support` libraries (tests/make_bags.py).
# The ROS 2 node's logic (ros/refloc_ros) is tested with the ROS 2 message
# types of `rosbags`.
# The venv lives in python/target/venv (git-ignored). The tests compile the
# shipped office map and localize scans that `mapc eval --dump` simulates,
# with the debug mapc binary (built by `cargo test`, or here when missing).
# Exit status: pytest's, 2 on a setup error.
set -euo pipefail
unset CARGO_TARGET_DIR
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
VENV=$ROOT/python/target/venv
say() { printf '== %s\n' "$*"; }
MAPC=$ROOT/target/debug/mapc
if [ ! -x "$MAPC" ]; then
    say "building mapc (for the simulated test scans)"
    cargo build --quiet -p mapc --manifest-path "$ROOT/Cargo.toml"
fi
say "virtual environment $VENV"
rm -rf "$VENV"
python3 -m venv "$VENV" || { echo "error: python3 -m venv failed" >&2; exit 2; }
"$VENV/bin/pip" install --quiet --upgrade pip
"$VENV/bin/pip" install --quiet "maturin>=1.5,<2" "numpy>=2" "pytest>=7" \
    "mcap>=1.2,<2" "mcap-ros2-support>=0.5,<1" "rosbags>=0.10,<1"
say "pip install ./python (maturin builds the extension)"
"$VENV/bin/pip" install --quiet "$ROOT/python"
say "pytest"
cd "$ROOT/python"
REFLOC_MAPC="$MAPC" REFLOC_ROOT="$ROOT" "$VENV/bin/python" -m pytest -q tests \
    "$ROOT/ros/refloc_ros/test"
