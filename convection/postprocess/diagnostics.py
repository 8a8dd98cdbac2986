"""Global diagnostics: rms velocity, Nusselt number, temperature statistics. All collective.

The statistics of a run are computed by the postprocessors of :mod:`convection.postprocess.postprocessors`.
"""

from __future__ import annotations

from typing import NamedTuple

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI

from convection.geometry.boundary import (
    SHELL_BOUNDARIES, boundary_measure, locate_side_dofs, shell_radii, side_axis, side_facet_tags, side_names, side_tag,
)
from convection.solvers.transport import TransportSolver


class TemperatureStats(NamedTuple):
    """Global temperature statistics.

    Attributes:
        mean: volume average ``int T dx / |Omega|``.
        min: minimum nodal value.
        max: maximum nodal value.
    """

    mean: float
    min: float
    max: float


def _integrate(mesh: dolfinx.mesh.Mesh, expr) -> float:
    """Global integral of a rank-0 UFL form. Collective."""
    local = dolfinx.fem.assemble_scalar(dolfinx.fem.form(expr))
    return float(mesh.comm.allreduce(local, op=MPI.SUM))


def _volume(mesh: dolfinx.mesh.Mesh) -> float:
    one = dolfinx.fem.Constant(mesh, np.float64(1.0))
    return _integrate(mesh, one * ufl.dx(domain=mesh))


def vrms(u: dolfinx.fem.Function) -> float:
    """Root-mean-square velocity ``sqrt(int |u|^2 dx / |Omega|)``. Collective."""
    mesh = u.function_space.mesh
    return float(np.sqrt(_integrate(mesh, ufl.inner(u, u) * ufl.dx) / _volume(mesh)))


def temperature_stats(T: dolfinx.fem.Function) -> TemperatureStats:
    """Volume-mean and nodal min / max of ``T`` over all ranks. Collective."""
    mesh = T.function_space.mesh
    mean = _integrate(mesh, T * ufl.dx) / _volume(mesh)
    n_owned = T.function_space.dofmap.index_map.size_local * T.function_space.dofmap.index_map_bs
    owned = T.x.array[:n_owned]
    local_min = float(owned.min()) if owned.size else np.inf
    local_max = float(owned.max()) if owned.size else -np.inf
    return TemperatureStats(
        mean,
        float(mesh.comm.allreduce(local_min, op=MPI.MIN)),
        float(mesh.comm.allreduce(local_max, op=MPI.MAX)),
    )


def boundary_flux(solver: TransportSolver, u: dolfinx.fem.Function, side: str) -> float:
    """Consistent boundary flux ``int_side grad T . n ds`` (``n`` the outward normal). Collective.

    Computed as the residual ``F(T; w)`` of the solver's last step
    (:meth:`TransportSolver.last_step_residual`, with ``u`` as velocity; zero time derivative
    before the first step), tested with ``w`` = 1 on the side's dofs and 0 elsewhere. For a
    Dirichlet side this is the flux conjugate to the discrete solution, exact for fields the
    space represents (e.g. the conduction profile). The form is compiled once per solver.
    """
    key = ("flux", id(u), side)
    if key not in solver.forms or solver.forms[key][1] is not u:
        w = dolfinx.fem.Function(solver.V)
        w.x.array[locate_side_dofs(solver.V, side)] = 1.0
        solver.forms[key] = (dolfinx.fem.form(solver.last_step_residual(u, w)), u, w)
    form = solver.forms[key][0]
    return float(solver.mesh.comm.allreduce(dolfinx.fem.assemble_scalar(form), op=MPI.SUM))


def side_integral(solver: TransportSolver, side: str) -> tuple[float, float]:
    """``(int_side T ds, int_side 1 ds)`` over the whole mesh for the solver's field. Collective."""
    key = ("side", side)
    if key not in solver.forms:
        mesh = solver.mesh
        if side in SHELL_BOUNDARIES:
            ds = boundary_measure(mesh, side)
        else:
            ds = ufl.Measure("ds", domain=mesh, subdomain_data=side_facet_tags(mesh))(side_tag(side, mesh.geometry.dim))
        one = dolfinx.fem.Constant(mesh, np.float64(1.0))
        solver.forms[key] = (dolfinx.fem.form(solver.T * ds), dolfinx.fem.form(one * ds))
    values = np.array([dolfinx.fem.assemble_scalar(f) for f in solver.forms[key]])
    total = np.empty_like(values)
    solver.mesh.comm.Allreduce(values, total, op=MPI.SUM)
    return float(total[0]), float(total[1])


def nusselt(energy_solver: TransportSolver, u: dolfinx.fem.Function, side: str = "top") -> float:
    """Nusselt number through ``side`` from the consistent boundary flux. Collective.

    With ``a`` the coordinate axis normal to ``side``, ``L`` the box extent along ``a``, ``A`` the
    side's area and ``dT = <T>_{a=min} - <T>_{a=max}`` the difference of the side-averaged
    temperatures of the two sides normal to ``a``::

        Nu = (q_a / A) / (dT / L),    q_a = -int_side grad T . e_a ds,

    where ``int_side grad T . n ds`` is the consistent (weak-form residual) flux of
    :func:`boundary_flux`. For the unit-height Blankenbach box with ``T = 0`` on top
    this is ``Nu = -(int_top dT/dz dx) / (int_bottom T dx)``; the conduction profile gives 1.

    Args:
        energy_solver: solver holding the temperature and its last step (for ``dT/dt``).
        u: velocity used in the residual.
        side: side name (default ``"top"``).
    """
    if side in SHELL_BOUNDARIES:
        return shell_nusselt(energy_solver, u, side)
    mesh = energy_solver.mesh
    gdim = mesh.geometry.dim
    axis, upper = side_axis(side, gdim)
    flux_out = boundary_flux(energy_solver, u, side)
    q_axis = -flux_out if upper else flux_out

    names = side_names(gdim)
    lower_side, upper_side = [s for s in names if side_axis(s, gdim)[0] == axis]
    if side_axis(lower_side, gdim)[1]:
        lower_side, upper_side = upper_side, lower_side
    area = side_integral(energy_solver, side)[1]
    means = []
    for s in (lower_side, upper_side):
        integral, measure = side_integral(energy_solver, s)
        means.append(integral / measure)
    x = mesh.geometry.x[:, axis]
    lo = mesh.comm.allreduce(float(x.min()) if x.size else np.inf, op=MPI.MIN)
    hi = mesh.comm.allreduce(float(x.max()) if x.size else -np.inf, op=MPI.MAX)
    delta_T = means[0] - means[1]
    if delta_T == 0.0:
        raise ZeroDivisionError(f"No temperature difference across the {side!r} axis")
    return float((q_axis / area) * (hi - lo) / delta_T)


def conductive_heat_flow(inner_radius: float, outer_radius: float, delta_T: float, gdim: int) -> float:
    """Heat flow ``Q`` through an annulus (per unit length, ``gdim = 2``) or spherical shell by pure
    conduction with temperature difference ``delta_T`` (inner minus outer)::

        2D:  Q = 2 pi delta_T / ln(r_o / r_i),      3D:  Q = 4 pi r_i r_o delta_T / (r_o - r_i).
    """
    ri, ro = inner_radius, outer_radius
    if gdim == 2:
        return float(2.0 * np.pi * delta_T / np.log(ro / ri))
    return float(4.0 * np.pi * ri * ro * delta_T / (ro - ri))


def shell_nusselt(energy_solver: TransportSolver, u: dolfinx.fem.Function, boundary: str = "outer") -> float:
    """Nusselt number through the ``inner`` or ``outer`` surface of an annulus/spherical shell. Collective.

    The heat flow out through the outer surface, ``Q_outer = -int_outer grad T . n ds``, or in
    through the inner one, ``Q_inner = int_inner grad T . n ds`` (``n`` the outward normal; consistent
    fluxes of :func:`boundary_flux`), divided by the conductive heat flow
    (:func:`conductive_heat_flow`) of the difference of the surface-averaged temperatures,
    ``dT = <T>_inner - <T>_outer``. Both are 1 for the conduction profile and equal at steady state
    without internal heating.
    """
    if boundary not in SHELL_BOUNDARIES:
        raise ValueError(f"Unknown shell boundary {boundary!r}; valid names: {list(SHELL_BOUNDARIES)}")
    mesh = energy_solver.mesh
    flux_out = boundary_flux(energy_solver, u, boundary)
    heat_flow = -flux_out if boundary == "outer" else flux_out
    means = []
    for name in SHELL_BOUNDARIES:
        integral, measure = side_integral(energy_solver, name)
        means.append(integral / measure)
    delta_T = means[0] - means[1]
    if delta_T == 0.0:
        raise ZeroDivisionError("No temperature difference between the inner and outer surfaces")
    inner, outer = shell_radii(mesh)
    return float(heat_flow / conductive_heat_flow(inner, outer, delta_T, mesh.geometry.dim))
