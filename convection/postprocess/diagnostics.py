"""Global diagnostics: rms velocity, Nusselt number, temperature statistics. All collective.

The statistics of a run are computed by the postprocessors of :mod:`convection.postprocess.postprocessors`.
"""

from __future__ import annotations

from typing import NamedTuple

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI

from convection.geometry.domain import Domain
from convection.solvers.transport import TransportSolver
from fembase.dolfinx_compat import cell_dofmap

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


SUPPORT = 1
"""The tag of the cells :func:`on_support` integrates over."""


def on_support(form: ufl.Form, w: dolfinx.fem.Function, /) -> ufl.Form:
    """``form`` with its cell integrals over the owned cells where ``w`` has a nonzero dof only
    (every other cell adds an exact zero when each term has ``w`` or its derivative as a factor:
    the value is the same to the last digit, for a fraction of the cells). Collective.

    The boundary flux's test function is nonzero on one side's dofs: at 32^3 its residual over
    the whole mesh cost 0.2 s a call, the layer of cells along the side 1/32 of that."""
    V = w.function_space
    mesh = V.mesh
    tdim = mesh.topology.dim
    owned = mesh.topology.index_map(tdim).size_local
    dofs = cell_dofmap(V)[:owned]
    values = w.x.array.reshape(-1, V.dofmap.index_map_bs)
    cells = np.flatnonzero((values[dofs] != 0.0).any(axis=(1, 2))).astype(np.int32)
    tags = dolfinx.mesh.meshtags(mesh, tdim, cells, np.full(cells.size, SUPPORT, dtype=np.int32))
    integrals = [integral.reconstruct(subdomain_id=SUPPORT, subdomain_data=tags)
                 if integral.integral_type() == "cell" and integral.subdomain_id() == "everywhere" else integral
                 for integral in form.integrals()]
    return ufl.Form(integrals)


def _domain_of(solver: TransportSolver, domain: Domain | None, /) -> Domain:
    """``domain``, or the solver's own when it is None."""
    out = solver.domain if domain is None else domain
    assert out is not None, "the solver has no domain: pass one"
    return out


def boundary_flux(solver: TransportSolver, u: dolfinx.fem.Function, side: str, domain: Domain | None = None, /
                  ) -> float:
    """Consistent boundary flux ``int_side grad T . n ds`` (``n`` the outward normal) through the
    boundary ``side`` of ``domain`` (default: the solver's). Collective.

    Computed as the residual ``F(T; w)`` of the solver's last step
    (:meth:`TransportSolver.last_step_residual`, with ``u`` as velocity; zero time derivative
    before the first step), tested with ``w`` = 1 on the side's dofs and 0 elsewhere. For a
    Dirichlet side this is the flux conjugate to the discrete solution, exact for fields the
    space represents (e.g. the conduction profile). The form is compiled once per solver.
    """
    domain = _domain_of(solver, domain)
    key = ("flux", id(u), side)
    if key not in solver.forms or solver.forms[key][1] is not u:
        w = dolfinx.fem.Function(solver.V)
        w.x.array[domain.locate_dofs(solver.V, side)] = 1.0
        residual = on_support(solver.last_step_residual(u, w), w)
        solver.forms[key] = (dolfinx.fem.form(residual), u, w)
    form = solver.forms[key][0]
    return float(solver.mesh.comm.allreduce(dolfinx.fem.assemble_scalar(form), op=MPI.SUM))


def side_integral(solver: TransportSolver, side: str, domain: Domain | None = None, /) -> tuple[float, float]:
    """``(int_side T ds, int_side 1 ds)`` over the whole mesh for the solver's field. Collective."""
    domain = _domain_of(solver, domain)
    key = ("side", side)
    if key not in solver.forms:
        mesh = solver.mesh
        ds = domain.measure(mesh, side)
        one = dolfinx.fem.Constant(mesh, np.float64(1.0))
        solver.forms[key] = (dolfinx.fem.form(solver.T * ds), dolfinx.fem.form(one * ds))
    values = np.array([dolfinx.fem.assemble_scalar(f) for f in solver.forms[key]])
    total = np.empty_like(values)
    solver.mesh.comm.Allreduce(values, total, op=MPI.SUM)
    return float(total[0]), float(total[1])


def nusselt(energy_solver: TransportSolver, u: dolfinx.fem.Function, side: str, domain: Domain | None = None, /
            ) -> float:
    """Nusselt number through the boundary ``side`` of ``domain`` (default: the solver's) from the
    consistent boundary flux. Collective.

    With ``(lower, upper)`` the pair of boundaries across which the domain measures the heat flow
    (:meth:`~convection.geometry.domain.Domain.opposite`: bottom and top, inner and outer, ...),
    the heat flow from ``lower`` to ``upper`` through ``side``, ``Q = -int_side grad T . n ds`` on
    the upper boundary and ``+int_side grad T . n ds`` on the lower one (the consistent flux of
    :func:`boundary_flux`), and ``dT = <T>_lower - <T>_upper`` the difference of the boundary-
    averaged temperatures, the domain divides ``Q`` by the conductive heat flow of ``dT``
    (:meth:`~convection.geometry.domain.Domain.nusselt`):

    - a box: ``Nu = (Q / A) / (dT / L)`` with ``A`` the side's area and ``L`` the box extent
      across (for the unit-height Blankenbach box with ``T = 0`` on top
      ``Nu = -(int_top dT/dz dx) / (int_bottom T dx)``);
    - a shell: ``Nu = Q / Q_cond``, ``Q_cond = 2 pi dT / ln(r_o / r_i)`` (annulus, per unit length)
      or ``4 pi r_i r_o dT / (r_o - r_i)`` (spherical shell);
    - a sector: ``Q_cond = (phi_east - phi_west) dT / ln(r_o / r_i)``.

    The conduction profile gives 1.
    """
    domain = _domain_of(energy_solver, domain)
    lower, upper = domain.opposite(side)
    flux_out = boundary_flux(energy_solver, u, side, domain)
    heat_flow = -flux_out if side == upper else flux_out
    area = side_integral(energy_solver, side, domain)[1]
    means = []
    for name in (lower, upper):
        integral, measure = side_integral(energy_solver, name, domain)
        means.append(integral / measure)
    delta_T = means[0] - means[1]
    if delta_T == 0.0:
        raise ZeroDivisionError(f"No temperature difference between {lower!r} and {upper!r}")
    return domain.nusselt(energy_solver.mesh, side, heat_flow, delta_T, area)
