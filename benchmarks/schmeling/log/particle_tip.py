"""Lab-note helper: the slab tip from the particles, independent of the particle-to-mesh interpolation.

    python -m benchmarks.schmeling.log.particle_tip RUN_DIR [RUN_DIR ...]

Reads RUN_DIR/particles/particles_*.h5 (positions in km, property ``lithosphere`` in 0..1), bins the
particles in boxes of 10 km (x) by 5 km (depth) and reports, per output time, the deepest box whose
lithosphere share is at least 0.5 (at least 3 particles in the box), minus the 50 km of air: the
depth of the C = 0.5 contour's deepest point, as G-ADOPT measures its level set (to about 5 km).
"""

import sys
from pathlib import Path

import h5py
import numpy as np

TOP = 750.0  # box top [km]
AIR = 50.0


def tip(h5: Path) -> tuple[float, float]:
    with h5py.File(h5, "r") as f:
        x = f["positions"][:, :2]
        c = f["properties/lithosphere"][:]
        t = float(f.attrs["time"])
    depth = TOP - x[:, 1]
    ix = np.floor(x[:, 0] / 10.0).astype(int)
    iz = np.floor(depth / 5.0).astype(int)
    key = ix * 1000 + iz
    keys, inverse = np.unique(key, return_inverse=True)
    count = np.bincount(inverse)
    share = np.bincount(inverse, weights=c) / count
    ok = (share >= 0.5) & (count >= 3)
    deepest = (keys[ok] % 1000).max()
    return t, (deepest + 1) * 5.0 - AIR


if __name__ == "__main__":
    for run in sys.argv[1:]:
        files = sorted(Path(run).glob("particles_*.h5")) or sorted(Path(run).rglob("particles_*.h5"))
        print(run, " ".join(f"{t:.1f}:{z:.0f}" for t, z in map(tip, files)))
