#!/usr/bin/env bash
# Create (or reuse) the project's virtual environment in .venv and install furnace-twin
# with its test extras, pinned by constraints.txt.  Idempotent; used by test.sh and serve.sh.
# pip runs only when the environment is missing or out of date: .venv/.setup-stamp holds the hash of
# pyproject.toml + constraints.txt it was installed from (FORCE_SETUP=1 installs anyway).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
STAMP=.venv/.setup-stamp
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
want=$(cat pyproject.toml constraints.txt | sha256sum | cut -d' ' -f1)
IMPORTS="import twin, backend, casadi, embreex, viser, rerun"
if [ "${FORCE_SETUP:-0}" != "1" ] && [ -f "$STAMP" ] && [ "$(cat "$STAMP")" = "$want" ] \
   && .venv/bin/python -c "$IMPORTS" 2>/dev/null; then
  exit 0  # installed from these very files and importable: nothing to do
fi
rm -f "$STAMP"
.venv/bin/python -m pip install -q --upgrade pip 2>&1 | grep -v "is ignored" || true
.venv/bin/python -m pip install -q -c constraints.txt -e ".[test]" 2>&1 | grep -v "is ignored" || true
.venv/bin/python -c "$IMPORTS" || { echo "setup-env: the environment is incomplete" >&2; exit 1; }
echo "$want" > "$STAMP"
