#!/usr/bin/env bash
# The vortex benchmark on both Debian releases in one sitting: every run ROUNDS times, interleaved
# (this machine's release, then the other release's root via scripts/in_release_root.sh, then
# deal.II's step-68 as the reference that does not change between them), with the 1-minute load
# average printed before each run. The numba and numpy versions differ between the releases
# (Debian 12: numba 0.56/numpy 1.24 from PyPI over Debian's; Debian 13: Debian's numba 0.61/numpy
# 2.2): a slowdown of either would show as a lower rate on the same problem.
# Usage: bash benchmarks/performance/releases_sitting.sh [ROUNDS] [OTHER_RELEASE]   (repository root)
# Log: benchmarks/performance/log/releases_sitting_<date>.txt (tee it there).
set -uo pipefail
ROUNDS=${1:-3}
host_release="$(. /etc/os-release && echo "${VERSION_CODENAME:-}")"
if [ "$host_release" = trixie ]; then other=bookworm; else other=trixie; fi
OTHER=${2:-$other}
STEP68=${STEP68:-../shared/bench/step68.sh}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_tcp_disable_family=6
. "$(dirname "${BASH_SOURCE[0]}")/sitting_common.sh"   # V, RATE, run
here() { bash -c "$1"; }
there() { bash scripts/in_release_root.sh "$OTHER" -- bash -c "$1"; }
versions='import sys, dolfinx, numpy, numba; print(f"Python {sys.version.split()[0]}, DOLFINx {dolfinx.__version__}, numpy {numpy.__version__}, numba {numba.__version__}")'
echo "# $host_release (this machine): $(.venv/bin/python -c "$versions")"
echo "# $OTHER (root): $(there ".venv/bin/python -c '$versions'")"
echo "# $(nproc) cores, $(date -u +%Y-%m-%dT%H:%MZ)"
for r in $(seq "$ROUNDS"); do
  run "deal.II step-68, 1 rank" bash "$STEP68" 6 8 0.1 2 1
  for integrator in euler rk2; do
    run "$host_release: ours $integrator, 1 rank" here ".venv/bin/python $V --integrator $integrator | .venv/bin/python -c '$RATE'"
    run "$OTHER: ours $integrator, 1 rank" there ".venv/bin/python $V --integrator $integrator | .venv/bin/python -c '$RATE'"
  done
  run "$host_release: ours euler, 2 ranks" here "mpirun -n 2 .venv/bin/python $V --integrator euler | .venv/bin/python -c '$RATE'"
  run "$OTHER: ours euler, 2 ranks" there "mpirun -n 2 .venv/bin/python $V --integrator euler | .venv/bin/python -c '$RATE'"
done
