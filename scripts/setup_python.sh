#!/usr/bin/env bash
# Create .venv with the Python references the interop tests use (pyuff, scipy, polars, pandas).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x .venv/bin/python ]; then
  python3 -m venv .venv
fi
.venv/bin/pip install --quiet --disable-pip-version-check -r scripts/requirements.txt
echo "Python references ready in .venv (export RFMLAB_PYTHON=$PWD/.venv/bin/python)"
