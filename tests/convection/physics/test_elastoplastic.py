"""Visco-elasto-plasticity (convection/physics/rheology.py ``ViscoPlastic.maxwell_yield`` with
convection/physics/elasticity.py): a box shortened in pure shear builds its stress up as the
backward-Euler Maxwell material and then holds it at the yield stress, with Picard and with
Newton (the residual per iteration falling to the tolerance); the particles carry the limited
stress; the plastic strain rate switches on at the yield; the invalid combinations are refused."""

import logging
from pathlib import Path

import numpy as np
import pytest
import yaml
from mpi4py import MPI

from benchmarks.viscoelastic import stress
from convection.app.factory import build_model
from convection.config.loader import load_config
from convection.schema import ConfigError

SIGMA_Y, DT, STEPS = 0.015, 0.1, 20
"""Yield stress (below the Maxwell plateau 2 eta eps = 0.02), the step and the steps run."""


def _document(out: Path, *, method: str = "picard", combination: str = "minimum", eta_star: float = 0.0) -> dict:
    document = stress.document(cells=2, dt=DT, end=STEPS * DT, out=out)
    document["physics"]["viscosity"] = {"law": {
        "name": "viscoplastic", "combination": combination, "viscous": stress.ETA,
        "plastic": {"name": "von_mises", "yield_stress": SIGMA_Y, "eta_star": eta_star}}}
    document["stokes"]["nonlinear"] = {"method": method, "rtol": 1e-10, "max_iterations": 30}
    document["particles"]["properties"] = ["elastic_stress", "plastic_strain"]
    return document


def _run(out: Path, method: str, eta_star: float = 0.0) -> tuple[np.ndarray, np.ndarray, list[tuple[float, ...]]]:
    """The particles' tau_II and plastic strain after every step, and the residual histories."""
    logging.getLogger().addFilter(lambda record: record.levelno >= logging.WARNING)
    comm = MPI.COMM_WORLD
    model = build_model(load_config(None, document=_document(out, method=method, eta_star=eta_star)), comm=comm)
    model.start()
    taus, strains, histories = [], [], []
    for _ in range(STEPS):
        model.step(DT)
        values = model.particles.primary.properties.values
        tau = values("elastic_stress")
        tau_ii = np.sqrt(0.25 * (tau[:, 0] - tau[:, 1]) ** 2 + tau[:, 2] ** 2)
        taus.append([comm.allreduce(float(tau_ii.min(initial=np.inf)), op=MPI.MIN),
                     comm.allreduce(float(tau_ii.max(initial=-np.inf)), op=MPI.MAX)])
        strain = values("plastic_strain")[:, 0]
        strains.append(comm.allreduce(float(strain.max(initial=-np.inf)), op=MPI.MAX))
        histories.append(model.flow_result.nonlinear.history)
    model.destroy()
    return np.array(taus), np.array(strains), histories


@pytest.mark.parametrize("method", ["picard", "newton"])
def test_stress_builds_up_then_holds_at_the_yield_stress(tmp_path, method):
    taus, strains, histories = _run(tmp_path / method, method)
    n = np.arange(1, STEPS + 1)
    maxwell = 2 * stress.ETA * stress.EPS * (1 - (1 + stress.G * DT / stress.ETA) ** -n)  # backward Euler
    elastic = maxwell < SIGMA_Y
    first_yield = int(np.argmin(elastic))
    assert 5 < first_yield < STEPS - 5  # both regimes are seen
    np.testing.assert_allclose(taus[elastic], np.repeat(maxwell[elastic, None], 2, axis=1), rtol=1e-9)
    np.testing.assert_allclose(taus[~elastic], SIGMA_Y, rtol=1e-9)  # the stress is the yield stress
    # The plastic strain grows only while the material yields, by eps_II dt a step (explicit: a step
    # behind). The first step integrates the flow solved at t = 0, viscous (no time has passed), which yields.
    assert strains[0] == pytest.approx(stress.EPS * DT, rel=1e-9)
    assert np.all(strains[:first_yield] == strains[0])
    assert strains[-1] == pytest.approx(stress.EPS * DT * (STEPS - first_yield), rel=1e-6)
    for history in histories:
        assert history[-1] <= 1e-10
    # The boundaries fix the (uniform) flow: one iteration each; the shear band's benchmark
    # (tests/benchmarks_viscoelastic/test_shear_band.py) has the nonlinear convergence.
    assert all(len(h) == 2 for h in histories)


def test_regularised_yield_adds_eta_star_times_the_plastic_strain_rate(tmp_path):
    """With eta_star: |tau|_II = sigma_y + 2 eta_star |eps_pl|_II, eps_pl = eps_eff - tau / (2 eta_ve); the
    steady stress of the discrete law, T = eta_ve (sigma_y + 2 eta_star eps) / (eta_ve + eta_star (1 - chi))."""
    eta_star = 0.05
    taus, _, _ = _run(tmp_path, "newton", eta_star)
    eta_ve = stress.ETA * stress.G * DT / (stress.ETA + stress.G * DT)
    chi = eta_ve / (stress.G * DT)
    steady = eta_ve * (SIGMA_Y + 2 * eta_star * stress.EPS) / (eta_ve + eta_star * (1 - chi))
    assert steady > SIGMA_Y * 1.01
    np.testing.assert_allclose(taus[-1], steady, rtol=1e-4)  # approached geometrically, step by step
    assert abs(taus[-1, 0] - steady) < 0.5 * abs(taus[-3, 0] - steady)


def test_invalid_combinations_are_refused(tmp_path):
    document = _document(tmp_path, combination="tosi")
    with pytest.raises(ConfigError, match=r"physics\.viscosity\.law\.combination': with physics\.elasticity"):
        load_config(None, document=document)
    document = _document(tmp_path)
    document["physics"]["viscosity"]["law"] = {"name": "weakened", "law": document["physics"]["viscosity"]["law"],
                                               "weakening": {"field": "plastic_strain", "start": 0.1, "end": 0.2}}
    with pytest.raises(ConfigError, match="must be the material's law itself"):
        load_config(None, document=document)
    document = _document(tmp_path, combination="harmonic")
    document["physics"]["elasticity"]["enabled"] = False
    document["particles"]["properties"] = ["plastic_strain"]
    assert load_config(None, document=document)  # without elasticity every combination stays


def test_check_refuses_in_one_line(tmp_path):
    from _runs import error_line, run_cli

    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(_document(tmp_path, combination="harmonic")))
    line = error_line(run_cli(["check", str(path)]), 2, "physics.viscosity.law.combination")
    assert "minimum" in line
