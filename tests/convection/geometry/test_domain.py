"""convection/geometry: the domain objects answer every geometry question from the mesh section."""

import math

import numpy as np
import pytest

from convection.config.loader import expression_constants, load_config
from convection.config.loader import config_domain as domain_from_config
from convection.geometry import DOMAINS, Annulus, BoxDomain, Sector, ShellDomain, SphericalShell
from convection.geometry.gravity import RadialGravity, VerticalGravity
from convection.geometry.probes import MAX_PROBES, boundary_probes, domain_probes
from convection.schema import ConfigError
from fembase.manifold import ShellManifold


def _config(mesh, **sections):
    return load_config(None, document={"mesh": mesh, "physics": {"Ra": 1.0}, "time": {"end": 1.0},
                                       "output": {"directory": "unused"}, **sections})


def test_registry_names_every_geometry():
    assert sorted(DOMAINS) == ["annulus", "box", "sector", "spherical_shell"]
    assert all(cls.description for cls in DOMAINS.values())
    with pytest.raises(ValueError, match="unknown geometry 'torus'"):
        DOMAINS.lookup("torus")


def test_box_domain():
    config = _config({"cells": [4, 2], "upper": [2.0, 1.0]})
    domain = domain_from_config(config)
    assert isinstance(domain, BoxDomain) and domain.name == "box"
    assert domain.boundaries == ("left", "right", "bottom", "top")
    assert (domain.top, domain.bottom, domain.gdim) == ("top", "bottom", 2)
    assert domain.gravity == VerticalGravity(top=1.0)
    assert domain.estimated_cells() == 16.0  # 4 x 2 squares, two triangles each
    assert domain.manifold() is None and domain.confinement(None) is None and not domain.curved
    assert np.array_equal(domain.up(np.array([[0.3, 0.4], [1.0, 1.0]])), [[0.0, 1.0], [0.0, 1.0]])
    assert domain.expression_constants() == {}
    assert [domain.normal_axis(s) for s in domain.boundaries] == [0, 0, 1, 1]
    assert domain.opposite("top") == ("bottom", "top") and domain.opposite("left") == ("left", "right")
    assert not domain.has_rotations(set(domain.boundaries))


@pytest.mark.parametrize("geometry, gdim, cls", [("annulus", 2, Annulus), ("spherical_shell", 3, SphericalShell)])
def test_shell_domain(geometry, gdim, cls):
    config = _config({"geometry": geometry, "radii": [1.0, 2.0], "resolution": 0.25})
    domain = domain_from_config(config)
    assert isinstance(domain, cls) and isinstance(domain, ShellDomain) and domain.name == geometry
    assert domain.boundaries == ("inner", "outer") and (domain.top, domain.bottom) == ("outer", "inner")
    assert domain.gravity == RadialGravity(2.0) and domain.gdim == gdim and domain.curved
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
    assert [domain.normal_axis(s) for s in domain.boundaries] == [None, None]
    assert domain.has_rotations({"inner", "outer"}) and not domain.has_rotations({"outer"})


def test_sector_domain():
    config = _config({"geometry": "sector", "radii": [1.0, 2.0], "angles": [30.0, 120.0], "resolution": 0.25},
                     boundary={"velocity": {"west": "no_slip"}, "temperature": {"inner": {"dirichlet": 1.0}}})
    domain = domain_from_config(config)
    assert isinstance(domain, Sector) and domain.boundaries == ("inner", "outer", "west", "east")
    assert config["boundary"]["velocity"] == {"inner": "free_slip", "outer": "free_slip", "west": "no_slip",
                                              "east": "free_slip"}
    assert domain.spec.span == pytest.approx(math.pi / 2) and domain.gravity == RadialGravity(2.0)
    assert domain.estimated_cells() == pytest.approx(0.25 * math.pi * 3.0 / (math.sqrt(3.0) / 4.0 * 0.0625))
    assert not domain.has_rotations(set(domain.boundaries)) and not domain.refinable
    # the probes: a polar grid over the sector, its sides the ends of the angle axis
    points = domain_probes(domain)
    r, phi = np.hypot(points[0], points[1]), np.degrees(np.arctan2(points[1], points[0]))
    assert r.min() == pytest.approx(1.0) and r.max() == pytest.approx(2.0)
    assert phi.min() == pytest.approx(30.0) and phi.max() == pytest.approx(120.0)
    west = boundary_probes(domain, "west")
    assert np.allclose(np.degrees(np.arctan2(west[1], west[0])), 30.0)
    assert domain_probes(domain).shape[1] <= MAX_PROBES


@pytest.mark.parametrize("mesh, extra, needle", [
    ({"geometry": "annulus", "resolution": 0.3, "cells": [4, 4]}, {},
     "'mesh.cells': not a key of mesh.geometry annulus"),
    ({"cells": [4, 4], "radii": [1.0, 2.0]}, {}, "'mesh.radii': not a key of mesh.geometry box"),
    ({"cells": [4, 4], "radii": [1.22, 2.22], "resolution": None}, {}, None),
    ({"geometry": "sector", "resolution": 0.3, "angles": [0.0, 200.0]}, {}, "'mesh.angles'"),
    ({"geometry": "sector", "resolution": 0.3}, {"adaptivity": {"enabled": True}},
     "'adaptivity.enabled': runs on mesh.geometry sector do not adapt"),
    ({"geometry": "annulus", "resolution": 0.3}, {"boundary": {"velocity": {"west": "no_slip"}}},
     "'boundary.velocity.west': not a boundary of mesh.geometry annulus"),
    ({"cells": [4, 4]}, {"boundary": {"temperature": {"inner": "insulating"}}},
     "'boundary.temperature.inner': not a boundary of mesh.geometry box"),
])
def test_keys_of_another_geometry_are_refused(mesh, extra, needle):
    """Given another value than its default, a key of another geometry is an error (it would be
    ignored); at its default (a resolved config written by a run holds them all) it is not."""
    if needle is None:
        _config(mesh, **extra)
        return
    with pytest.raises(ConfigError, match=needle):
        _config(mesh, **extra)
