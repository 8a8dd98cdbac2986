#!/usr/bin/env bash
# Side by side with ASPECT on the 3D thick layer (configs/thick_layer_3d.yaml at 16^3 to t = 0.002,
# 2 ranks, 245 760 particles): ASPECT 2.5 with block AMG and with block GMG
# (../shared/bench/aspect/thick_layer_3d.prm; for GMG the box is one coarse cell refined 4 times),
# this project with `stokes.solver: iterative` (what `auto` picks in 3D) and `multigrid`.
# Every run REPEAT times in turn (round robin, so a change of the machine's load hits all alike);
# the table keeps each one's fastest run.
#
# Usage: [CELLS=32] [RUNS="..."] bash benchmarks/scaling/aspect_thick_layer_sitting.sh ASPECT_BINARY [REPEAT] [OUT_MD]
#   ASPECT_BINARY: built by ../shared/bench/aspect/build.sh
#   CELLS: cells per side, a power of 2 (default 16; ASPECT's GMG box is one cell refined log2(CELLS) times)
#   END: the end time (default 0.002)
#   LOGS: the folder of the raw logs (default below)
# Writes the raw logs under benchmarks/scaling/log/aspect_thick_layer/ (CELLS=32:
# .../aspect_thick_layer_32/) and the table to OUT_MD (default benchmarks/scaling/aspect_thick_layer.md,
# CELLS=32: aspect_thick_layer_32.md).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
aspect=$(readlink -f "${1:?path to the aspect binary}")
repeat="${2:-3}"
cells="${CELLS:-16}"
end="${END:-0.002}"
suffix=$([ "$cells" = 16 ] && echo "" || echo "_$cells")
refine=$(python3 -c "import math, sys; n = int(sys.argv[1]); k = round(math.log2(n)); assert 2**k == n; print(k)" "$cells")
out_md="${3:-$here/benchmarks/scaling/aspect_thick_layer$suffix.md}"
prm="$here/../shared/bench/aspect/thick_layer_3d.prm"
logs="${LOGS:-$here/benchmarks/scaling/log/aspect_thick_layer$suffix}"
work="$(mktemp -d "${TMPDIR:-/tmp}/aspect_sitting.XXXXXX")"
mkdir -p "$logs"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
python="$here/.venv/bin/python"

# The GMG variant: ASPECT's GMG needs a mesh hierarchy (one coarse cell refined 4 times = 16^3).
# ASPECT's parameter file has 16^3's particle count (60 per cube, as this project's 10 per
# tetrahedron): scaled with the cells (before 2026-12-04 the 32^3 sittings gave ASPECT 8x fewer).
particles=$((60 * cells * cells * cells))
sed -e 's/set Stokes solver type = block AMG/set Stokes solver type = block GMG/' \
    -e 's/set \([XYZ]\) repetitions = 16/set \1 repetitions = 1/' \
    -e "s/set Initial global refinement = 0/set Initial global refinement = $refine/" \
    -e "s/set Number of particles = .*/set Number of particles = $particles/" \
    -e "s/set End time .*/set End time                               = $end/" "$prm" > "$work/gmg.prm"
sed -e "s|set Output directory .*|set Output directory = $work/out-amg|" \
    -e "s/set \([XYZ]\) repetitions = 16/set \1 repetitions = $cells/" \
    -e "s/set Number of particles = .*/set Number of particles = $particles/" \
    -e "s/set End time .*/set End time                               = $end/" "$prm" > "$work/amg.prm"
sed -i -e "s|set Output directory .*|set Output directory = $work/out-gmg|" "$work/gmg.prm"

load=$(cut -d' ' -f1-3 /proc/loadavg)
echo "load average before the sitting: $load" | tee "$logs/sitting.txt"
echo "cells: $cells" | tee -a "$logs/sitting.txt"
echo "end: $end" | tee -a "$logs/sitting.txt"
# RUNS="aspect_gmg multigrid" limits the sitting to some of the four; multigrid_scalable is the
# multigrid with PETSc's default Galerkin product (before 2026-12-07: matptap_via scalable). Each
# run's peak resident size (the largest rank's, from GNU time on mpirun) goes to <run>_<round>.rss.
runs="${RUNS:-aspect_amg aspect_gmg iterative multigrid}"
for round in $(seq 1 "$repeat"); do
  for run in $runs; do
    log="$logs/${run}_$round.log"
    rss=(/usr/bin/time -f "maxrss_kb %M" -o "$logs/${run}_$round.rss")
    start=$(date +%s.%N)
    case $run in
      aspect_amg) "${rss[@]}" mpirun -n 2 "$aspect" "$work/amg.prm" > "$log" 2>&1 ;;
      aspect_gmg) "${rss[@]}" mpirun -n 2 "$aspect" "$work/gmg.prm" > "$log" 2>&1 ;;
      *) solver=${run%_scalable}  # multigrid_scalable: the multigrid with PETSc's default Galerkin product
         petsc=$([ "$run" = "$solver" ] && echo "" || echo "-matptap_via scalable")
         "${rss[@]}" mpirun -n 2 env PYTHONPATH="$here" PETSC_OPTIONS="$petsc" "$python" -m convection run \
           "$here/configs/thick_layer_3d.yaml" --set "mesh.cells=[$cells,$cells,$cells]" --set time.end=$end --set stokes.solver=$solver \
           --output "$work/out-$run" > "$log" 2>&1
         cp "$work/out-$run/summary.json" "$logs/${run}_$round.summary.json"
         cp "$work/out-$run/statistics.csv" "$logs/${run}_$round.statistics.csv" ;;
    esac
    wall=$(echo "$(date +%s.%N) - $start" | bc)
    echo "$run round $round: $wall s" | tee -a "$logs/sitting.txt"
  done
done
echo "load average after the sitting: $(cut -d' ' -f1-3 /proc/loadavg)" | tee -a "$logs/sitting.txt"
"$python" "$here/benchmarks/scaling/aspect_thick_layer_table.py" "$logs" > "$out_md"
cat "$out_md"
rm -rf "$work"
