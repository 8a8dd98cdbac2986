"""The elastic stress carried by particles through whole runs: a lid-driven cavity of a Maxwell
material (eta = G = 1, dt = 0.05: the Maxwell time is 20 steps) whose stress varies in space, so
the old stress's load shapes the flow. The particles circulate across the two ranks' halves and
the mesh is repartitioned every 3 steps; the run gives the 1-rank numbers to the direct solver's
round-off, and a run stopped at a checkpoint and resumed gives the uninterrupted one bit for bit."""

import textwrap

import h5py
import numpy as np
import pytest

from _runs import assert_same_statistics, final_particles, final_property, rows, run_cli, sets

CAVITY = textwrap.dedent("""\
    name: elastic_cavity
    mesh: {cells: [6, 6]}
    physics:
      Ra: 0.0
      viscosity: {law: 1.0}
      elasticity: {enabled: true, shear_modulus: 1.0}
    boundary:
      velocity:
        top: {kind: prescribed, value: ["16*x*x*(1-x)*(1-x)", 0]}
        bottom: no_slip
        left: no_slip
        right: no_slip
      temperature: {left: insulating, right: insulating, bottom: insulating, top: insulating}
    initial: {temperature: "0"}
    energy: {enabled: false}
    stokes: {solver: direct}
    particles:
      enabled: true
      generator: {name: random_uniform, particles_per_cell: 8, seed: 2}
      properties: [elastic_stress, {name: rank, update: never}]  # rank: where each particle was made
    balance: {strategy: every, every: 3}
    time: {end: 1.0, cfl: 100.0, dt_max: 0.05, max_steps: 8}
    output: {fields_every: 0, progress: none, checkpoint: {every_steps: 4}}
    """)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cavity")
    config = folder / "cavity.yaml"
    config.write_text(CAVITY)
    out = {}
    for name, ranks, extra in (("serial", 1, []), ("two", 2, []), ("stopped", 2, ["time.max_steps=4"])):
        out[name] = folder / name
        proc = run_cli(["run", str(config), "--output", str(out[name]), *sets(extra)], ranks)
        assert proc.returncode == 0, proc.stderr
    proc = run_cli(["resume", str(out["stopped"]), *sets(["time.max_steps=8"])], 2)
    assert proc.returncode == 0, proc.stderr
    return out


def test_stress_builds_up_unevenly(runs):
    tau = final_property(runs["two"], "elastic_stress")
    assert tau.shape[1] == 3 and np.all(np.isfinite(tau))
    size = np.abs(tau).max()
    assert size > 0.05 and np.ptp(tau[:, 2]) > 0.5 * size  # sheared under the lid, little in the corners


def test_two_ranks_give_the_serial_history(runs):
    a, b = rows(runs["serial"]), rows(runs["two"])
    assert [r["n_particles"] for r in a] == [r["n_particles"] for r in b]
    for ra, rb in zip(a, b):
        assert float(ra["vrms"]) == pytest.approx(float(rb["vrms"]), rel=1e-10)
    ids1, x1, _ = final_particles(runs["serial"])
    ids2, x2, _ = final_particles(runs["two"])
    assert np.array_equal(ids1, ids2) and np.allclose(x1, x2, rtol=0, atol=1e-12)
    t1, t2 = final_property(runs["serial"], "elastic_stress"), final_property(runs["two"], "elastic_stress")
    assert np.allclose(t1, t2, rtol=0, atol=1e-11 * np.abs(t1).max())


def test_resumed_run_is_bit_for_bit(runs):
    assert_same_statistics(runs["two"], runs["stopped"])
    assert np.array_equal(final_property(runs["two"], "elastic_stress"),
                          final_property(runs["stopped"], "elastic_stress"))


def test_particles_changed_rank(runs):
    """Rows of the checkpoint are grouped by the rank holding them; some are not where they were made."""
    from convection.io.checkpoint import latest_checkpoint

    with h5py.File(latest_checkpoint(runs["two"]) / "particles.h5", "r") as f:
        offsets = f["rank_offsets"][...]
        names = [n.decode() if isinstance(n, bytes) else str(n) for n in f["layout/names"][...]]
        made = f["properties"][...][:, int(f["layout/starts"][names.index("rank")])]
    holder = np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))
    assert holder.shape == made.shape and set(holder) == {0, 1}
    assert np.count_nonzero(holder != made) > 10
