"""Lab-note helper: air in the plate's top cell row (675-700 km, x 1300-2900 km) per field output, from
fields_000.h5 of a DG0 run: how many cells hold > 1 % air, their mean air and lithosphere fractions
and mean log10 viscosity (23 for intact plate).

    python -m benchmarks.schmeling.log.air_film RUN_DIR
"""
import sys
import h5py
import numpy as np
run = sys.argv[1]
with h5py.File(f"{run}/fields_000.h5") as f:
    xy = f["Mesh/mesh/geometry"][:]; cells = f["Mesh/mesh/topology"][:]
    keys = sorted(f["Function/air"].keys(), key=lambda k: float(k.replace("_", ".")))
    for k in keys:
        a = f[f"Function/air/{k}"][:, 0]; l = f[f"Function/lithosphere/{k}"][:, 0]; eta = f[f"Function/viscosity/{k}"][:, 0]
        if a.size != cells.shape[0]:
            continue
        p = xy[cells]; area = 0.5 * np.abs((p[:,1,0]-p[:,0,0])*(p[:,2,1]-p[:,0,1]) - (p[:,2,0]-p[:,0,0])*(p[:,1,1]-p[:,0,1]))
        c = p.mean(axis=1)
        plate = (c[:, 0] > 1300) & (c[:, 0] < 2900)
        top = plate & (c[:, 1] > 675) & (c[:, 1] < 700)
        mixed_top = top & (a > 0.01)
        print(f"t={k:>22s} air total {np.sum(a*area):9.0f} km2 | plate top row (675-700 km, x 1300-2900): cells {top.sum()}, with air>1%: {mixed_top.sum()}, mean air {a[top].mean():.3f}, mean lith {l[top].mean():.3f}, mean log10 eta {np.log10(eta[top]).mean():.2f} | row 700-725 mean lith {l[plate & (c[:,1]>700)&(c[:,1]<725)].mean():.3f}")
