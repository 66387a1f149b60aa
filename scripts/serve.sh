#!/usr/bin/env bash
# Install (if needed) and start the dashboard on http://127.0.0.1:8000 (viser on :8080).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup-env.sh
exec .venv/bin/furnace-twin serve "$@"
