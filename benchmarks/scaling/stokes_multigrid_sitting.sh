#!/usr/bin/env bash
# Regenerates benchmarks/scaling/stokes_multigrid.md: the whole Stokes solve against the mesh,
# `stokes.solver: multigrid` beside the AMG solver (`iterative`), constant viscosity and contrasts
# of 1e4 and 1e6, in 3D (8^3 ... 32^3) and 2D (128^2 ... 512^2), on 2 ranks. Every row in a process
# of its own (so that its peak resident size is its own); the machine otherwise idle. 1024^2
# (9.4 million unknowns, about 24 GB at the 2.5 kB per unknown measured at 512^2) does not fit in
# the 24 GB of the 2-core machine.
#
# Usage: bash benchmarks/scaling/stokes_multigrid_sitting.sh [OUT_MD]
#   SIZES_3D="8 16 24 32" SIZES_2D="128 256 512" AMG_MAX_3D=24 AMG_MAX_2D=512 override the sizes
#   (AMG rows stop at AMG_MAX_*: its memory and time at the largest sizes).
# Raw rows go to benchmarks/scaling/log/stokes_multigrid/rows.md.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
out_md="${1:-$here/benchmarks/scaling/stokes_multigrid.md}"
logs="$here/benchmarks/scaling/log/stokes_multigrid"
mkdir -p "$logs"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
python="$here/.venv/bin/python"
cd "$here"  # the script runs as a module of the benchmarks package
sizes_3d="${SIZES_3D:-8 16 24 32}"
sizes_2d="${SIZES_2D:-128 256 512}"
amg_max_3d="${AMG_MAX_3D:-24}"
amg_max_2d="${AMG_MAX_2D:-512}"

load_before=$(cut -d' ' -f1-3 /proc/loadavg)
rows="$logs/rows.md"
: > "$rows"
row() {  # row DIM N CONTRAST SOLVER
  mpirun -n 2 "$python" -m benchmarks.scaling.stokes_multigrid --dim "$1" --sizes "$2" --contrast "$3" --solvers "$4" 2>>"$logs/stderr.log" \
    | grep '^| ' | tee -a "$rows"
}
for dim in 3 2; do
  if [ "$dim" = 3 ]; then sizes="$sizes_3d" amg_max="$amg_max_3d"; else sizes="$sizes_2d" amg_max="$amg_max_2d"; fi
  for n in $sizes; do
    for contrast in 1 1e4 1e6; do
      row "$dim" "$n" "$contrast" multigrid
      [ "$n" -le "$amg_max" ] && row "$dim" "$n" "$contrast" iterative
    done
  done
done
load_after=$(cut -d' ' -f1-3 /proc/loadavg)

{
  cat <<HEAD
# The whole Stokes solve against the mesh: multigrid and BoomerAMG

Generated $(date -u '+%Y-%m-%d %H:%M UTC') by \`bash benchmarks/scaling/stokes_multigrid_sitting.sh\` on $(nproc) cores, 2 ranks,
load average $load_before before and $load_after after. One cold solve from zero per row, each row
in a process of its own (single runs, not best of three: the iterations are the point), \`ksp_rtol\`
1e-7, the thick layer's temperature, Ra = 1e6, free slip on every side; the viscosity is constant or
exp(-ln(contrast) T) (the contrast across the layer). The multigrid's meshes are the boxes of n/2,
n/4, ... cells (\`stokes.multigrid.levels: 0\`). Memory: the growth of the peak resident size (max
over the ranks, times the ranks) while the solver is made and solves, per Stokes unknown.
BoomerAMG rows stop at ${amg_max_3d}^3 and ${amg_max_2d}^2.

HEAD
  "$python" - "$rows" <<'PY'
import sys
from collections import defaultdict
HEADER = ("| dim | cells per side | Stokes unknowns | viscosity contrast | solver | levels | iterations | "
          "setup + solve [s] | assembly [s] | memory [bytes / unknown] |\n|---|---|---|---|---|---|---|---|---|---|")
rows = [line.rstrip("\n") for line in open(sys.argv[1]) if line.startswith("| ")]
print(HEADER)
print("\n".join(rows))
its = defaultdict(list)
for line in rows:
    cells = [c.strip() for c in line.strip("|").split("|")]
    its[(cells[0], cells[4], cells[3])].append((int(cells[1]), int(cells[6])))
print("\nIterations against the mesh (smallest to largest size):\n")
print("| dim | solver | contrast | iterations | max / min |\n|---|---|---|---|---|")
for (dim, solver, contrast), values in sorted(its.items()):
    counts = [c for _, c in sorted(values)]
    print(f"| {dim} | {solver} | {contrast} | {' '.join(map(str, counts))} | {max(counts) / min(counts):.2f} |")
PY
} > "$out_md"
cat "$out_md"
