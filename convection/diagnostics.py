"""Global diagnostics: rms velocity, Nusselt number, temperature statistics. All collective.

The statistics of a run are computed by the postprocessors of :mod:`convection.postprocess`.
"""

from __future__ import annotations

from typing import NamedTuple

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI

from convection.boundary import side_axis, side_names
from convection.transport import TransportSolver


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


def nusselt(energy_solver: TransportSolver, u: dolfinx.fem.Function, side: str = "top") -> float:
    """Nusselt number through ``side`` from the consistent boundary flux. Collective.

    With ``a`` the coordinate axis normal to ``side``, ``L`` the box extent along ``a``, ``A`` the
    side's area and ``dT = <T>_{a=min} - <T>_{a=max}`` the difference of the side-averaged
    temperatures of the two sides normal to ``a``::

        Nu = (q_a / A) / (dT / L),    q_a = -int_side grad T . e_a ds,

    where ``int_side grad T . n ds`` is the consistent (weak-form residual) flux of
    :meth:`TransportSolver.boundary_flux`. For the unit-height Blankenbach box with ``T = 0`` on top
    this is ``Nu = -(int_top dT/dz dx) / (int_bottom T dx)``; the conduction profile gives 1.

    Args:
        energy_solver: solver holding the temperature and its last step (for ``dT/dt``).
        u: velocity used in the residual.
        side: side name (default ``"top"``).
    """
    mesh = energy_solver.mesh
    gdim = mesh.geometry.dim
    axis, upper = side_axis(side, gdim)
    flux_out = energy_solver.boundary_flux(u, side)
    q_axis = -flux_out if upper else flux_out

    names = side_names(gdim)
    lower_side, upper_side = [s for s in names if side_axis(s, gdim)[0] == axis]
    if side_axis(lower_side, gdim)[1]:
        lower_side, upper_side = upper_side, lower_side
    area = energy_solver.side_integral(side)[1]
    means = []
    for s in (lower_side, upper_side):
        integral, measure = energy_solver.side_integral(s)
        means.append(integral / measure)
    x = mesh.geometry.x[:, axis]
    lo = mesh.comm.allreduce(float(x.min()) if x.size else np.inf, op=MPI.MIN)
    hi = mesh.comm.allreduce(float(x.max()) if x.size else -np.inf, op=MPI.MAX)
    delta_T = means[0] - means[1]
    if delta_T == 0.0:
        raise ZeroDivisionError(f"No temperature difference across the {side!r} axis")
    return float((q_axis / area) * (hi - lo) / delta_T)
