#!/bin/bash
# Before (f81aa24, /work/wt-before) and after (main) side by side, interleaved, 3 rounds:
# the default job's run (van Keken 1a to t = 300, 2 ranks, scripts/run.sh's overrides) and the 3D
# thick layer at 16^3 (20 steps, 1 rank).
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
PY=/work/main/.venv/bin/python
out=/work/timing; rm -rf $out; mkdir -p $out
for round in 1 2 3; do
  for tree in before main; do
    dir=/work/wt-$tree; [ $tree = main ] && dir=/work/main
    cd $dir
    echo "round $round $tree load $(cut -d' ' -f1-3 /proc/loadavg)" >> $out/log
    s=$(date +%s.%N)
    PYTHONPATH=$dir mpirun -n 2 --oversubscribe $PY -m convection run configs/vankeken_1a.yaml --output $out/vk_${tree}_$round \
      --set output.progress=none --set output.fields_every=10 --set particles.output.every_time=100 \
      --set "particles.output.properties=[composition]" --set time.end=300 > $out/vk_${tree}_$round.log 2>&1
    e=$(date +%s.%N); echo "vk $tree $round $(echo "$e - $s" | bc)" >> $out/log
    s=$(date +%s.%N)
    PYTHONPATH=$dir $PY -m convection run configs/thick_layer_3d.yaml --output $out/tl_${tree}_$round \
      --set "mesh.cells=[16,16,16]" --set time.max_steps=20 --set output.progress=none > $out/tl_${tree}_$round.log 2>&1
    e=$(date +%s.%N); echo "tl $tree $round $(echo "$e - $s" | bc)" >> $out/log
  done
done
