#!/usr/bin/env bash
# Mutation testing of the numerics (issue 17): mutmut over the modules listed in pyproject.toml
# ([tool.mutmut]) with the fast tests that cover them, then a report per module with every
# surviving mutant's diff (test-artifacts/mutation-report.md, an artifact; the scores in docs/mutation.md).
#
#   bash scripts/mutation.sh                 # full run (about an hour on 2 loaded cores), then the report
#   bash scripts/mutation.sh --report-only   # the report from the results in ./mutants
#   bash scripts/mutation.sh --fresh         # forget earlier results (after changing the code)
#   bash scripts/mutation.sh 'twin.runs.metrics.*'   # only these mutants (mutmut name globs)
#
# Runs niced (the machine is shared).  Results are cached in ./mutants: a second run only tests
# mutants without a result, so after adding tests, re-test the survivors (all that are not killed and
# not listed as equivalent) with `bash scripts/mutation.sh --survivors`.
set -euo pipefail
set -f  # the mutant name globs are for mutmut, not for the shell
cd "$(dirname "$0")/.."
[ -x .venv/bin/mutmut ] || bash scripts/setup-env.sh
REPORT=${MUTATION_REPORT:-test-artifacts/mutation-report.md}  # an artifact; docs/mutation.md keeps the scores
export MPLBACKEND=Agg OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1

# What is mutated: every function of the listed modules except the IPOPT set-up of the feedforward
# OCP and the two benchmark helpers (each mutant there would cost a 40 s OCP solve or a timing
# loop); scripts/mutation_report.py keeps the same scope.
scope() { .venv/bin/python scripts/mutation_report.py --scope; }

case "${1:-}" in
  --report-only) ;;
  --fresh) rm -rf mutants; shift; nice -n 19 .venv/bin/mutmut run --max-children 2 $(scope) ;;
  --survivors)
    # tests changed: re-collect which tests cover which function, then re-test what was not killed
    rm -f mutants/mutmut-stats.json
    names=$(.venv/bin/python scripts/mutation_report.py --not-killed --skip-equivalent)
    if [ -n "$names" ]; then nice -n 19 .venv/bin/mutmut run --max-children 2 $names; fi ;;
  "") nice -n 19 .venv/bin/mutmut run --max-children 2 $(scope) ;;
  *) nice -n 19 .venv/bin/mutmut run --max-children 2 "$@" ;;
esac
.venv/bin/python scripts/mutation_report.py --out "$REPORT" --summary docs/mutation.md
echo "mutation report: $REPORT"
