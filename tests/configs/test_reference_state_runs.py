"""The reference state of physical parameters in runs (issue 49): a TALA model with a depth-dependent
thermal expansivity and heat capacity and a 660 with latent heat, written in physical units, against
its nondimensional twin; its adiabat outputs in kelvin (fields as ParaView reads them, and the
``adiabat`` statistic); ``check`` refusing bad input; killed and resumed runs bit for bit (TALA, ALA,
the phase transition with latent heat); and 1, 2, 3 ranks equal to the solver's tolerance.

Small: 8 x 8 cells, a few steps."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from mpi4py import MPI

from _runs import CONFIGS, assert_same_statistics, error_line, kill_and_resume, rows, run_cli, run_on_ranks, sets
from convection.config.loader import load_config
from convection.io.pictures import import_pyvista
from convection.physics.compressible import ReferenceProfile, ReferenceState
from convection.schema import ConfigError

L, ETA, KAPPA, RHO, G, ALPHA, DT, T_REF, CP = 2.89e6, 1e24, 1e-6, 3300.0, 10.0, 3e-5, 3000.0, 273.0, 1250.0
MYR = 1e6 * 365.25 * 86400.0
STATISTICS = ["time", "velocity", "nusselt", "temperature", "heating", "adiabat"]


def _physical() -> dict:
    return {
        "name": "reference_physical",
        "scaling": {"length": "2890 km", "viscosity": "1e24 Pa s", "density": "3300 kg/m^3", "gravity": "10 m/s^2",
                    "thermal_expansivity": "3e-5 1/K", "temperature_difference": "3000 K",
                    "reference_temperature": "273 K", "heat_capacity": "1250 J/kg/K"},
        "mesh": {"cells": [8, 8], "upper": ["2890 km", "2890 km"]},
        "physics": {"approximation": "tala", "reference": {
            "potential_temperature": "1600 K",
            "profile": {"depth": ["0 km", "660 km", "2890 km"],
                        "thermal_expansivity": ["3e-5 1/K", "2e-5 1/K", "1e-5 1/K"],
                        "heat_capacity": ["1250 J/kg/K", "1250 J/kg/K", "1300 J/kg/K"]}}},
        "phase_transitions": {"p660": {"depth": "660 km", "width": "100 km", "temperature": "1900 K",
                                       "clapeyron": "-2.5 MPa/K", "density_jump": 0.08,
                                       "entropy_change": "clausius_clapeyron"}},
        "boundary": {"velocity": dict.fromkeys(("left", "right", "bottom", "top"), "free_slip"),
                     "temperature": {"bottom": {"dirichlet": "3273 K"}, "top": {"dirichlet": "273 K"}}},
        "initial": {"temperature": "1 - z + 0.05*cos(pi*x)*sin(pi*z)"},
        "stokes": {"solver": "direct"},
        "time": {"end": "1e5 Myr", "max_steps": 6},
        "output": {"directory": "unused", "fields_every": 3, "statistics": STATISTICS, "progress": "none"},
    }


def _twin() -> dict:
    """The same model in the solver's numbers, each worked out here from its physical form."""
    doc = _physical()
    del doc["scaling"]
    doc["mesh"] = {"cells": [8, 8]}
    doc["physics"] = {"Ra": RHO * ALPHA * DT * G * L**3 / (ETA * KAPPA), "approximation": "tala", "reference": {
        "Di": ALPHA * G * L / CP, "surface_temperature": T_REF / DT, "potential_temperature": (1600.0 - T_REF) / DT,
        "profile": {"depth": [0.0, 660e3 / L, 1.0], "thermal_expansivity": [1.0, 2.0 / 3.0, 1.0 / 3.0],
                    "heat_capacity": [1.0, 1.0, 1.04]}}}
    doc["phase_transitions"] = {"p660": {
        "depth": 660e3 / L, "width": 100e3 / L, "temperature": (1900.0 - T_REF) / DT,
        "clapeyron": -2.5e6 * DT / (RHO * G * L), "Rb": 0.08 * RHO * G * L**3 / (ETA * KAPPA),
        "entropy_change": -2.5e6 * 0.08 / (RHO * CP)}}
    doc["boundary"]["temperature"] = {"bottom": {"dirichlet": 1.0}, "top": {"dirichlet": 0.0}}
    doc["time"] = {"end": 1e5 * MYR * KAPPA / L**2, "max_steps": 6}
    return doc


def _write(doc: dict, folder: Path, name: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def _numbers(node, prefix=""):
    if isinstance(node, dict):
        return {k: v for key, value in node.items() for k, v in _numbers(value, f"{prefix}{key}.").items()}
    if isinstance(node, list):
        return {k: v for i, value in enumerate(node) for k, v in _numbers(value, f"{prefix}{i}.").items()}
    return {prefix[:-1]: node} if isinstance(node, float) else {}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The physical model and its twin, each run in a subprocess on one rank."""
    folder = tmp_path_factory.mktemp("reference")
    out = {}
    for name, doc in (("physical", _physical()), ("twin", _twin())):
        proc = run_cli(["run", str(_write(doc, folder, name)), "--output", str(folder / name)])
        assert proc.returncode == 0, proc.stderr
        out[name] = folder / name
    return out


def test_physical_units_give_the_nondimensional_twin(tmp_path, runs):
    physical, twin = (load_config(_write(doc, tmp_path, name)) for name, doc in (("p", _physical()), ("t", _twin())))
    ours, theirs = (_numbers({k: c[k] for k in ("physics", "phase_transitions")}) for c in (physical, twin))
    assert ours.keys() == theirs.keys() and len(ours) > 15
    for key, value in theirs.items():
        assert ours[key] == pytest.approx(value, rel=1e-12, abs=1e-15), key
    a, b = rows(runs["physical"]), rows(runs["twin"])
    assert len(a) == len(b) == 7
    for x, y in zip(a, b):
        for key in x:
            if key != "wall_time":
                assert float(x[key]) == pytest.approx(float(y[key]), rel=1e-9, abs=1e-12), (key, x["step"])


def test_adiabat_outputs_in_kelvin(runs):
    """The fields as ParaView reads them (VTK's XdmfReader): T_ad of the reference state at each
    vertex, T - T_ad beside the temperature; the statistic's means in K, T_mean - T_ad mean."""
    folder = runs["physical"]
    units = json.loads((folder / "fields_units.json").read_text())["fields"]
    assert (units["adiabatic_temperature"], units["nonadiabatic_temperature"]) == ("K", "K")
    physics = load_config(folder / "config.yaml")["physics"]["reference"]
    reference = ReferenceState(**{**physics, "profile": ReferenceProfile(
        **{k: tuple(v) for k, v in physics["profile"].items()})})
    pv = import_pyvista()  # not `import pyvista` after DOLFINx: see import_pyvista
    reader = pv.get_reader(str(folder / "fields.xdmf"))
    reader.set_active_time_value(reader.time_values[-1])
    grid = reader.read()
    depth_km = 2890.0 - grid.points[:, 1]
    expected = T_REF + DT * reference.adiabat_at(depth_km / 2890.0)
    assert np.allclose(grid.point_data["adiabatic_temperature"], expected, rtol=1e-6, atol=0.0)
    assert expected.max() > 1600.0 * 1.2 and expected.min() == pytest.approx(1600.0, rel=1e-9)
    assert np.allclose(grid.point_data["nonadiabatic_temperature"],
                       grid.point_data["temperature"] - grid.point_data["adiabatic_temperature"], atol=1e-6 * DT)
    last = rows(folder)[-1]
    with open(folder / "statistics_physical.csv") as f:
        header = f.readline().strip().split(",")
        values = dict(zip(header, map(float, f.read().strip().splitlines()[-1].split(","))))
    assert values["T_nonadiabatic_mean [K]"] == pytest.approx(values["T_mean [K]"] - values["T_adiabatic_mean [K]"],
                                                              rel=1e-12)
    assert values["T_nonadiabatic_mean [K]"] == pytest.approx(DT * float(last["T_nonadiabatic_mean"]), rel=1e-12)


@pytest.mark.parametrize("change, key", [
    ({"Di": 0.5}, "physics.reference.Di': 0.5 given, but the scaling gives Di = 0.6936"),
    ({"surface_temperature": 0.2}, "physics.reference.surface_temperature'"),
    ({"profile": {"depth": ["0 km", "1 km"], "thermal_expansivity": ["3e-5 K", "3e-5 1/K"]}},
     "physics.reference.profile.thermal_expansivity': '3e-5 K' is not of 1 / [temperature]"),
    ({"profile": {"depth": ["0 km", "1 km", "2 km"], "heat_capacity": [1.0, 1.1]}},
     "physics.reference.profile': the reference profile has 3 depth(s) but 2 heat capacity value(s)"),
    ({"profile": {"depth": ["1000 km", "660 km"], "heat_capacity": [1.0, 1.1]}},
     "physics.reference.profile': the reference profile's depths must increase"),
])
def test_bad_reference_is_refused(tmp_path, change, key):
    doc = _physical()
    doc["physics"]["reference"].update(change)
    with pytest.raises(ConfigError, match=f"config key '{key}".replace("[", r"\[").replace("(", r"\(")
                       .replace(")", r"\)")):
        load_config(_write(doc, tmp_path, "bad"))


def test_check_refuses_in_the_users_terms(tmp_path):
    """``check``: exit 2, one line, naming the key and the value as written."""
    doc = _physical()
    doc["physics"] = {"approximation": "boussinesq", "reference": {"profile": {"depth": ["0 km", "660 km"],
                                                                              "heat_capacity": [1.0, 1.1]}}}
    doc["phase_transitions"] = {}
    line = error_line(run_cli(["check", str(_write(doc, tmp_path, "bad"))]), 2, "physics.reference.profile")
    assert "only with physics.approximation eba or tala or ala" in line


def _king(extra: list[str]) -> list[str]:
    return ["mesh.cells=[8,8]", "time.max_steps=10", "output.progress=none", "output.fields_every=0",
            "output.checkpoint.every_steps=2", *extra]


@pytest.mark.parametrize("case, ranks", [("tala", 1), ("ala", 2), ("physical", 2)])
def test_killed_run_resumes_bit_for_bit(tmp_path, case, ranks):
    """Killed (SIGKILL) after a few steps and resumed: the statistics of an uninterrupted run to the
    last digit (TALA and ALA of King et al.; the physical TALA model with its 660's latent heat)."""
    if case == "physical":
        config = _write(_physical(), tmp_path, "physical")
        extra = ["time.max_steps=10", "output.fields_every=0", "output.checkpoint.every_steps=2"]
    else:
        config = CONFIGS / "king_tala.yaml"
        extra = _king([f"physics.approximation={case}", "physics.reference.Di=1.0",
                       "output.statistics=[time,velocity,nusselt,temperature,heating,adiabat]"])
    reference = tmp_path / "reference"
    proc = run_cli(["run", str(config), "--output", str(reference), *sets(extra)], ranks)
    assert proc.returncode == 0, proc.stderr
    killed = tmp_path / "killed"
    kill_and_resume(config, killed, ranks, extra, after_rows=5)
    assert_same_statistics(reference, killed)
    assert len(rows(reference)) == 11


def test_one_two_three_ranks_agree(tmp_path):
    """The physical model on 1, 2 and 3 ranks: every statistic (global sums and extremes) equal to
    the direct solver's round-off, grown over the steps (seen: 1e-9 in nusselt_bottom on 3 ranks)."""
    if MPI.COMM_WORLD.size > 1:
        pytest.skip("starts its own runs")
    config = _write(_physical(), tmp_path, "physical")
    folders = run_on_ranks(config, {n: tmp_path / f"ranks{n}" for n in (1, 2, 3)}, ["time.max_steps=4"])
    one = rows(folders[1])
    assert float(one[-1]["vrms"]) > 0.0 and float(one[-1]["heating_W"]) != 0.0
    for n in (2, 3):
        for x, y in zip(one, rows(folders[n]), strict=True):
            for key in x:
                if key != "wall_time":
                    assert float(y[key]) == pytest.approx(float(x[key]), rel=1e-7, abs=1e-12), (n, key, x["step"])
