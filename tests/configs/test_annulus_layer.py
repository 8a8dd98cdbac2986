"""Issue 13 must-show (b) in miniature: configs/annulus_layer.yaml (a dense layer on the inner
surface carried by particles, thermal convection, free slip on both curved surfaces) on a coarse
annulus for a few steps: no particle lost, every written particle inside the shell, and on 2+ ranks
the same statistics and particles as on one rank (the full-size comparison is
benchmarks/shell/annulus_particles.py, measured in benchmarks/shell/README.md)."""

from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

pytest.importorskip("gmsh")

ROOT = Path(__file__).resolve().parents[2]
RI, RO = 1.22, 2.22
STEPS = 4
RANK_DEPENDENT = ("wall_time", "cell_imbalance", "particle_imbalance")


def _run(comm, directory):
    from convection.config.loader import load_config
    from convection.app.factory import run_config

    overrides = ["mesh.resolution=0.2", f"time.max_steps={STEPS}", "time.end=1e9",
                 "particles.output.every_steps=2", "particles.output.properties=[composition]",
                 "output.fields_every=0", "output.progress=none", "output.checkpoint.at_end=false",
                 f"output.directory={directory}"]
    run_config(load_config(ROOT / "configs" / "annulus_layer.yaml", overrides), comm=comm)


def _particles(directory):
    """{step: (sorted ids, positions and composition in id order)} of every particle file."""
    import h5py

    out = {}
    for path in sorted(Path(directory).glob("particles_*.h5")):
        with h5py.File(path, "r") as f:
            ids = np.asarray(f["ids"]).reshape(-1)
            x = np.asarray(f["positions"])
            c = np.asarray(f["properties/composition"]).reshape(-1)
            step = int(f.attrs["step"])
        order = np.argsort(ids)
        out[step] = (ids[order], x[order], c[order])
    return out


def test_annulus_layer_keeps_particles_inside_and_matches_one_rank(world, tmp_path):
    from convection.io.pictures import read_statistics

    base = Path(world.bcast(str(tmp_path) if world.rank == 0 else None))
    _run(world, base / "all")
    if world.size > 1 and world.rank == 0:
        _run(MPI.COMM_SELF, base / "one")
    world.barrier()
    if world.rank != 0:
        return
    stats = read_statistics(base / "all" / "statistics.csv")
    particles = _particles(base / "all")
    assert list(stats["step"]) == list(range(STEPS + 1)) and sorted(particles) == [0, 2, 4]
    assert np.all(stats["n_lost"] == 0)
    assert stats["n_particles"][0] > 5000 and stats["entrainment"][0] >= 0.0
    assert stats["vrms"][-1] > 0.0
    for step, (ids, x, c) in particles.items():
        assert ids.size == stats["n_particles"][step] and np.unique(ids).size == ids.size
        r = np.linalg.norm(x, axis=1)
        assert r.min() >= RI and r.max() <= RO, step
        assert np.all((c == 0.0) | (c == 1.0)) and 0 < c.sum() < c.size  # the dense layer
    if world.size == 1:
        return
    serial = read_statistics(base / "one" / "statistics.csv")
    for key in stats:
        if key in RANK_DEPENDENT:
            continue
        scale = max(float(np.abs(serial[key]).max()), 1e-300)
        assert np.abs(stats[key] - serial[key]).max() <= 1e-7 * scale, key
    for step, (ids, x, c) in _particles(base / "one").items():
        assert np.array_equal(ids, particles[step][0]) and np.array_equal(c, particles[step][2])
        # MUMPS factorises with a dynamic schedule on > 1 rank: velocities differ from the serial
        # run's in the last digits; positions measured 0 to 8e-11 apart after 2 steps in most runs,
        # 2.385e-7 in 2 of 12 runs on 2 ranks (the same value each time, with this session's code
        # and with the code before it: one alternative schedule), so the bound is 1e-6.
        difference = float(np.abs(x - particles[step][1]).max(initial=0.0))
        assert difference <= 1e-6, (step, difference)
