#!/usr/bin/env bash
# Particle throughput before and after a change, side by side with deal.II's step-68 in one
# sitting: the vortex problem of the sittings (sitting_common.sh) with the code of a checkout of
# the commit before (BEFORE_TREE, e.g. `git worktree add /tmp/before <commit>`) and of this tree,
# Euler and RK2 on 1 rank, every run ROUNDS times, interleaved, the 1-minute load average printed
# before each run. Take the best of the rounds.
# Usage: bash benchmarks/performance/vortex_before_after.sh BEFORE_TREE [ROUNDS]   (from the repository root)
# Log: benchmarks/performance/log/vortex_before_after_<date>.txt (tee it there).
set -uo pipefail
BEFORE=$(cd "$1" && pwd); ROUNDS=${2:-3}
PY=${PYTHON:-.venv/bin/python}
STEP68=${STEP68:-../shared/bench/step68.sh}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
. "$(dirname "${BASH_SOURCE[0]}")/sitting_common.sh"   # V, RATE, run
echo "before: $BEFORE ($(git -C "$BEFORE" rev-parse --short HEAD)); after: $(pwd) ($(git rev-parse --short HEAD))"
for r in $(seq "$ROUNDS"); do
  run "deal.II step-68, 1 rank" bash "$STEP68" 6 8 0.1 2 1
  for integrator in euler rk2; do
    run "before, $integrator, 1 rank" bash -c "cd '$BEFORE' && PYTHONPATH='$BEFORE' $PWD/$PY $V --integrator $integrator | $PWD/$PY -c '$RATE'"
    run "after, $integrator, 1 rank" bash -c "PYTHONPATH='$PWD' $PY $V --integrator $integrator | $PY -c '$RATE'"
  done
done
