"""Issue 22: the seed's global model, configs/shell_adaptive.yaml (3D spherical shell, plates,
adaptivity by temperature, particles at the core with at most 25 per cell, repartitioned by
particle weight), at a CI size on 1 and 2 ranks: the mesh adapts and stays on the spheres, no
particle is lost, every particle stays inside the shell, no cell holds more than 25 after the
population control, the meshes and the flow agree across rank counts (to 1e-5 relative: the 3D
Stokes solve is iterative, FGMRES to its relative tolerance, whose iterates depend on the
partition), and the repartition keeps the particles balanced where the static partition lets them drift."""

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("gmsh")

from _runs import CONFIGS, final_particles, rows, run_cli, sets  # noqa: E402

RI, RO = 1.22, 2.22
STEPS = 4
CONFIG = CONFIGS / "shell_adaptive.yaml"
EXTRA = ["mesh.resolution=0.8", f"time.max_steps={STEPS}", "time.end=1e9", "output.fields_every=0",
         "output.progress=none", "particles.generator.num_particles=4000", "particles.output.every_steps=1000",
         "adaptivity.every=2", "adaptivity.initial_steps=1", "balance.every=2",
         "output.statistics=[time,velocity,nusselt,mesh,particles,load]"]


def _run(directory: Path, ranks: int, extra=()) -> dict[str, np.ndarray]:
    proc = run_cli(["run", str(CONFIG), "--output", str(directory), *sets([*EXTRA, *extra])], ranks)
    assert proc.returncode == 0, proc.stderr
    table = rows(directory)
    return {key: np.array([float(r[key]) for r in table]) for key in table[0]}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    out = {}
    for ranks in (1, 2):
        folder = tmp_path_factory.mktemp(f"shell_adaptive_{ranks}")
        out[ranks] = (folder, _run(folder, ranks))
    return out


def test_adapts_keeps_particles_inside_and_limits_them(runs):
    folder, stats = runs[1]
    assert list(stats["step"]) == list(range(STEPS + 1))
    assert len(set(stats["cells"])) > 1  # the mesh adapted
    assert np.all(stats["n_lost"] == 0)
    assert np.all(stats["ppc_max"][1:] <= 25)
    assert stats["n_removed"].sum() > 0  # the population control had work to do
    for ranks in (1, 2):
        ids, x, _ = final_particles(runs[ranks][0])
        r = np.linalg.norm(x, axis=1)
        assert np.unique(ids).size == ids.size == runs[ranks][1]["n_particles"][-1]
        assert r.min() >= RI and r.max() <= RO, ranks


def test_one_and_two_ranks_agree(runs):
    """The same meshes (cell counts at every step) and the same flow to 1e-5 relative (FGMRES to
    its tolerance: vrms differs by 1.3e-6 at step 0). The particle count may differ by a few: at
    step 0 the population control removed 15 of 4000 particles on 1 rank and 14 on 2 (measured; the cause
    is not pinned down, suspected a particle on a facet between a full and an overfull curved cell,
    counted in either)."""
    serial, parallel = runs[1][1], runs[2][1]
    assert np.array_equal(serial["step"], parallel["step"])
    assert np.array_equal(serial["cells"], parallel["cells"])
    assert np.all(parallel["n_lost"] == 0)
    assert np.abs(serial["n_particles"] - parallel["n_particles"]).max() <= 3
    for key in ("time", "vrms", "nusselt", "nusselt_bottom"):
        scale = max(float(np.abs(serial[key]).max()), 1e-300)
        assert np.abs(parallel[key] - serial[key]).max() <= 1e-5 * scale, key


def test_repartition_balances_particles(runs, tmp_path):
    """Measured at this size on 2 ranks: never repartitioned, the particle imbalance (max/mean)
    grows to 1.04, 1.07, 1.10 over steps 2-4 as the particles move; repartitioned every 2 steps
    it stays at 1.006 or below."""
    balanced = runs[2][1]["particle_imbalance"]
    static = _run(tmp_path / "static", 2, ["balance.strategy=none"])["particle_imbalance"]
    assert balanced[2:].max() < 1.02
    assert static[-1] > 1.05 and static[-1] > balanced[-1]
