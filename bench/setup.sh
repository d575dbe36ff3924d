#!/usr/bin/env bash
# Makes the Python environment of the side-by-side benchmarks: a venv (default
# /tmp/gyrocal-bench-venv, or $BENCH_VENV) with bench/requirements.txt installed by pip.
# Idempotent: a second run only checks the pins. Needs python3 (3.11 on the project's
# machines) with its venv module, and the package index.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
venv="${BENCH_VENV:-/tmp/gyrocal-bench-venv}"
if [[ ! -x "$venv/bin/python" ]]; then
    python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$here/requirements.txt"
"$venv/bin/python" -c 'import numpy, pandas, allantools; print("bench venv:", numpy.__version__, pandas.__version__, allantools.__version__)'
echo "$venv"
