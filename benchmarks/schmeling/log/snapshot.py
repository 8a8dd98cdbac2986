"""Lab-note helper: log10 viscosity and the lithosphere's 0.5 contour near the trench, from fields_000.h5.

    python -m benchmarks.schmeling.log.snapshot OUT.png RUN_DIR:TIME [RUN_DIR:TIME ...]

TIME is the output time key nearest the wanted Myr. Positions in the file are in km.
"""

import sys

import h5py
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.tri as mtri  # noqa: E402
import numpy as np  # noqa: E402


def panel(ax, run: str, time: float) -> None:
    with h5py.File(f"{run}/fields_000.h5", "r") as f:
        mesh = f["Mesh/mesh"]
        xy, cells = mesh["geometry"][:], mesh["topology"][:]
        keys = list(f["Function/viscosity"].keys())
        key = min(keys, key=lambda k: abs(float(k.replace("_", ".")) - time))
        eta = f[f"Function/viscosity/{key}"][:, 0]
        lith = f[f"Function/lithosphere/{key}"][:, 0]
    tri = mtri.Triangulation(xy[:, 0], 750 - xy[:, 1], cells)
    im = ax.tripcolor(tri, facecolors=np.log10(eta), cmap="viridis", vmin=19, vmax=23)
    if lith.size == xy.shape[0]:
        ax.tricontour(tri, lith, levels=[0.5], colors="w", linewidths=0.8)
    else:
        centre = xy[cells].mean(axis=1)
        ax.tricontour(mtri.Triangulation(centre[:, 0], 750 - centre[:, 1]), lith, levels=[0.5], colors="w",
                      linewidths=0.8)
    ax.set_xlim(700, 1700)
    ax.set_ylim(600, 0)
    ax.set_aspect("equal")
    ax.set_title(f"{run.split('/')[-1]} t = {key.replace('_', '.')[:5]} Myr", fontsize=8)
    ax.set_xlabel("x [km]")
    ax.set_ylabel("depth below box top [km]")
    return im


if __name__ == "__main__":
    specs = [s.rsplit(":", 1) for s in sys.argv[2:]]
    fig, axes = plt.subplots(len(specs), 1, figsize=(7, 3.2 * len(specs)), constrained_layout=True, squeeze=False)
    for ax, (run, time) in zip(axes[:, 0], specs):
        im = panel(ax, run, float(time))
    fig.colorbar(im, ax=axes[:, 0], label="log10 viscosity [Pa s]", shrink=0.6)
    fig.savefig(sys.argv[1], dpi=100)
