#!/usr/bin/env bash
# van Keken 1a to t = 300 (configs/vankeken_1a.yaml: 2D, direct Stokes solve, adaptive) with the code
# before issue 34 and with the current code, side by side: ROUNDS rounds, each running both trees
# one after the other on 1 rank, with the 1-minute load average before each run; prints the wall
# time, the Stokes solve and assembly times and vrms of each run (issue 34's must-show "the linear 2D
# benchmarks no slower"). Usage, from the repository root:
#   git worktree add /tmp/before 94e46e9^ --detach
#   bash benchmarks/scaling/vk1a_before_after.sh /tmp/before [ROUNDS]
# Log: benchmarks/scaling/log/vk1a_before_after_<date>.txt (tee it there).
set -uo pipefail
BEFORE=$(cd "$1" && pwd)
AFTER=$(pwd)
ROUNDS=${2:-3}
PY=${PYTHON:-$AFTER/.venv/bin/python}
OUT=${OUT:-/tmp/vk1a_before_after}
mkdir -p "$OUT"
SHOW='import json,sys; s=json.load(open(sys.argv[1])); t=s["timings"]
print("wall %.2f s  stokes_solve %.2f s  stokes_assembly %.2f s  vrms %.10g  cells %d" % (s["wall_time"], t["stokes_solve"]["max_seconds"], t.get("stokes_assembly", {}).get("max_seconds", float("nan")), s["vrms"], s["cells"]))'
run() {  # tree name
  (cd "$1" && PYTHONPATH="$1" "$PY" -m convection run configs/vankeken_1a.yaml --set time.end=300 \
     --set output.directory="$OUT/$2" --set output.progress=none > "$OUT/$2.log" 2>&1)
}
run "$BEFORE" warm_before; run "$AFTER" warm_after  # JIT and numba caches
for r in $(seq "$ROUNDS"); do
  for name in before after; do
    tree=$BEFORE; [ "$name" = after ] && tree=$AFTER
    printf '%s load=%s %-6s ' "$(date +%H:%M:%S)" "$(cut -d' ' -f1 /proc/loadavg)" "$name"
    run "$tree" "$name"
    "$PY" -c "$SHOW" "$OUT/$name/summary.json"
  done
done
