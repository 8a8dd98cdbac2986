"""The domain of a run (ASPECT's GeometryModel): one object, built from the ``mesh`` config
section, that answers "box or shell?" and what follows from it.

A domain knows its boundary names and which are the top and the bottom, the gravity direction,
the constants it adds to expressions, the mesh spec (:mod:`convection.geometry.mesh`), how particles are
kept inside (:meth:`ShellDomain.confinement`), an estimate of its base cell count, and the
*manifold* that places the geometry nodes of refined cells (:class:`fembase.manifold.ShellManifold`
on the annulus and the spherical shell; none on a box, whose refined cells are straight).

=================== ================================== ======================================
query               :class:`BoxDomain`                 :class:`ShellDomain`
=================== ================================== ======================================
``boundaries``      left, right, bottom, top (+        inner, outer
                    front, back in 3D)
``top / bottom``    top / bottom                       outer / inner
``gravity``         ``"vertical"`` (``-e_z``)          ``"radial"`` (``-x/|x|``)
``manifold()``      None                               ShellManifold (annulus, spherical shell)
=================== ================================== ======================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Union

import numpy as np
import numpy.typing as npt

import dolfinx.mesh

from convection.geometry.boundary import SHELL_BOUNDARIES, side_names
from convection.geometry.mesh import BoxSpec, ShellSpec, mesh_spec_from_config, shell_confinement
from fembase.manifold import ShellManifold

__all__ = ["SHELL_GEOMETRIES", "BoxDomain", "Domain", "ShellDomain", "domain_from_config", "is_shell_geometry"]

SHELL_GEOMETRIES: dict[str, int] = {"annulus": 2, "spherical_shell": 3}
"""The shell geometries (``mesh.geometry`` name -> dimension)."""


def is_shell_geometry(config_or_geometry: dict[str, Any] | str, /) -> bool:
    """Whether a config (or its ``mesh.geometry`` name) is an annulus or spherical shell."""
    if isinstance(config_or_geometry, str):
        return config_or_geometry in SHELL_GEOMETRIES
    return config_or_geometry["mesh"].get("geometry", "box") in SHELL_GEOMETRIES


@dataclass(frozen=True)
class BoxDomain:
    """An axis-aligned box (:class:`convection.geometry.mesh.BoxSpec`)."""

    spec: BoxSpec

    is_shell = False
    top = "top"
    bottom = "bottom"
    gravity = "vertical"

    @property
    def gdim(self) -> int:
        return self.spec.gdim

    @property
    def boundaries(self) -> tuple[str, ...]:
        return side_names(self.gdim)

    @property
    def up(self) -> Callable[[npt.NDArray[np.float64]], npt.NDArray[np.float64]]:
        """Unit up vector at points x (shape=(n, gdim)): ``e_z``."""
        def up(x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
            out = np.zeros((x.shape[0], self.gdim))
            out[:, -1] = 1.0
            return out
        return up

    def expression_constants(self) -> dict[str, float]:
        return {}

    def estimated_cells(self) -> float:
        """Cells of the base mesh."""
        return float(math.prod(self.spec.cells)) * (math.factorial(self.gdim) if self.spec.cell_type == "simplex"
                                                    else 1)

    def manifold(self) -> None:
        """Refined box cells stay straight: no manifold."""
        return None

    def confinement(self, mesh: dolfinx.mesh.Mesh, /) -> None:
        """Particles in a box need no confinement (the walls are straight)."""
        return None


@dataclass(frozen=True)
class ShellDomain:
    """An annulus or spherical shell (:class:`convection.geometry.mesh.ShellSpec`)."""

    spec: ShellSpec

    is_shell = True
    top = "outer"
    bottom = "inner"
    gravity = "radial"
    boundaries = SHELL_BOUNDARIES

    @property
    def gdim(self) -> int:
        return self.spec.gdim

    @property
    def up(self) -> Callable[[npt.NDArray[np.float64]], npt.NDArray[np.float64]]:
        """Unit up vector at points x (shape=(n, gdim)): ``x/|x|``."""
        def up(x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
            x = np.asarray(x, dtype=np.float64)[:, : self.gdim]
            return x / np.linalg.norm(x, axis=1)[:, None]
        return up

    def expression_constants(self) -> dict[str, float]:
        return {"r_inner": self.spec.inner_radius, "r_outer": self.spec.outer_radius}

    def estimated_cells(self) -> float:
        """Shell volume over the volume of an equilateral simplex of edge ``resolution``."""
        h = self.spec.resolution
        cell = math.sqrt(3.0) / 4.0 * h * h if self.gdim == 2 else h**3 / (6.0 * math.sqrt(2.0))
        return self.spec.volume / cell

    def manifold(self) -> ShellManifold:
        """Where refined cells' geometry nodes go: a new (unfitted) :class:`ShellManifold`."""
        return ShellManifold(self.spec.inner_radius, self.spec.outer_radius, self.gdim)

    def confinement(self, mesh: dolfinx.mesh.Mesh, /) -> Callable[[npt.NDArray[np.float64]], None]:
        """Moves particles outside the shell back in (:func:`convection.geometry.mesh.shell_confinement`;
        collective)."""
        return shell_confinement(mesh, self.spec)


Domain = Union[BoxDomain, ShellDomain]


def domain_from_config(config: dict[str, Any], /) -> Domain:
    """The domain of a resolved config's ``mesh`` section."""
    spec = mesh_spec_from_config(config["mesh"])
    return ShellDomain(spec) if isinstance(spec, ShellSpec) else BoxDomain(spec)
