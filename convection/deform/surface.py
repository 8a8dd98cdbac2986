"""The free surface in the Stokes equations: the load of the topography and its stabilisation.

The momentum equation is written for the departure of the density from the reference ``rho0``
(:mod:`convection.physics.approximation`), with the pressure ``p`` the departure from the
reference's hydrostatic pressure ``rho0 g depth``. A free surface has no traction in the total
stress; in ``p``'s stress it carries the weight of the reference density between the surface's
reference level (``depth = 0``: the box's top) and where it is now, at height ``h`` above it::

    (2 eta eps(u) - p I) n = -B h n            on the free surface,

with ``B = rho0 g L^3 / (eta0 kappa)`` nondimensional (``free_surface.buoyancy``; from
``scaling.density`` and ``scaling.gravity`` in a model with units). In the weak form this adds
``-(B h n, v)_surface`` to the right-hand side. The load is evaluated on the deformed mesh (``h`` is
the height of each point of the discrete surface), so it is exact for any amplitude.

Free-surface stabilisation (FSSA; Kaus, Muhlhaus & May 2010, PEPI 181, 12-20, eq. 22): the
surface moves over the coming step ``dt`` with the flow, so the load at the step's end is
anticipated a fraction ``theta`` into it, ``h -> h + theta dt (u . n) / (n . e_up)``; to first order
in the surface's slope this adds to the operator::

    + theta dt B (u . n) (v . e_up)                on the free surface.

Without it (``theta = 0``) steps longer than the relaxation time of the surface's shortest
resolved wavelength make the surface overshoot and oscillate ("drunken sailor"). A mode relaxing
with time ``tau`` is multiplied per step by ``A = (tau - (1 - theta) dt) / (tau + theta dt)``:
``theta = 1`` (the default) gives ``0 < A < 1`` for every ``dt``, no overshoot however long the
step; ``theta = 0.5`` (ASPECT's default) is second order for ``dt << tau`` but ``A -> -1`` for
``dt >> tau``: the surface rings. The stabilisation needs the step it anticipates: the model
solves the flow again when a step is more than twice the one the flow was solved for (the first
step: :meth:`convection.model.model.Model.step`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import dolfinx
import ufl
from petsc4py import PETSc

from convection.geometry.domain import Domain
from convection.schema import ConfigError, param

__all__ = ["FreeSurfaceSettings", "SurfaceTerms", "check_free_surface", "surface_terms"]


@dataclass(frozen=True)
class FreeSurfaceSettings:
    """The ``free_surface`` config section (used where a boundary's velocity condition is
    ``free_surface``)."""

    theta: float = param(1.0, minimum=0.0, maximum=1.0,
                         help="free-surface stabilisation (Kaus et al. 2010): the surface load anticipated theta dt "
                              "into the step; 1: no overshoot at any step, 0.5: second order where dt < the "
                              "relaxation time, 0: none")
    buoyancy: float | None = param(None, minimum=0.0,
                                   help="B = rho0 g L^3 / (eta0 kappa), the weight of the reference density in the "
                                        "surface load (null: from scaling.density and scaling.gravity)")
    initial_topography: str | None = param(None, help="the surface's height above the box's top at t = 0, an "
                                                      "expression in x (and y in 3D)")


@dataclass(frozen=True)
class SurfaceTerms:
    """What the free surface adds to the Stokes forms (module docstring).

    Attributes:
        names: The free-surface boundaries.
        buoyancy: ``B``.
        theta: The stabilisation's ``theta`` (0: none).
    """

    names: tuple[str, ...]
    buoyancy: float
    theta: float

    def rhs(self, mesh: dolfinx.mesh.Mesh, domain: Domain, v: Any, /, *, metadata: dict | None = None) -> Any:
        """``-(B h n, v)`` on the free surfaces (UFL; ``h = -depth``)."""
        x = ufl.SpatialCoordinate(mesh)
        n = ufl.FacetNormal(mesh)
        h = -domain.gravity.depth(x)
        tags = domain.facet_tags(mesh)
        out = None
        for name in self.names:
            term = -self.buoyancy * h * ufl.dot(v, n) * domain.measure(mesh, name, tags=tags, metadata=metadata)
            out = term if out is None else out + term
        return out

    def lhs(self, mesh: dolfinx.mesh.Mesh, domain: Domain, u: Any, v: Any, dt: Any, /, *,
            metadata: dict | None = None) -> Any:
        """``theta dt B (u . n) (v . e_up)`` on the free surfaces (UFL), or None with ``theta = 0``."""
        if self.theta == 0.0:
            return None
        x = ufl.SpatialCoordinate(mesh)
        n = ufl.FacetNormal(mesh)
        up = domain.gravity.up(x)
        tags = domain.facet_tags(mesh)
        out = None
        for name in self.names:
            term = (self.theta * self.buoyancy * dt * ufl.dot(u, n) * ufl.dot(v, up)
                    * domain.measure(mesh, name, tags=tags, metadata=metadata))
            out = term if out is None else out + term
        return out

    @staticmethod
    def step_constant(mesh: dolfinx.mesh.Mesh, /) -> dolfinx.fem.Constant:
        """The coming step ``dt`` of the stabilisation, a Constant the solver sets before each solve."""
        return dolfinx.fem.Constant(mesh, PETSc.ScalarType(0.0))


def surface_terms(names: tuple[str, ...], settings: FreeSurfaceSettings, /) -> SurfaceTerms:
    """The terms of a checked ``free_surface`` section (``buoyancy`` resolved)."""
    if settings.buoyancy is None:
        raise ValueError("free_surface.buoyancy is needed (B = rho0 g L^3 / (eta0 kappa)), or scaling.density and "
                         "scaling.gravity")
    return SurfaceTerms(tuple(names), float(settings.buoyancy), float(settings.theta))




def check_free_surface(settings: FreeSurfaceSettings, names: tuple[str, ...], domain: type[Domain], /, *,
                       multigrid: bool) -> None:
    """The cross-key checks of a free surface (ConfigError naming the key): ``names``, the boundaries
    whose velocity condition is a free surface, are the top of a box or the annulus's outer circle;
    not yet with the multigrid (``multigrid``: ``stokes.solver`` names it); ``buoyancy`` known."""
    if not names:
        if settings != FreeSurfaceSettings():  # set, but for nothing
            raise ConfigError("config key 'free_surface': no boundary is a free surface (boundary.velocity.<side>: "
                              "free_surface)")
        return
    for name in names:
        if name not in domain.free_surfaces:
            raise ConfigError(f"config key 'boundary.velocity.{name}': a free surface is the top of a box or the "
                              f"outer circle of an annulus for now (boundary.velocity.top of a box, "
                              f"boundary.velocity.outer of mesh.geometry annulus)")
    if multigrid:
        raise ConfigError("config key 'stokes.solver': the multigrid is not with a free surface yet (its mesh moves; "
                          "the coarser levels do not follow it)")
    if settings.buoyancy is None:
        raise ConfigError("config key 'free_surface.buoyancy': required with a free surface in a model without units "
                          "(B = rho0 g L^3 / (eta0 kappa), the reference density's weight; in a model with units it "
                          "follows from scaling.density and scaling.gravity)")
