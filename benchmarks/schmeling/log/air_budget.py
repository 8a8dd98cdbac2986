"""Lab-note helper: air below the initial surface (z < 700 km) and rock above it, per km of width, in three
x ranges (mantle side, trench, plate), from fields_000.h5 of a DG0 run.

    python -m benchmarks.schmeling.log.air_budget RUN_DIR
"""
import sys
import h5py
import numpy as np
run = sys.argv[1]
with h5py.File(f"{run}/fields_000.h5") as f:
    xy = f["Mesh/mesh/geometry"][:]; cells = f["Mesh/mesh/topology"][:]
    keys = sorted(f["Function/air"].keys(), key=lambda k: float(k.replace("_", ".")))
    p = xy[cells]; area = 0.5*np.abs((p[:,1,0]-p[:,0,0])*(p[:,2,1]-p[:,0,1]) - (p[:,2,0]-p[:,0,0])*(p[:,1,1]-p[:,0,1])); c = p.mean(axis=1)
    for k in keys[:: max(1, len(keys)//5)] + [keys[-1]]:
        a = f[f"Function/air/{k}"][:, 0]
        if a.size != cells.shape[0]: continue
        out = []
        for lo, hi in ((0, 1000), (1000, 1300), (1300, 3000)):
            m = (c[:,0] > lo) & (c[:,0] < hi)
            below = np.sum((a*area)[m & (c[:,1] < 700)]) / (hi - lo)
            solid_above = np.sum(((1-a)*area)[m & (c[:,1] > 700)]) / (hi - lo)
            out.append(f"x {lo}-{hi}: air below 700 {below:5.2f} km, solid above 700 {solid_above:5.2f} km")
        print(f"t={float(k.replace('_','.')):5.1f}", " | ".join(out))
