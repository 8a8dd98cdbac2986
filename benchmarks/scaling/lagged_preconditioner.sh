#!/usr/bin/env bash
# The multigrid preconditioner kept over several steps (stokes.multigrid.rebuild_steps,
# convection/solvers/stokes/lagged.py) on the 3D thick layer: wall time, iterations and how far vrms
# strays from a tightly solved reference, for: set up every solve (rebuild_steps 1), the defaults
# (10, 0.25), (20, 0.5), and both at ksp_rtol 1e-10.
#
# Usage: [CELLS=16] [END=0.002] bash benchmarks/scaling/lagged_preconditioner.sh [OUT_DIR]
# One run each, one after the other, 2 ranks (a sitting: nothing else running). Prints a markdown table.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cells="${CELLS:-16}"
end="${END:-0.002}"
out="${1:-$(mktemp -d "${TMPDIR:-/tmp}/lagged.XXXXXX")}"
python="$here/.venv/bin/python"
mkdir -p "$out"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 PYTHONPATH="$here"
echo "load average before: $(cut -d' ' -f1-3 /proc/loadavg)" >&2
runs=("every 1 0.25 1e-7" "default 10 0.25 1e-7" "long 20 0.5 1e-7" "every_tight 1 0.25 1e-10" "default_tight 10 0.25 1e-10")
for run in "${runs[@]}"; do
    read -r name steps change rtol <<< "$run"
    rm -rf "$out/$name"
    mpirun -n 2 -x PYTHONPATH "$python" -m convection run "$here/configs/thick_layer_3d.yaml" \
        --set "mesh.cells=[$cells,$cells,$cells]" --set "time.end=$end" --set stokes.solver=multigrid \
        --set "stokes.multigrid.rebuild_steps=$steps" --set "stokes.multigrid.rebuild_dt_change=$change" \
        --set "stokes.petsc_options={ksp_rtol: $rtol}" --set output.progress=none --set output.fields_every=0 \
        --output "$out/$name" > "$out/$name.log" 2>&1
done
"$python" - "$out" "${runs[@]}" <<'EOF'
import csv
import json
import sys
from pathlib import Path

out, runs = Path(sys.argv[1]), [r.split() for r in sys.argv[2:]]


def rows(name):
    return list(csv.DictReader(open(out / name / "statistics.csv")))


reference = rows("every_tight")
print("| run | rebuild_steps | rebuild_dt_change | ksp_rtol | steps | wall [s] | Stokes solve [s] | its/step "
      "| max relative vrms difference to the ksp_rtol 1e-10 run set up every solve |")
print("|---|---|---|---|---|---|---|---|---|")
for name, steps, change, rtol in runs:
    r, summary = rows(name), json.loads((out / name / "summary.json").read_text())
    n = min(len(r), len(reference))
    diff = max(abs(float(a["vrms"]) - float(b["vrms"])) / float(b["vrms"]) for a, b in zip(r[:n], reference[:n]))
    its = sum(int(x["stokes_iterations"]) for x in r) / len(r)
    print(f"| {name} | {steps} | {change} | {rtol} | {summary['steps']} | {summary['wall_time']:.1f} | "
          f"{summary['timings']['stokes_solve']['max_seconds']:.1f} | {its:.1f} | {diff:.1e} |")
EOF
