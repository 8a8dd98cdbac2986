"""The strain-localisation model (configs/localisation.yaml) at CI size: shear bands on particles.

An extending visco-plastic layer with a weak seed; the particles carry their plastic strain, which
weakens the yield stress. The checks: every step converges (Newton, 1e-8); the same run on 1, 2
and 3 ranks (Open MPI, MUMPS) gives the same particle counts and nonlinear iteration counts and
the same statistics to 1e-7 relative (MUMPS sums in another order on another partition; the
band grows from those round-off differences no faster than that); the deformation localises
more with weakening than without; a killed run resumes bit for bit; the benchmark script prints
its JSON line.
"""

import json
import sys

import numpy as np
import pytest

from _runs import (
    CONFIGS, ROOT, assert_same_statistics, env, final_particles, final_property, kill_run, rows, rows_written, run_cli,
    guarded_run, sets,
)

CONFIG = CONFIGS / "localisation.yaml"
SMALL = ["mesh.cells=[32,8]", "time.end=0.3", "output.progress=none", "output.fields_every=0",
         "particles.output.every_steps=null"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    out = {}
    for ranks in (1, 2, 3):
        folder = tmp_path_factory.mktemp(f"loc{ranks}")
        proc = run_cli(["run", str(CONFIG), "--output", str(folder), *sets(SMALL)], ranks)
        assert proc.returncode == 0, proc.stderr
        out[ranks] = folder
    return out


def _localisation(e):
    """Fraction of the particles holding half of the total plastic strain."""
    order = np.sort(e)[::-1]
    return (np.searchsorted(np.cumsum(order), 0.5 * order.sum()) + 1) / e.size


def test_every_step_converges_and_the_layer_yields_in_bands(runs):
    table = rows(runs[1])
    assert len(table) > 10
    for row in table:
        assert float(row["nonlinear_residual"]) <= 1e-8 and int(row["nonlinear_iterations"]) >= 1
        assert 1e-3 * (1 - 1e-12) <= float(row["eta_min"]) and float(row["eta_max"]) <= 1.0 + 1e-12
    _, x, _ = final_particles(runs[1])
    e = final_property(runs[1], "plastic_strain")
    assert np.all(e >= 0)
    assert 0.05 < np.mean(e > 0.01) < 0.7  # a part of the layer yielded, not all of it
    assert e.max() > 0.5  # the bands weakened fully (the weakening ends at e = 0.5)
    # The bands reach the surface away from the seed (|x - 2| > 0.5 near the top).
    top = (x[:, 1] > 0.8) & (np.abs(x[:, 0] - 2) > 0.5)
    assert np.any(e[top] > 0.1)


def test_one_two_and_three_ranks_agree(runs):
    base = rows(runs[1])
    for ranks in (2, 3):
        other = rows(runs[ranks])
        assert [r["step"] for r in base] == [r["step"] for r in other]
        for a, b in zip(base, other):
            for key in ("n_particles", "n_lost", "n_added", "n_removed", "nonlinear_iterations", "cells"):
                assert a[key] == b[key], (key, ranks, a["step"])
            for key in ("time", "vrms", "eta_min", "eta_max", "vrms_surface", "vmax_surface"):
                assert float(a[key]) == pytest.approx(float(b[key]), rel=1e-7), (key, ranks, a["step"])
        assert np.array_equal(final_particles(runs[1])[0], final_particles(runs[ranks])[0])
        e1, e2 = final_property(runs[1], "plastic_strain"), final_property(runs[ranks], "plastic_strain")
        assert np.allclose(e1, e2, rtol=1e-6, atol=1e-9)


def test_weakening_localises_further(runs, tmp_path):
    proc = run_cli(["run", str(CONFIG), "--output", str(tmp_path),
                    *sets([*SMALL, "physics.viscosity.law.plastic.weakening=null"])])
    assert proc.returncode == 0, proc.stderr
    weak = final_property(runs[1], "plastic_strain")
    plain = final_property(tmp_path, "plastic_strain")
    assert weak.max() > 2 * plain.max()
    assert _localisation(weak) < _localisation(plain)


def test_killed_run_resumes_bit_for_bit(runs, tmp_path):
    extra = [*SMALL, "output.checkpoint.every_steps=4"]
    killed = tmp_path / "killed"
    code = kill_run(CONFIG, killed, 2, extra, when=lambda d: rows_written(d, 10))
    assert code != 0
    proc = run_cli(["resume", str(killed)], 2)
    assert proc.returncode == 0, proc.stderr
    assert_same_statistics(runs[2], killed)
    ids1, x1, p1 = final_particles(runs[2])
    ids2, x2, p2 = final_particles(killed)
    assert np.array_equal(ids1, ids2) and np.array_equal(x1, x2) and np.array_equal(p1, p2)


def test_benchmark_script_prints_its_json_line(tmp_path):
    proc = guarded_run([sys.executable, "-m", "benchmarks.localisation.run", "--methods",
                        "--cells", "16x4", "--steps", "3", "--out", str(tmp_path), "--results", str(tmp_path)],
                       cwd=ROOT, env=env(), budget=300)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    assert summary["picard"] >= 3 and summary["newton"] >= 3
    assert (tmp_path / "methods.md").exists() and (tmp_path / "methods.png").exists()
