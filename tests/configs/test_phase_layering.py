"""Christensen & Yuen (1985) layering at CI size (benchmarks/phase_transitions/layering.py has the full runs).

configs/phase_layering.yaml at Ra = 1e5 on 24 x 24 cells to t = 0.03 (one rank, in this process): the
endothermic transition at mid-depth with P = -0.1 leaves one well-mixed interior (whole mantle), with
P = -0.6 it splits the box into two layers, each with its own interior temperature, exchanging a
small part of the whole-mantle case's mass flux through mid-depth. The sampling of the final state
is checked on any number of ranks (run under mpirun -n 2 and 3 too).
"""

import numpy as np
import pytest
from mpi4py import MPI

from benchmarks.phase_transitions import layering
from convection import build_model, load_config

STORED = {"whole": -0.013821, "layered": 0.350552}
"""dT_mid of the runs below, 2026-12-07 (one rank)."""


def _config(name: str, *extra: str) -> dict:
    case = layering.CASES[name]
    return load_config(case.path, [*case.overrides, *extra, "output.directory=/tmp/phase_layering_unused"])


def test_the_cases_lie_on_either_side_of_the_published_boundary():
    """P = Rb gamma / Ra: -0.1 and -0.6 beside C&Y's boundary near -0.2 .. -0.4; Rb = 2 Ra at mid-depth."""
    assert layering.phase_parameter(_config("whole")) == pytest.approx(-0.1)
    assert layering.phase_parameter(_config("layered")) == pytest.approx(-0.6)
    assert [layering.phase_parameter(_config(f"P{p:.1f}")) for p in (-0.2, -0.3, -0.4)] == pytest.approx(
        [-0.2, -0.3, -0.4])
    config = _config("layered")
    transition = config["phase_transitions"]["mid"]
    assert transition["Rb"] == 2.0 * config["physics"]["Ra"] and transition["depth"] == 0.5
    assert transition["temperature"] == 0.5 and transition.get("entropy_change", 0.0) == 0.0


def test_trapezoidal_mean_is_exact_for_linear_profiles():
    z = np.linspace(0.0, 1.0, 9)
    assert layering._mean(3.0 * z + 1.0) == pytest.approx(2.5)
    grid = np.add.outer(z, 2.0 * z)  # rows: z, columns: x
    assert layering._mean(grid, axis=1) == pytest.approx(z + 1.0)


def test_sample_is_exact_on_any_number_of_ranks():
    """A quadratic temperature (P2: exact) sampled on a grid with points on faces, corners and the
    boundary: every point once, the same values on every rank."""
    model = build_model(_config("layered", "mesh.cells=[8,8]"), comm=MPI.COMM_WORLD)
    T = model.fields()["temperature"]
    T.interpolate(lambda x: 0.3 + x[0] * x[1] + 0.5 * x[1] ** 2)
    T.x.scatter_forward()
    z = np.linspace(0.0, 1.0, 9)
    X, Z = np.meshgrid(z, z)
    points = np.column_stack([X.ravel(), Z.ravel()])
    values = layering.sample(model, {"T": T}, points)["T"][:, 0]
    model.destroy()
    assert values == pytest.approx(0.3 + points[:, 0] * points[:, 1] + 0.5 * points[:, 1] ** 2, abs=1e-12)
    gathered = MPI.COMM_WORLD.allgather(values)
    assert all(np.array_equal(g, gathered[0]) for g in gathered)


def test_layering_regimes_at_ci_size(tmp_path):
    if MPI.COMM_WORLD.size > 1:
        pytest.skip("one rank: runs in this process")
    quick = list(layering.QUICK)
    whole = layering.run_case(layering.CASES["whole"], tmp_path, quick, comm=MPI.COMM_SELF)
    layered = layering.run_case(layering.CASES["layered"], tmp_path, quick, comm=MPI.COMM_SELF)
    assert (layering.regime(whole), layering.regime(layered)) == ("whole mantle", "layered")
    assert abs(whole["jump_mean"]) < 0.05 < layering.LAYERED_JUMP < layered["jump_mean"]
    assert layered["flux"] < 0.35 * whole["flux"]
    # the layered interior: colder above the transition than below, the whole-mantle one nearly uniform
    for result in (whole, layered):
        profile = np.asarray(result["T_profile"])
        assert np.all((profile >= -1e-9) & (profile <= 1.0 + 1e-9))
        assert profile[0] == pytest.approx(1.0, abs=1e-9) and profile[-1] == pytest.approx(0.0, abs=1e-9)
    assert whole["jump_mean"] == pytest.approx(STORED["whole"], abs=2e-3)
    assert layered["jump_mean"] == pytest.approx(STORED["layered"], abs=2e-3)
