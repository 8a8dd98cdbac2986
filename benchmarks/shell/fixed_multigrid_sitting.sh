#!/usr/bin/env bash
# The fixed 3D shell with the multigrid (levels by refinement: a coarser gmsh shell refined uniformly,
# convection/geometry/shell.py) against BoomerAMG (`iterative`, what `auto` picks on a shell) at about
# equal cells: configs/shell_plates.yaml (20 000 particles, plates on the outer surface) for STEPS
# steps on 2 ranks, every run REPEAT times in turn (round robin); the table keeps each run's fastest.
#
# Usage: [STEPS=10] [REPEAT=3] bash benchmarks/shell/fixed_multigrid_sitting.sh RUN...
#   RUN: SOLVER:RESOLUTION, e.g. multigrid:0.25 iterative:0.2287 (gmsh's own mesh at 0.2287 has
#   about the cells of gmsh's 0.485 refined once: 0.25 * (11817 / 15432)^(1/3))
#   LOGS: the folder of the raw logs (default benchmarks/shell/log/fixed_multigrid_<date>)
# Prints the table (Markdown); each run's statistics, summary and GNU time's peak resident size
# (the largest rank's) go to LOGS.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
steps="${STEPS:-10}"
repeat="${REPEAT:-3}"
logs="${LOGS:-$here/benchmarks/shell/log/fixed_multigrid_$(date +%F)}"
work="$(mktemp -d "${TMPDIR:-/tmp}/shell_sitting.XXXXXX")"
mkdir -p "$logs"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
python="$here/.venv/bin/python"
echo "load average before the sitting: $(cut -d' ' -f1-3 /proc/loadavg)" | tee "$logs/sitting.txt"
echo "steps: $steps" | tee -a "$logs/sitting.txt"
for round in $(seq 1 "$repeat"); do
  for run in "$@"; do
    solver=${run%%:*}
    resolution=${run#*:}
    name="${solver}_${resolution}"
    start=$(date +%s.%N)
    /usr/bin/time -f "maxrss_kb %M" -o "$logs/${name}_$round.rss" mpirun -n 2 env PYTHONPATH="$here" "$python" \
      -m convection run "$here/configs/shell_plates.yaml" --set stokes.solver="$solver" \
      --set mesh.resolution="$resolution" --set time.max_steps="$steps" --set time.end=1e9 \
      --set output.fields_every=0 --set particles.output.every_steps=100000 --set output.progress=none \
      --output "$work/$name" > "$logs/${name}_$round.log" 2>&1
    cp "$work/$name/summary.json" "$logs/${name}_$round.summary.json"
    cp "$work/$name/statistics.csv" "$logs/${name}_$round.statistics.csv"
    echo "$name round $round: $(echo "$(date +%s.%N) - $start" | bc) s" | tee -a "$logs/sitting.txt"
  done
done
echo "load average after the sitting: $(cut -d' ' -f1-3 /proc/loadavg)" | tee -a "$logs/sitting.txt"
"$python" - "$logs" "$@" <<'PY'
import csv, json, sys
from pathlib import Path
logs = Path(sys.argv[1])
print("| run | cells | wall per round [s] | best [s] | Stokes solve (best round) [s] | Stokes iterations per step | max RSS per rank [MB] | vrms at the end |")
print("|---|---|---|---|---|---|---|---|")
for run in sys.argv[2:]:
    name = run.replace(":", "_")
    rounds = sorted(logs.glob(f"{name}_*.summary.json"))
    summaries = [json.loads(p.read_text()) for p in rounds]
    walls = [s["wall_time"] for s in summaries]
    best = min(range(len(walls)), key=walls.__getitem__)
    rows = list(csv.DictReader(open(str(rounds[best]).replace(".summary.json", ".statistics.csv"))))
    iterations = [int(r["stokes_iterations"]) for r in rows]
    rss = max(int(open(str(p).replace(".summary.json", ".rss")).read().split()[-1]) for p in rounds) / 1024
    s = summaries[best]
    print(f"| {run} | {s['cells']} | {', '.join(f'{w:.1f}' for w in walls)} | {walls[best]:.1f} | "
          f"{s['timings']['stokes_solve']['max_seconds']:.1f} | {min(iterations)}-{max(iterations)} | {rss:.0f} | "
          f"{float(rows[-1]['vrms']):.6g} |")
PY
rm -rf "$work"
