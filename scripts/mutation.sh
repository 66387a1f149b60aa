#!/usr/bin/env bash
# Mutation testing that counts every mutant (issue 23): per module, cached by source hash, not in CI.
#
#   bash scripts/mutation.sh twin.runs.metrics twin.estimation.glr   # these modules (skipped if cached)
#   bash scripts/mutation.sh --all                                   # the whole scope (hours on 2 busy cores)
#   bash scripts/mutation.sh --list                                  # the scope and which results are current
#   bash scripts/mutation.sh --force twin.physics.fillet             # run again although cached
#
# Every call then rewrites the summary (docs/mutation.md, committed) and the full report with every
# survivor's diff (test-artifacts/mutation-report.md, an artifact).  Details: scripts/mutation_modules.py.
# The issue-17 report (docs/mutation-report.md, scripts/mutation_report.py) excused survivors by regex
# rules and left mutants unrun; it is kept for its history, not as the score.
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/mutmut ] || bash scripts/setup-env.sh
export MPLBACKEND=Agg OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
exec nice -n 10 .venv/bin/python scripts/mutation_modules.py "$@" \
  --summary "${MUTATION_SUMMARY:-docs/mutation.md}" \
  --report "${MUTATION_REPORT:-test-artifacts/mutation-report.md}"
