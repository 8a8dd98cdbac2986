"""configs/annulus_free_surface.yaml (a free outer surface on the curved annulus, the mesh moving
radially) at CI size: the degree-4 topography relaxes, the enclosed area stays (the mean height
within 1 % of the initial amplitude: the inner free slip is weak, by Nitsche's method, so the
inner circle lets a little through), no particle lost; the same run on 1, 2 and 3 ranks; resumed
bit for bit on 2 ranks."""

from __future__ import annotations

import csv
import math
import shutil
from collections import defaultdict

import numpy as np
import pytest

from _runs import CONFIGS, assert_same_statistics, rows, run_cli, run_on_ranks

CONFIG = CONFIGS / "annulus_free_surface.yaml"
SMALL = ["mesh.resolution=0.16", "time.end=0.012", "output.progress=none", "output.fields_every=2",
         "output.checkpoint.every_steps=2", "output.checkpoint.keep=10", "particles.generator.particles_per_cell=6",
         "particles.population.min_per_cell=3", "particles.population.max_per_cell=12"]
AMPLITUDE = 0.02


def _mean_heights(folder) -> dict[float, float]:
    """The mean height of the outer surface (over the angle, trapezoidal) at every field output."""
    points = defaultdict(list)
    with open(folder / "topography_profile.csv", newline="") as f:
        for r in csv.DictReader(f):
            points[float(r["time"])].append((math.atan2(float(r["y"]), float(r["x"])), float(r["topography"])))
    out = {}
    for t, pts in points.items():
        angle, h = np.array(sorted(pts)).T
        step = np.diff(np.append(angle, angle[0] + 2.0 * math.pi))
        out[t] = float(np.sum(0.5 * (h + np.roll(h, -1)) * step) / (2.0 * math.pi))
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    return run_on_ranks(CONFIG, {ranks: tmp_path_factory.mktemp(f"annulus_fs_{ranks}") for ranks in (1, 2, 3)}, SMALL)


def test_the_surface_relaxes_and_keeps_the_area(runs):
    table = rows(runs[1])
    assert len(table) == 7
    top = np.array([float(r["topography_max"]) for r in table])
    assert top[0] == pytest.approx(AMPLITUDE, rel=1e-12)
    assert np.all(np.diff(top) < 0.0) and top[-1] < 0.2 * AMPLITUDE
    assert all(r["n_lost"] == "0" for r in table)
    means = _mean_heights(runs[1])
    assert len(means) == 4
    assert max(abs(m) for m in means.values()) < 0.01 * AMPLITUDE


def test_ranks_agree(runs):
    base = rows(runs[1])
    for ranks in (2, 3):
        for a, b in zip(base, rows(runs[ranks])):
            assert (a["n_particles"], b["n_lost"]) == (b["n_particles"], "0"), (ranks, a["step"])
            assert float(b["vrms"]) == pytest.approx(float(a["vrms"]), rel=1e-6), (ranks, a["step"])
            for key in ("topography_max", "topography_min", "mesh_quality_min"):
                assert float(b[key]) == pytest.approx(float(a[key]), rel=1e-7, abs=1e-12), (ranks, key, a["step"])


def test_resumed_bit_for_bit_on_2_ranks(runs, tmp_path):
    """From the checkpoint of step 2 (the mesh moved): the statistics to the last digit (the curved
    cells' sizes in Nitsche's term and the rotations removed from the flow come from the undeformed
    cells and from the nodes' positions at each step, not from the mesh the resumed run started on)."""
    resumed = tmp_path / "resumed"
    shutil.copytree(runs[2], resumed)
    proc = run_cli(["resume", str(resumed), "--checkpoint", str(resumed / "checkpoints" / "checkpoint_000002")], 2)
    assert proc.returncode == 0, proc.stderr
    assert "note:" not in proc.stderr, proc.stderr
    assert_same_statistics(runs[2], resumed)


def test_adaptive_and_repartitioned_annulus_agrees_on_1_and_2_ranks(tmp_path):
    """Adaptivity (the curved hierarchy) and repartitioning with the moving outer surface: the same
    meshes and particle counts on 1 and 2 ranks, the flow and surface to 1e-8, no particle lost."""
    extra = [*SMALL, "adaptivity.enabled=true", "adaptivity.every=2", "adaptivity.max_level=1",
             "adaptivity.fields=[composition]", "balance.strategy=every", "balance.every=3", "output.fields_every=0"]
    tables = {ranks: rows(folder) for ranks, folder in
              run_on_ranks(CONFIG, {ranks: tmp_path / str(ranks) for ranks in (1, 2)}, extra).items()}
    assert len({r["cells"] for r in tables[1]}) > 1
    for a, b in zip(tables[1], tables[2]):
        assert (a["cells"], a["n_particles"], b["n_lost"]) == (b["cells"], b["n_particles"], "0"), a["step"]
        for key in ("vrms", "topography_max"):
            assert float(b[key]) == pytest.approx(float(a[key]), rel=1e-8), (key, a["step"])
