"""Lab-note helper: when the tip passes 300 / 400 km, by the cell measure (statistics) and by the
particle measure (log/particle_tip.py), for run folders.

    python -m benchmarks.schmeling.log.passing RUN_DIR [RUN_DIR ...]
"""

import sys
from pathlib import Path

import numpy as np

from benchmarks.schmeling.run import passing, tip_curve
from benchmarks.schmeling.log.particle_tip import tip

HERE = Path(__file__).resolve().parent

for run in map(Path, sys.argv[1:]):
    cells = tip_curve(run)
    files = sorted(run.glob("particles_*.h5"))
    parts = tuple(np.array(v) for v in zip(*map(tip, files))) if files else (np.array([]), np.array([]))
    print(run.name, " ".join(f"{d:g} km: cell {passing(cells, d):.1f} / particles "
                             f"{passing(parts, d) if parts[0].size else float('nan'):.1f} Myr" for d in (300.0, 400.0)))
