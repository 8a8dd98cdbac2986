"""Null spaces of the Stokes operator and how the solver deals with them.

- The **constant pressure** solves the homogeneous problem when every boundary fixes the normal
  velocity: the domain's :meth:`~convection.geometry.domain.Domain.pressure_pin` removes it for a
  direct solver (one pressure dof set to zero, exact because the system is consistent),
  :func:`constant_pressure_null_space` hands it to a Krylov solver, and :class:`PressureMean`
  normalises the pressure to ``int p dx = 0`` after every solve.
- Under the anelastic liquid approximation (:mod:`convection.physics.compressible`) the pressure's
  buoyancy ``-c p e_up`` turns the constant into a mode ``(u_0, p_0)`` with ``p_0 ~ exp((cp / cv)
  rho_r)`` and a small ``u_0`` (the discretisation's): :class:`PressureMode` finds it exactly, one
  solve with the pinned operator, and shifts the solution along it to ``int p dx = 0``, so that
  neither the velocity nor the pressure depends on which dof was pinned (on the partition).
- **Rigid rotations** about the origin solve the homogeneous problem when both shell boundaries
  are free slip; they are only nearly in the discrete null space (the Nitsche penalty pins them
  weakly), so they are not given to PETSc: :class:`RigidRotations` removes the solution's L2
  projection onto them after every solve.
- The **rigid-body modes** (:func:`rigid_body_modes`) are the near-null space of the velocity
  block that smoothed-aggregation AMG needs.
"""

from __future__ import annotations

from typing import Any

import dolfinx
import dolfinx.fem
import dolfinx.fem.petsc
import dolfinx.la
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from fembase.dolfinx_compat import orthonormalize

__all__ = ["PressureMean", "PressureMode", "RigidRotations", "constant_pressure_null_space", "pressure_normaliser",
           "rigid_body_modes"]


def constant_pressure_null_space(template: PETSc.Vec, num_owned_velocity: int, /) -> PETSc.NullSpace:
    """The normalised constant-pressure vector of a block (velocity, pressure) system as a PETSc
    null space; ``template`` has the system's layout, its first ``num_owned_velocity`` owned
    entries are velocity. Collective."""
    vector = template.duplicate()
    vector.set(0.0)
    vector.array[num_owned_velocity:] = 1.0
    vector.normalize()
    return PETSc.NullSpace().create(vectors=[vector], comm=template.getComm())


class PressureMean:
    """Shift a pressure Function to zero mean, ``int p dx = 0``.

    Args:
        p: The pressure Function.
    """

    def __init__(self, p: dolfinx.fem.Function, /) -> None:
        self.p = p
        mesh = p.function_space.mesh
        one = dolfinx.fem.Constant(mesh, PETSc.ScalarType(1.0))
        self.volume = mesh.comm.allreduce(
            dolfinx.fem.assemble_scalar(dolfinx.fem.form(one * ufl.dx(domain=mesh))), op=MPI.SUM)
        self._integral = dolfinx.fem.form(p * ufl.dx)

    def normalise(self) -> None:
        """Subtract the mean. Collective."""
        comm = self.p.function_space.mesh.comm
        mean = comm.allreduce(dolfinx.fem.assemble_scalar(self._integral), op=MPI.SUM) / self.volume
        self.p.x.array[:] -= mean


class PressureMode:
    """The null vector ``x_0 = (u_0, p_0)`` of a direct solve's operator ``K`` whose pressure is
    pinned (:meth:`~convection.geometry.domain.Domain.pressure_pin`), and the shift of the solution
    along it to ``int p dx = 0``.

    The pin zeroes its dof's row and column of ``K`` (unit diagonal), so ``x_0`` with ``p_0 = 1`` at
    the pin solves ``K_pin x_0 = e_pin - k_pin`` (``k_pin``: the pin's column of ``K``, its
    velocity rows, the strong conditions' rows zero): every row of ``K`` but the pin's then holds
    ``K x_0 = 0``, and the pin's continuity row is minus the sum of the others (the constant
    pressure test function is ``K``'s left null vector). Boussinesq and TALA: ``x_0 = (0, 1)``
    (the :class:`PressureMean`); ALA: ``p_0 > 0`` varies with depth and ``u_0 != 0``.

    Args:
        system: The linear system (:class:`~convection.solvers.stokes.linear.StokesLinearSystem`,
            pinned): its solution Functions ``u``, ``p``, KSP, vectors and the pin.
        column: ``p -> `` the momentum equation's pressure term as a linear form in the velocity
            test function (:meth:`~convection.solvers.stokes.forms.StokesDiscretisation.pressure_column`).
    """

    def __init__(self, system: Any, column: Any, /) -> None:
        self.system = system
        self.u0 = dolfinx.fem.Function(system.u.function_space)
        self.p0 = dolfinx.fem.Function(system.p.function_space)
        self._pin = dolfinx.fem.Function(system.p.function_space)
        pinned = system.bcs[-1].dof_indices()[0]
        self._pin.x.array[pinned] = 1.0
        self._column = column(self._pin)
        self._mean = PressureMean(system.p)
        self._mean0 = dolfinx.fem.form(self.p0 * ufl.dx)
        self._state: int | None = None  # the operator's PETSc state at the last update

    def update(self) -> None:
        """Solve for ``x_0`` with the operator as factorised now. Collective."""
        system = self.system
        n_u = system.V.dofmap.index_map.size_local * system.V.dofmap.index_map_bs
        n_p = system.Q.dofmap.index_map.size_local
        k = dolfinx.fem.petsc.assemble_vector(self._column)
        k.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        column = k.array_r[:n_u].copy()
        k.destroy()
        for bc in system.bcs[:-1]:
            dofs = bc.dof_indices()[0]
            column[dofs[dofs < n_u]] = 0.0
        b0 = system.b.duplicate()
        b0.set(0.0)
        b0.array[:n_u] = -column
        pinned = system.bcs[-1].dof_indices()[0]
        b0.array[n_u + pinned[pinned < n_p]] = 1.0
        x0 = b0.duplicate()
        system.ksp.solve(b0, x0)
        self.u0.x.array[:n_u] = x0.array_r[:n_u]
        self.p0.x.array[:n_p] = x0.array_r[n_u:n_u + n_p]
        self.u0.x.scatter_forward()
        self.p0.x.scatter_forward()
        b0.destroy()
        x0.destroy()

    def normalise(self) -> None:
        """``x -= (mean p / mean p_0) x_0`` with ``x_0`` of the operator now (:meth:`update` when the
        operator changed: its PETSc state). Collective."""
        state = self.system.A.stateGet()
        if state != self._state:
            self.update()
            self._state = state
        comm = self.p0.function_space.mesh.comm
        mean, mean0 = (comm.allreduce(dolfinx.fem.assemble_scalar(f), op=MPI.SUM)
                       for f in (self._mean._integral, self._mean0))
        shift = mean / mean0
        self.system.u.x.array[:] -= shift * self.u0.x.array
        self.system.p.x.array[:] -= shift * self.p0.x.array


def pressure_normaliser(system: Any, discretisation: Any, /) -> PressureMean | PressureMode | None:
    """What fixes the pressure after a solve of the linear system ``system`` (module docstring):
    None without a pressure null space, a :class:`PressureMode` with the ALA's pressure buoyancy
    (``discretisation``'s approximation; a direct solver only), else a :class:`PressureMean`.

    Raises:
        ValueError: the ALA with an iterative solver (its null space is not the constant pressure)."""
    if not system.pressure_null_space:
        return None
    if not discretisation.approximation.formulation.pressure_buoyancy:
        return PressureMean(system.p)
    if system.iterative:
        raise ValueError("the anelastic liquid approximation (its pressure buoyancy) needs the direct Stokes solver")
    return PressureMode(system, discretisation.pressure_column)


class RigidRotations:
    """The rigid rotations about the origin in a vector space ``V`` (exact: they are linear):
    ``(-y, x)`` in 2D; ``e_i x x`` for i = x, y, z in 3D.

    Args:
        V: The velocity space.
    """

    def __init__(self, V: dolfinx.fem.FunctionSpace, /) -> None:
        self.V = V
        self._rotations: list[dolfinx.fem.Function] = []
        self._moment_forms: dict[int, list] = {}
        self._gram: np.ndarray | None = None

    @property
    def rotations(self) -> list[dolfinx.fem.Function]:
        """One Function per rotation (built on first use)."""
        if not self._rotations:
            if self.V.mesh.geometry.dim == 2:
                fields = [lambda x: np.stack([-x[1], x[0]])]
            else:
                zero = lambda x: np.zeros(x.shape[1])  # noqa: E731
                fields = [lambda x: np.stack([zero(x), -x[2], x[1]]), lambda x: np.stack([x[2], zero(x), -x[0]]),
                          lambda x: np.stack([-x[1], x[0], zero(x)])]
            for field in fields:
                rotation = dolfinx.fem.Function(self.V)
                rotation.interpolate(field)
                self._rotations.append(rotation)
        return self._rotations

    def mesh_moved(self) -> None:
        """The mesh's nodes moved: the rotations and their Gram matrix are made again at the next
        use (from the nodes' new positions; a resumed run makes them from the same positions)."""
        self._rotations, self._moment_forms, self._gram = [], {}, None

    def remove(self, u: dolfinx.fem.Function, /) -> None:
        """Subtract the L2 projection of ``u`` (in ``V``) onto the rotations. Collective."""
        rotations = self.rotations
        comm = self.V.mesh.comm
        if self._gram is None:
            local = np.array([[dolfinx.fem.assemble_scalar(dolfinx.fem.form(ufl.inner(a, b) * ufl.dx))
                               for b in rotations] for a in rotations])
            self._gram = np.empty_like(local)
            comm.Allreduce(local, self._gram, op=MPI.SUM)
        forms = self._moment_forms.get(id(u))
        if forms is None:
            forms = self._moment_forms[id(u)] = [dolfinx.fem.form(ufl.inner(u, a) * ufl.dx) for a in rotations]
        local = np.array([dolfinx.fem.assemble_scalar(f) for f in forms])
        moments = np.empty_like(local)
        comm.Allreduce(local, moments, op=MPI.SUM)
        for coefficient, rotation in zip(np.linalg.solve(self._gram, moments), rotations):
            u.x.array[:] -= coefficient * rotation.x.array


def rigid_body_modes(V: dolfinx.fem.FunctionSpace) -> PETSc.NullSpace:
    """The rigid-body modes of the vector space ``V`` as an orthonormal PETSc near-null space.

    Three modes in 2D (two translations, one rotation), six in 3D (three of each), built from the
    coordinates of ``V``'s owned nodes. The vectors have ``V``'s owned layout (block size gdim),
    the layout of the velocity block of the Stokes operator. Collective.
    """
    gdim = V.mesh.geometry.dim
    index_map, bs = V.dofmap.index_map, V.dofmap.index_map_bs
    n_nodes = index_map.size_local
    x = V.tabulate_dof_coordinates()[:n_nodes, :gdim]
    comm = V.mesh.comm
    centre = comm.allreduce(x.sum(axis=0), op=MPI.SUM) / index_map.size_global
    x = x - centre  # rotations about the centre are better conditioned (the same centre on all ranks)
    vectors = [PETSc.Vec().createMPI((n_nodes * bs, PETSc.DECIDE), bsize=bs, comm=comm)
               for _ in range(3 if gdim == 2 else 6)]
    values = [v.getArray() for v in vectors]
    for axis in range(gdim):
        values[axis][axis::bs] = 1.0
    if gdim == 2:
        values[2][0::bs], values[2][1::bs] = -x[:, 1], x[:, 0]
    else:
        for k, (i, j) in enumerate(((0, 1), (1, 2), (2, 0))):  # rotation in the (i, j) plane
            values[3 + k][i::bs], values[3 + k][j::bs] = -x[:, j], x[:, i]
    for v in vectors:
        v.assemble()
    orthonormalize(vectors)
    return PETSc.NullSpace().create(vectors=vectors, comm=comm)
