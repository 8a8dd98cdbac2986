#!/usr/bin/env bash
# The coupled adaptive run on 1 and 2 ranks (issue 12's table): van Keken 1a to t = 300, every rank
# count ROUNDS times, interleaved, with the 1-minute load average before each run; prints the wall
# time and the phases of mesh adaptation (field transfer + adaptation + particles' mesh change).
# Usage: bash benchmarks/scaling/vk1a_sitting.sh [ROUNDS]      (from the repository root)
# Log: benchmarks/scaling/log/vk1a_sitting_<date>.txt (tee it there).
set -uo pipefail
ROUNDS=${1:-3}
PY=${PYTHON:-python3}
OUT=${OUT:-/tmp/vk1a_sitting}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
SHARE='import json,sys; s=json.load(open(sys.argv[1])); t=s["timings"]; p=("field_transfer","adaptation","particle_mesh_change")
a=[t[k]["max_seconds"] for k in p]
print("vrms %.6g cells %d  wall %.2f s  stokes_solve %.2f s  %s = %.2f s (%.1f %%)" % (s["vrms"], s["cells"], s["wall_time"], t["stokes_solve"]["max_seconds"], " + ".join("%.2f" % x for x in a), sum(a), 100 * sum(a) / s["wall_time"]))'
$PY -m convection run configs/vankeken_1a.yaml --set time.end=300 --set output.directory="$OUT/warm" --set output.progress=none > /dev/null  # JIT and numba caches
for r in $(seq "$ROUNDS"); do
  for n in 1 2; do
    printf '%s load=%s ranks=%s  ' "$(date +%H:%M:%S)" "$(cut -d' ' -f1 /proc/loadavg)" "$n"
    mpirun -n "$n" $PY -m convection run configs/vankeken_1a.yaml --set time.end=300 \
      --set output.directory="$OUT/n$n" --set output.progress=none > "$OUT/n$n.log" 2>&1
    $PY -c "$SHARE" "$OUT/n$n/summary.json"
  done
done
