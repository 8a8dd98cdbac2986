"""convection/geometry/domain.py: the domain object answers box-or-shell queries from the mesh section."""

import math

import numpy as np
import pytest

from convection.config.loader import expression_constants, load_config
from convection.geometry.domain import BoxDomain, ShellDomain, domain_from_config, is_shell_geometry
from fembase.manifold import ShellManifold


def _config(mesh):
    return load_config(None, document={"mesh": mesh, "physics": {"Ra": 1.0}, "time": {"end": 1.0},
                                       "output": {"directory": "unused"}})


def test_box_domain():
    config = _config({"cells": [4, 2], "upper": [2.0, 1.0]})
    domain = domain_from_config(config)
    assert isinstance(domain, BoxDomain) and not domain.is_shell and not is_shell_geometry(config)
    assert domain.boundaries == ("left", "right", "bottom", "top")
    assert (domain.top, domain.bottom, domain.gravity, domain.gdim) == ("top", "bottom", "vertical", 2)
    assert domain.estimated_cells() == 16.0  # 4 x 2 squares, two triangles each
    assert domain.manifold() is None and domain.confinement(None) is None
    assert np.array_equal(domain.up(np.array([[0.3, 0.4], [1.0, 1.0]])), [[0.0, 1.0], [0.0, 1.0]])
    assert domain.expression_constants() == {}


@pytest.mark.parametrize("geometry, gdim", [("annulus", 2), ("spherical_shell", 3)])
def test_shell_domain(geometry, gdim):
    config = _config({"geometry": geometry, "radii": [1.0, 2.0], "resolution": 0.25})
    domain = domain_from_config(config)
    assert isinstance(domain, ShellDomain) and domain.is_shell and is_shell_geometry(config)
    assert is_shell_geometry(geometry) and not is_shell_geometry("box")
    assert domain.boundaries == ("inner", "outer") and (domain.top, domain.bottom) == ("outer", "inner")
    assert domain.gravity == "radial" and domain.gdim == gdim
    x = np.array([[3.0, 4.0, 0.0][:gdim], [0.0, -2.0, 0.0][:gdim]])
    assert np.allclose(domain.up(x), x / np.linalg.norm(x, axis=1)[:, None], rtol=0, atol=1e-15)
    assert domain.expression_constants() == {"r_inner": 1.0, "r_outer": 2.0}
    assert {k: v for k, v in expression_constants(config).items() if k.startswith("r_")} == \
        domain.expression_constants()
    volume = math.pi * 3.0 if gdim == 2 else 4.0 / 3.0 * math.pi * 7.0
    cell = math.sqrt(3.0) / 4.0 * 0.25**2 if gdim == 2 else 0.25**3 / (6.0 * math.sqrt(2.0))
    assert domain.estimated_cells() == pytest.approx(volume / cell, rel=1e-12)
    manifold = domain.manifold()
    assert isinstance(manifold, ShellManifold) and (manifold.r_inner, manifold.r_outer) == (1.0, 2.0)
    assert manifold.gdim == gdim and not manifold.fitted
