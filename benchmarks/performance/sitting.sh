#!/usr/bin/env bash
# One side-by-side sitting against deal.II's step-68 (issue 12's table): every run ROUNDS times,
# interleaved, with the 1-minute load average printed before each run.
# Usage: bash benchmarks/performance/sitting.sh [ROUNDS]      (from the repository root)
# Log: benchmarks/performance/log/sitting_<date>.txt (tee it there).
set -uo pipefail
ROUNDS=${1:-3}
PY=${PYTHON:-.venv/bin/python}
STEP68=${STEP68:-../shared/bench/step68.sh}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
. "$(dirname "${BASH_SOURCE[0]}")/sitting_common.sh"   # V, RATE, run
# The machine's own 2-process ceiling: two independent serial runs with half the particles each,
# started together; their combined rate is twice the slower one's.
HALF="-m benchmarks.performance.vortex --cells 64 --particles 196608 --steps 50 --integrator euler"
PAIR='import json,sys; r=[json.loads(l)["particle_updates_per_second"] for l in sys.stdin if l.startswith("{")]; print("rate=%.0f (two independent half runs: %s)" % (2 * min(r), ", ".join("%.0f" % x for x in r)))'
for r in $(seq "$ROUNDS"); do
  run "deal.II step-68, 1 rank" bash "$STEP68" 6 8 0.1 2 1
  run "ours euler, 1 rank" bash -c "$PY $V --integrator euler | $PY -c '$RATE'"
  run "ours rk2, 1 rank" bash -c "$PY $V --integrator rk2 | $PY -c '$RATE'"
  run "deal.II step-68, 2 ranks" bash "$STEP68" 6 8 0.1 2 2
  run "ours euler, 2 ranks --balance" bash -c "mpirun -n 2 $PY $V --integrator euler --balance | $PY -c '$RATE'"
  run "ours euler, 2 ranks" bash -c "mpirun -n 2 $PY $V --integrator euler | $PY -c '$RATE'"
  run "ceiling: 2 x 1 rank, half each" bash -c "($PY $HALF & $PY $HALF & wait) | $PY -c '$PAIR'"
done
