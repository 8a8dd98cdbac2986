"""Issue 22 in miniature: configs/annulus_layer.yaml with adaptivity and load balancing on the
curved annulus (the hierarchy's manifold, fembase/manifold.py), at a CI size: no particle lost,
every particle inside the shell, the same statistics on 1, 2 and 3 ranks (to 1e-7 relative, the
tolerance of the fixed-mesh test tests/configs/test_annulus_layer.py: MUMPS factorises with a dynamic
schedule on several ranks; measured 4e-9 in vrms), and a run killed and resumed on 2 ranks
continuing it: on the exact path (no note), the same counts, the other columns equal to 1e-12
relative. Not bit for bit: the annulus on a fixed mesh (no adaptivity) also resumes with
last-digit differences (vrms 213.07958349695681 against ...680 one step after the checkpoint, 2
ranks), which the box configs of tests/configs/test_resume_configs.py do not show; the cause is open."""

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("gmsh")

from _runs import CONFIGS, final_particles, kill_run, rows, rows_written, run_cli, sets  # noqa: E402

RI, RO = 1.22, 2.22
STEPS = 6
CONFIG = CONFIGS / "annulus_layer.yaml"
EXTRA = ["mesh.resolution=0.25", f"time.max_steps={STEPS}", "time.end=1e9", "output.fields_every=0",
         "output.progress=none", "particles.generator.particles_per_cell=8", "adaptivity.enabled=true",
         "adaptivity.every=2", "adaptivity.max_level=1", "adaptivity.initial_steps=1", "balance.strategy=every",
         "balance.every=3", "output.checkpoint.every_steps=2"]
COUNTS = ("step", "cells", "n_particles", "n_lost", "n_added", "n_removed", "ppc_min", "ppc_max")
RANK_DEPENDENT = ("wall_time", "cell_imbalance", "particle_imbalance")


def _run(directory: Path, ranks: int) -> None:
    proc = run_cli(["run", str(CONFIG), "--output", str(directory), *sets(EXTRA)], ranks)
    assert proc.returncode == 0, proc.stderr


def _columns(directory: Path) -> dict[str, np.ndarray]:
    table = rows(directory)
    return {key: np.array([float(r[key]) for r in table]) for key in table[0]}


def test_adaptive_balanced_annulus_layer(tmp_path):
    runs = {ranks: tmp_path / f"ranks_{ranks}" for ranks in (1, 2, 3)}
    for ranks, directory in runs.items():
        _run(directory, ranks)
    serial = _columns(runs[1])
    assert list(serial["step"]) == list(range(STEPS + 1))
    assert np.all(serial["n_lost"] == 0)
    assert serial["cells"][-1] != serial["cells"][0]  # the mesh adapted
    for ranks, directory in runs.items():
        ids, x, _ = final_particles(directory)
        r = np.linalg.norm(x, axis=1)
        assert ids.size == serial["n_particles"][-1] and np.unique(ids).size == ids.size
        assert r.min() >= RI and r.max() <= RO, ranks
        if ranks == 1:
            continue
        stats = _columns(directory)
        assert np.all(stats["n_lost"] == 0)
        if ranks > 1:
            assert np.any(stats["cell_imbalance"] > 1.0)  # cells really spread over the ranks
        for key in stats:
            if key in RANK_DEPENDENT:
                continue
            if key in COUNTS:
                assert np.array_equal(stats[key], serial[key]), (ranks, key)
                continue
            scale = max(float(np.abs(serial[key]).max()), 1e-300)
            assert np.abs(stats[key] - serial[key]).max() <= 1e-7 * scale, (ranks, key)
    # Killed after step 3 (the checkpoint of step 2 complete) and resumed: the same run.
    killed = tmp_path / "killed"
    code = kill_run(CONFIG, killed, 2, EXTRA, when=lambda d: rows_written(d, 4))
    assert code != 0, "the run ended before it was killed"
    proc = run_cli(["resume", str(killed)], 2)
    assert proc.returncode == 0, proc.stderr
    assert "note:" not in proc.stderr, proc.stderr  # the exact path
    reference, resumed = _columns(runs[2]), _columns(killed)
    for key in reference:
        if key == "wall_time":
            continue
        if key in COUNTS:
            assert np.array_equal(reference[key], resumed[key]), key
            continue
        scale = max(float(np.abs(reference[key]).max()), 1e-300)
        assert np.abs(resumed[key] - reference[key]).max() <= 1e-12 * scale, key
    (ids_a, x_a, _), (ids_b, x_b, _) = final_particles(runs[2]), final_particles(killed)
    assert np.array_equal(ids_a, ids_b) and np.abs(x_a - x_b).max() < 1e-10
