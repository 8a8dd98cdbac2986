"""Annulus/spherical-shell configs: keys, defaults, refusals, expressions in r/phi/theta, and a short
annulus run whose conduction Nusselt numbers are 1 on both surfaces."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from convection.config.loader import ConfigError, config_gdim, expression_constants, load_config
from convection.expressions import Expression

pytest.importorskip("gmsh")

CONDUCTION = "log(r / r_outer) / log(r_inner / r_outer)"


def _document(**sections):
    document = {
        "mesh": {"geometry": "annulus", "radii": [1.22, 2.22], "resolution": 0.2},
        "physics": {"Ra": 0.0},
        "time": {"end": 1.0, "max_steps": 1, "dt_max": 0.01},
        "output": {"directory": "unused", "progress": "none", "fields_every": 0},
    }
    for key, value in sections.items():
        document.setdefault(key, {}).update(value)
    return document


def test_shell_defaults_and_names():
    config = load_config(None, document=_document())
    assert config_gdim(config) == 2
    assert config["boundary"]["velocity"] == {"inner": "free_slip", "outer": "free_slip"}
    assert config["boundary"]["temperature"] == {"inner": "insulating", "outer": "insulating"}
    assert expression_constants(config)["r_outer"] == 2.22
    shell3 = load_config(None, document=_document(mesh={"geometry": "spherical_shell"}))
    assert config_gdim(shell3) == 3
    box = load_config(None, document={"mesh": {"cells": [4, 4]}, "physics": {"Ra": 1.0}, "time": {"end": 1.0},
                                      "output": {"directory": "unused"}})
    assert "inner" not in box["boundary"]["velocity"] and box["boundary"]["velocity"]["top"] == "free_slip"


@pytest.mark.parametrize("sections, key", [
    ({"boundary": {"velocity": {"top": "no_slip"}}}, "boundary.velocity.top"),
    ({"mesh": {"cells": [4, 4]}}, "mesh.cells"),
    ({"mesh": {"resolution": None}}, "mesh.resolution"),
    ({"mesh": {"radii": [2.0, 1.0]}}, "mesh.radii"),
    ({"mesh": {"geometry": "spherical_shell", "geometry_degree": 1}, "adaptivity": {"enabled": True}},
     "adaptivity.enabled"),
    ({"mesh": {"geometry": "spherical_shell", "geometry_degree": 1}, "balance": {"strategy": "every"}},
     "balance.strategy"),
    ({"mesh": {"geometry_degree": 1}, "adaptivity": {"enabled": True}}, "adaptivity.enabled"),
    ({"boundary": {"velocity": {"outer": {"kind": "prescribed", "value": ["-y"]}}}}, "boundary.velocity.outer.value"),
    ({"boundary": {"velocity": {"outer": {"kind": "prescribed", "value": ["-q", "x"]}}}}, "boundary.velocity.outer"),
    ({"particles": {"enabled": True}}, "particles.generator.name"),  # the default random_uniform: curved cells
    ({"particles": {"enabled": True, "generator": {"name": "random_density", "num_particles": 10,
                                                   "density": "r < 1.5"}}},
     "particles.generator.name"),
])
def test_shell_config_errors(sections, key):
    with pytest.raises(ConfigError, match=f"'{key}'"):
        load_config(None, document=_document(**sections))


@pytest.mark.parametrize("geometry", ["annulus", "spherical_shell"])
def test_shell_adaptivity_and_balance_allowed(geometry):
    config = load_config(None, document=_document(mesh={"geometry": geometry, "resolution": 0.5},
                                                  adaptivity={"enabled": True}, balance={"strategy": "every"}))
    assert config["adaptivity"]["enabled"] and config["balance"]["strategy"] == "every"


def test_shell_generators_for_curved_cells():
    """metropolis_hastings samples curved cells; random_uniform does on straight-sided shells."""
    curved = load_config(None, document=_document(particles={"generator": {"name": "metropolis_hastings",
                                                                             "num_particles": 10}}))
    assert curved["particles"]["generator"]["name"] == "metropolis_hastings"
    straight = load_config(None, document=_document(mesh={"geometry_degree": 1}, particles={"enabled": True}))
    assert straight["particles"]["generator"]["name"] == "random_uniform"


def test_shell_names_refused_on_a_box():
    document = {"mesh": {"cells": [4, 4]}, "physics": {"Ra": 1.0}, "time": {"end": 1.0},
                "output": {"directory": "unused"}, "boundary": {"temperature": {"inner": {"dirichlet": 1.0}}}}
    with pytest.raises(ConfigError, match="'boundary.temperature.inner'"):
        load_config(None, document=document)


def test_spherical_coordinates_in_expressions():
    x = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]]).T
    assert np.allclose(Expression("r", gdim=3)(x), [1.0, 2.0, 3.0])
    assert np.allclose(Expression("theta", gdim=3)(x), [np.pi / 2, np.pi / 2, 0.0])
    assert np.allclose(Expression("phi", gdim=3)(x), [0.0, np.pi / 2, 0.0])
    assert np.allclose(Expression("r * cos(phi)", gdim=2)(x), [1.0, 0.0, 0.0])


def test_conduction_nusselt_is_one_on_both_surfaces(tmp_path):
    """T = ln(r / r_o) / ln(r_i / r_o) between T = 1 inside and 0 outside, Ra = 0: both surfaces'
    Nusselt numbers are 1 (to the discretisation error of the P2 temperature), vrms 0."""
    from convection.app.factory import run_config
    from convection.io.pictures import read_statistics

    out = MPI.COMM_WORLD.bcast(str(tmp_path) if MPI.COMM_WORLD.rank == 0 else None)
    config = load_config(None, document=_document(
        boundary={"temperature": {"inner": {"dirichlet": 1.0}, "outer": {"dirichlet": 0.0}}},
        initial={"temperature": CONDUCTION}, output={"directory": out}))
    run_config(config)
    stats = read_statistics(tmp_path / "statistics.csv")
    assert np.allclose(stats["nusselt"], 1.0, atol=2e-3) and np.allclose(stats["nusselt_bottom"], 1.0, atol=2e-3)
    assert np.all(stats["vrms"] < 1e-12)
