#!/bin/bash
# The cost of a step of configs/king_tala.yaml (32 x 32, Ra = 1e4, Di = 0.5 where it applies, 1 rank,
# 60 steps from the config's initial temperature) under boussinesq, tala and ala: a warm-up run each
# (forms compiled), then 3 rounds interleaved. Usage: bash this.sh WORKTREE OUT
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
PY=/work/main/.venv/bin/python
tree=${1:-$(cd "$(dirname "$0")/../../.." && pwd)}; out=${2:-/tmp/step_cost}
rm -rf "$out"; mkdir -p "$out"; cd "$tree"
run() {  # name approximation Di folder
  PYTHONPATH=$tree $PY -m convection run configs/king_tala.yaml --output "$4" --set physics.approximation=$2 \
    --set physics.reference.Di=$3 --set "mesh.cells=[32,32]" --set time.max_steps=60 --set output.progress=none \
    --set output.fields_every=0 > "$4.log" 2>&1
}
for a in boussinesq:0 tala:0.5 ala:0.5; do run warm ${a%%:*} ${a##*:} "$out/warm_${a%%:*}"; done
for round in 1 2 3; do
  for a in boussinesq:0 tala:0.5 ala:0.5; do
    echo "round $round ${a%%:*} load $(cut -d' ' -f1-3 /proc/loadavg)" >> "$out/log"
    run r ${a%%:*} ${a##*:} "$out/${a%%:*}_$round"
  done
done
