#!/usr/bin/env bash
# The Python package's tests: build the extension into .venv (dev profile: the numeric crates
# optimised as in `cargo test`), then pytest (python/tests) and the example (examples/tour.py).
# Needs `bash scripts/setup_python.sh` first (it installs maturin, pytest and the references).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x .venv/bin/maturin ]; then
  echo "no .venv with maturin: run 'bash scripts/setup_python.sh' first" >&2
  exit 2
fi
export RFMLAB_SHARED="${RFMLAB_SHARED:-$(cd .. && pwd)/shared}"
# The ROM cache `cargo test` fills (.cargo/config.toml): the tour reuses the base springs' term
# ROM instead of building it again.
export RFMLAB_ROM_CACHE="${RFMLAB_ROM_CACHE:-$PWD/target/rom-cache}"

echo "== python package (maturin develop into .venv)"
VIRTUAL_ENV="$PWD/.venv" PATH="$PWD/.venv/bin:$PATH" .venv/bin/maturin develop --profile dev

echo "== python tests (python/tests)"
.venv/bin/python -m pytest python/tests -q -p no:cacheprovider

echo "== the Python tour (examples/tour.py)"
tour_out="$(mktemp -d)"
start=$(date +%s)
MPLBACKEND=Agg RFMLAB_TOUR_OUT="$tour_out" .venv/bin/python examples/tour.py
echo "the tour ran in $(( $(date +%s) - start )) s; its figures are in $tour_out"
