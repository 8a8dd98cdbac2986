#!/usr/bin/env bash
# What reproducible runs cost (issue 19): van Keken 1a to t = 300, ROUNDS times, interleaved, with
# the 1-minute load average before each run; wall time and Stokes solve time (max over ranks).
#   old      the code before reproducible partitions and solves (git commit OLD, default c0922a9:
#            SCOTCH partition, parallel MUMPS), in a temporary worktree
#   new      this code (rcb partition; on 2 ranks PETSc's telescope, the default: the system gathered
#            on rank 0, one sequential MUMPS factorisation there, the solution scattered back)
#   mumps    this code on 2 ranks with the parallel MUMPS factorisation (not reproducible)
#   red      this code on 2 ranks with PETSc's redundant: every rank factorises the whole system
#            with sequential MUMPS (reproducible too)
# Usage: bash benchmarks/scaling/direct_solver_sitting.sh [ROUNDS]      (from the repository root)
# Log: benchmarks/scaling/log/direct_solver_sitting_<date>.txt (tee it there).
set -uo pipefail
ROUNDS=${1:-3}
PY=${PYTHON:-.venv/bin/python}
OUT=${OUT:-/tmp/direct_solver_sitting}
OLD=${OLD:-c0922a9}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
here=$(pwd)
old_tree="$OUT/old_tree"
mkdir -p "$OUT"
[ -d "$old_tree" ] || git worktree add -q --detach "$old_tree" "$OLD"
SHARE='import json,sys; s=json.load(open(sys.argv[1])); t=s["timings"]
print("vrms %.10g cells %d  wall %.2f s  stokes_solve %.2f s" % (s["vrms"], s["cells"], s["wall_time"], t["stokes_solve"]["max_seconds"]))'
declare -A OPTS=(
  [new]="{}"
  [mumps]="{pc_type: lu, pc_factor_mat_solver_type: mumps}"
  [red]="{pc_type: redundant, redundant_pc_type: lu, redundant_pc_factor_mat_solver_type: mumps}"
)
run() {  # run NAME RANKS TREE OPTIONS
  local name=$1 n=$2 tree=$3 opts=$4
  printf '%s load=%s %-6s ranks=%s  ' "$(date +%H:%M:%S)" "$(cut -d' ' -f1 /proc/loadavg)" "$name" "$n"
  (cd "$tree" && PYTHONPATH="$tree" mpirun -n "$n" "$here/$PY" -m convection run configs/vankeken_1a.yaml \
      --set time.end=300 --set output.directory="$OUT/$name$n" --set output.progress=none \
      --set "stokes.petsc_options=$opts" > "$OUT/$name$n.log" 2>&1)
  "$here/$PY" -c "$SHARE" "$OUT/$name$n/summary.json"
}
run warm 1 "$here" "{}" > /dev/null          # JIT and numba caches of both trees
run warm 1 "$old_tree" "{}" > /dev/null
for r in $(seq "$ROUNDS"); do
  for n in 1 2; do
    run old "$n" "$old_tree" "{}"
    run new "$n" "$here" "{}"
  done
  run mumps 2 "$here" "${OPTS[mumps]}"
  run red 2 "$here" "${OPTS[red]}"
done
git worktree remove --force "$old_tree"
