"""The stress on particles survives everything (issue 48, "Must show"): configs/crameri_case1_free_surface.yaml
made visco-elastic (G = 1e10 Pa: Maxwell times of 3 kyr in the mantle, 300 kyr in the lid, steps of
1 kyr) at CI size, with adaptivity every 2 steps, repartitioning every 3 and the free surface, the
stress and its outputs on the particles. On 1, 2 and 3 ranks: no particle lost, the same meshes,
particles and statistics at every step and the same stress on every particle to the solver's
tolerance; killed on 2 ranks and resumed from its newest checkpoint: the uninterrupted run bit for
bit (statistics and every particle's stress)."""

from __future__ import annotations

import numpy as np
import pytest

from _runs import CONFIGS, assert_same_statistics, final_particles, final_property, kill_and_resume, rows, run_on_ranks

CONFIG = CONFIGS / "crameri_case1_free_surface.yaml"
ELASTIC = ["mesh.cells=[28,7]", "time.dt_max=1 kyr", "time.max_steps=6", "output.progress=none",
           "output.fields_every=4", "particles.generator.particles_per_cell=8", "particles.population.min_per_cell=4",
           "particles.population.max_per_cell=16", "adaptivity.enabled=true", "adaptivity.every=2",
           "adaptivity.max_level=2", "adaptivity.fields=[composition]", "balance.strategy=every", "balance.every=3",
           "output.checkpoint.every_steps=2", "output.checkpoint.keep=10", "physics.elasticity.enabled=true",
           "physics.elasticity.shear_modulus=1e10 Pa",
           "particles.properties=[elastic_stress,elastic_stress_invariant,elastic_share]",
           "particles.output.every_steps=4",
           "output.statistics=[time,velocity,topography,free_surface,mesh,stokes,particles,elasticity]"]
COMPARED = ("vrms", "topography_max", "topography_min", "mesh_quality_min", "elastic_stress_invariant_max",
            "elastic_stress_invariant_mean", "elastic_strain_rate_mean", "viscous_strain_rate_mean")


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("elastic_survival")
    return run_on_ranks(CONFIG, {ranks: folder / f"ranks{ranks}" for ranks in (1, 2, 3)}, ELASTIC)


def test_no_particle_is_lost_and_the_ranks_agree(runs):
    tables = {ranks: rows(folder) for ranks, folder in runs.items()}
    assert len({r["cells"] for r in tables[1]}) > 2  # the mesh adapted
    assert float(tables[1][-1]["elastic_share"]) > 0.1  # the flow is visco-elastic
    for ranks, table in tables.items():
        assert len(table) == 7 and all(r["n_lost"] == "0" for r in table), ranks
        for a, b in zip(tables[1], table):
            assert (a["cells"], a["n_particles"]) == (b["cells"], b["n_particles"]), (ranks, a["step"])
            for key in COMPARED:
                assert float(b[key]) == pytest.approx(float(a[key]), rel=1e-8), (ranks, key, a["step"])
    ids, x, _ = final_particles(runs[1])
    tau = final_property(runs[1], "elastic_stress")
    assert np.abs(tau).max() > 0.0
    for ranks in (2, 3):
        other_ids, other_x, _ = final_particles(runs[ranks])
        assert np.array_equal(ids, other_ids)
        assert np.allclose(x, other_x, rtol=0.0, atol=1e-10)
        assert np.allclose(final_property(runs[ranks], "elastic_stress"), tau, rtol=0.0, atol=1e-8 * np.abs(tau).max())


def test_the_written_particles_carry_the_stress_invariant(runs):
    """The particle output of step 4 (every 4 steps) holds the invariant of each particle's stress."""
    import h5py

    with h5py.File(runs[2] / "particles_000004.h5", "r") as f:
        tau = f["properties/elastic_stress"][...]
        invariant = f["properties/elastic_stress_invariant"][...].reshape(-1)
        share = f["properties/elastic_share"][...].reshape(-1)
    assert tau.shape == (invariant.size, 3)
    expected = np.sqrt(0.5 * (tau[:, 0] ** 2 + tau[:, 1] ** 2) + tau[:, 2] ** 2)
    assert np.allclose(invariant, expected, rtol=1e-12, atol=0.0) and invariant.max() > 0.0
    assert np.all(share >= 0.0) and share.max() > 0.0


def test_killed_run_resumes_bit_for_bit(runs, tmp_path):
    """On 2 ranks, SIGKILLed after the 5th statistics row, resumed from its newest checkpoint."""
    killed = tmp_path / "killed"
    kill_and_resume(CONFIG, killed, 2, ELASTIC, after_rows=5)
    assert_same_statistics(runs[2], killed)
    assert np.array_equal(final_property(runs[2], "elastic_stress"), final_property(killed, "elastic_stress"))
    assert np.array_equal(final_particles(runs[2])[1], final_particles(killed)[1])
