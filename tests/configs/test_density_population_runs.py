"""configs/vankeken_1a_particles.yaml with ``particles.population.method=density`` and the
``particle_distribution`` statistics: the same particles on 1, 2 and 3 ranks, and a resume from a
checkpoint bit for bit."""

import shutil

import numpy as np
import pytest

from _runs import CONFIGS, assert_same_statistics, final_particles, rows, run_cli, run_on_ranks, sets, shrink

from convection.io.checkpoint import list_checkpoints

CONFIG = CONFIGS / "vankeken_1a_particles.yaml"
STATISTICS = "output.statistics=[time,velocity,mesh,particles,particle_distribution,wall_time]"


def _small(steps: int) -> list[str]:
    return [*shrink(CONFIG, divisor=3, coarsen=1.8, max_particles=3000, max_per_cell=8), "adaptivity.every=4",
            f"time.max_steps={steps}", "output.progress=none", "output.fields_every=0", "particles.output=null",
            "particles.population.method=density", STATISTICS]


def test_density_control_gives_the_same_particles_on_1_2_and_3_ranks(tmp_path):
    runs = run_on_ranks(CONFIG, {r: tmp_path / str(r) for r in (1, 2, 3)}, _small(14))
    a = rows(runs[1])
    assert len(a) == 15 and int(a[-1]["n_added"]) > 0 and int(a[-1]["n_removed"]) > 0
    assert all(0.0 <= float(r["distribution_score_min"]) <= float(r["distribution_score"])
               <= float(r["distribution_score_max"]) <= 1.0 for r in a)
    ids1, x1, p1 = final_particles(runs[1])
    exact = ("step", "cells", "n_particles", "n_added", "n_removed", "ppc_min", "ppc_max")
    for ranks in (2, 3):
        b = rows(runs[ranks])
        assert len(b) == len(a)
        for x, y in zip(a, b):
            assert [x[k] for k in exact] == [y[k] for k in exact]
            assert float(y["distribution_score"]) == pytest.approx(float(x["distribution_score"]), rel=1e-9)
            assert float(y["vrms"]) == pytest.approx(float(x["vrms"]), rel=1e-6)
        ids, x, p = final_particles(runs[ranks])
        assert np.array_equal(ids1, ids)
        assert np.allclose(x1, x, rtol=0, atol=1e-9) and np.allclose(p1, p, rtol=0, atol=1e-8)


@pytest.mark.parametrize("ranks", [1, 2])
def test_density_control_resumes_bit_for_bit(tmp_path, ranks):
    extra = [*_small(16), "output.checkpoint.every_steps=3", "output.checkpoint.keep=10"]
    reference = tmp_path / "reference"
    proc = run_cli(["run", str(CONFIG), "--output", str(reference), *sets(extra)], ranks)
    assert proc.returncode == 0, proc.stderr
    resumed = tmp_path / "resumed"
    shutil.copytree(reference, resumed)
    checkpoints = list_checkpoints(resumed)
    assert len(checkpoints) > 2
    proc = run_cli(["resume", str(resumed), "--checkpoint", str(checkpoints[1])], ranks)
    assert proc.returncode == 0, proc.stderr
    assert "note:" not in proc.stderr, proc.stderr
    assert_same_statistics(reference, resumed)
    last = rows(resumed)[-1]
    assert int(last["n_removed"]) > 0 and last["wall_time"] != rows(reference)[-1]["wall_time"]  # run again
    for a, b in zip(final_particles(reference), final_particles(resumed)):
        assert np.array_equal(a, b)
