# Sourced, from the repository root, by the scripts that localize the shared
# logs on maps made with numpy (log-maps.sh, resolution-maps.sh):
#
#   source scripts/experiment-env.sh NAME DIR...
#
# NAME is the calling script's (for messages), each DIR a folder of the
# shared data it needs (maps, logs). Sets S (the shared data, ../shared or
# $SHARED), M (the release mapc, built here) and PY (a Python with numpy:
# $PYTHON, else the venv scripts/python-test.sh makes), or exits 2 saying
# what is missing.
S=${SHARED:-../shared}
M=target/release/mapc
PY=${PYTHON:-python/target/venv/bin/python}
experiment_name=$1
shift
for d in "$@"; do
  if [ ! -d "$S/$d" ]; then
    echo "$experiment_name: needs the shared $d at $S (set SHARED=...)" >&2
    exit 2
  fi
done
if ! "$PY" -c "import numpy" 2> /dev/null; then
  echo "$experiment_name: needs a Python with numpy (run scripts/python-test.sh once, or set PYTHON=...)" >&2
  exit 2
fi
cargo build --release -q -p mapc
