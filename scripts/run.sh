#!/usr/bin/env bash
# Set everything up (idempotent) and run the default job: configs/demo.yaml on 2 MPI ranks, then
# draw output/demo/summary.png. Extra arguments go to the CLI (e.g. --set time.end=0.02).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
py="$(bash scripts/setup.sh | tail -n 1)"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
ranks="${RANKS:-2}"
mpirun -n "$ranks" --oversubscribe "$py" -m convection run configs/demo.yaml --output output/demo "$@"
"$py" -m convection.plot output/demo
