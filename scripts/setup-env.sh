#!/usr/bin/env bash
# Create (or reuse) the project's virtual environment in .venv and install furnace-twin
# with its test extras, pinned by constraints.txt.  Idempotent; used by test.sh and serve.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip 2>&1 | grep -v "is ignored" || true
.venv/bin/python -m pip install -q -c constraints.txt -e ".[test]" 2>&1 | grep -v "is ignored" || true
.venv/bin/python -c "import twin, backend, casadi, embreex, viser, rerun" \
  || { echo "setup-env: the environment is incomplete" >&2; exit 1; }
