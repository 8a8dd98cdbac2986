#!/usr/bin/env bash
# ASPECT 2.5's own bending beam (benchmarks/viscoelastic_bending_beam of v2.5.0, included unchanged)
# at NX x NZ cells: loaded to 50 kyr, then resumed from its checkpoint with gravity off to END years,
# with three tracer particles at the beam's tip whose positions give the deflection. What was run
# for bending_beam.md: NX x NZ = 30 x 20 and 75 x 50 (the prm's own), END = 200e3, 1 rank.
# Usage: bash run_aspect.sh ASPECT_BINARY ASPECT_GIT_DIR NX NZ END RUN_DIR
# then:  python -m benchmarks.viscoelastic.bending_beam --aspect-csv RUN_DIR/outNX
set -euo pipefail
aspect=$(readlink -f "$1"); git_dir=$(readlink -f "$2"); nx=$3; nz=$4; end=$5
mkdir -p "$6" && cd "$6"
git --git-dir="$git_dir" show v2.5.0:benchmarks/viscoelastic_bending_beam/viscoelastic_bending_beam.prm > base.prm
printf '# x y (m): the beam tip, mid-line, top and bottom corners\n4500 2750\n4500 3000\n4500 2500\n' > tip.dat
cat > "load$nx.prm" <<PRM
# ASPECT's v2.5.0 prm (base.prm) with: the mesh $nx x $nz, the end time 50 kyr, a checkpoint at the
# end, and tracer particles at the beam's tip (written every step) instead of the visualization.
include base.prm
set Output directory = out$nx
set End time = 50e3
subsection Geometry model
  subsection Box
    set X repetitions = $nx
    set Y repetitions = $nz
  end
end
subsection Termination criteria
  set Termination criteria = end time
  set Checkpoint on termination = true
end
subsection Checkpointing
  set Steps between checkpoint = 1000
end
subsection Postprocess
  set List of postprocessors = velocity statistics, basic statistics, particles
  subsection Particles
    set Number of particles = 3
    set Time between data output = 0
    set Data output format = gnuplot
    set Particle generator name = ascii file
    subsection Generator
      subsection Ascii file
        set Data directory = ./
        set Data file name = tip.dat
      end
    end
  end
end
PRM
cat > "unload$nx.prm" <<PRM
# The recovery: resumes the loaded run's checkpoint (Resume computation = auto) with gravity off.
include load$nx.prm
set End time = $end
subsection Gravity model
  subsection Vertical
    set Magnitude = 0.
  end
end
PRM
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
mpirun -n 1 "$aspect" "load$nx.prm" > "load$nx.log" 2>&1
mpirun -n 1 "$aspect" "unload$nx.prm" > "unload$nx.log" 2>&1
echo "$PWD/out$nx"
