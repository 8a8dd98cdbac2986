"""A free surface moves the mesh (arbitrary Lagrangian-Eulerian): the mesh velocity and the motion.

The surface moves with the flow: its height ``h(x)`` above a point of the box's bottom obeys the
kinematic condition ``dh/dt = u_z - u_x dh/dx = (u . n) / (n . e_up)`` (``n`` the outward unit
normal), so the mesh moves along ``e_up`` only and the sides stay where they are. The mesh velocity
``w e_up`` is

- on the free surface, the lumped L2 projection of that rate onto the mesh's nodes,
  ``w_i = (u . n, phi_i)_surface / (n . e_up, phi_i)_surface``;
- inside, harmonic: ``-lap w = 0`` with ``w = 0`` on the bottom and ``dw/dn = 0`` on the other
  boundaries (the sides' nodes slide along them), which spreads the surface's move over the
  column and keeps the cells from folding while the surface moves less than a cell per step.

A step moves every node by ``dt w e_up``. The temperature and the advected material fields are
carried in the moving frame: their nodal values move with the nodes, and they are advected with
``u - w e_up`` (:meth:`FreeSurface.relative`). Particles keep their positions and are found again
in the moved cells (:func:`particles.relocation.moving_mesh.follow_mesh`).

The cells' shape is watched (:func:`cell_quality`: ``4 sqrt(3) |K| / sum(l^2)`` for a triangle,
the same measure scaled to 1 for the regular tetrahedron): 1 for an equilateral cell, 0 for a
flat one. The minimum is reported each step, and a step that turns a cell inside out raises.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Iterator
from collections.abc import Mapping
from typing import Any

import dolfinx
import dolfinx.fem.petsc
import numpy as np
import numpy.typing as npt
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from convection.deform.surface import SurfaceTerms
from convection.geometry.domain import Domain, keep_boundary_facets
from fembase.dolfinx_compat import (
    cell_dofmap, coordinate_map, create_vector, function_space, geometry_dofmap, interpolation_points, petsc_vector,
)
from fembase.geometry import set_reference_coordinates
from fembase.state import State, Stateful

__all__ = ["FreeSurface", "cell_quality"]


def cell_quality(mesh: dolfinx.mesh.Mesh, /) -> npt.NDArray[np.float64]:
    """Shape quality of every owned cell, shape=(num_owned_cells,): ``c_d |K|^(2/d) / mean(l^2)``
    over the edges ``l``, ``c_d`` making it 1 for the regular simplex, signed by the orientation of
    the cell's vertices (which DOLFINx does not make alike: compare with the same cell's sign
    before it moved)."""
    tdim = mesh.topology.dim
    owned = mesh.topology.index_map(tdim).size_local
    x = mesh.geometry.x[:, : mesh.geometry.dim]
    vertices = x[geometry_dofmap(mesh)[:owned, : tdim + 1]]
    edges = vertices[:, 1:, :] - vertices[:, :1, :]
    signed = np.linalg.det(edges) / math.factorial(tdim)
    pairs = [(i, j) for i in range(tdim + 1) for j in range(i + 1, tdim + 1)]
    mean_l2 = np.mean([np.sum((vertices[:, i] - vertices[:, j]) ** 2, axis=1) for i, j in pairs], axis=0)
    regular = math.sqrt(3.0) / 4.0 if tdim == 2 else 1.0 / (6.0 * math.sqrt(2.0))
    return np.sign(signed) * (np.abs(signed) / regular) ** (2.0 / tdim) / mean_l2


def _deform_initially(mesh: dolfinx.mesh.Mesh, domain: Domain, height: Callable[[np.ndarray], np.ndarray], /) -> None:
    """Raise the top to ``height(x)`` above its reference level (``x`` shape=(3, n) -> (n,)),
    every node along ``e_up`` in proportion to its height above the bottom (a column keeps its
    cells' order). Collective (the bottom's depth is the largest over the ranks; every rank moves
    its own and its ghost nodes alike)."""
    x = mesh.geometry.x
    gdim = mesh.geometry.dim
    depth = domain.gravity.depth_at(x[:, :gdim])
    thickness = mesh.comm.allreduce(float(depth.max(initial=0.0)), op=MPI.MAX)  # the bottom's depth
    fraction = 1.0 - depth / thickness
    x[:, :gdim] += (fraction * np.asarray(height(x.T), dtype=np.float64).reshape(-1))[:, None] * domain.up(x)


class FreeSurface(Stateful):
    """The free surfaces of a box and the motion of its mesh (module docstring). Collective.

    Args:
        mesh: The run's mesh (its boundary facets are kept here: call before it moves).
        domain: The domain (a box: ``e_up`` is ``e_z``).
        terms: The free surfaces' terms in Stokes (names, ``B``, ``theta``).

    Attributes:
        W: The scalar Lagrange space of the geometry's degree (one dof per geometry node).
        w: The mesh velocity along ``e_up`` of the last :meth:`velocity`.
        quality_min: The lowest cell quality after the last move (global).
        moves: Steps moved.
    """

    _positions: dolfinx.fem.Function  # the deformed node positions :meth:`to_mesh` carried over to a new mesh

    def __init__(self, mesh: dolfinx.mesh.Mesh, domain: Domain, terms: SurfaceTerms, /) -> None:
        keep_boundary_facets(domain, mesh)
        self.mesh, self.domain, self.terms = mesh, domain, terms
        self._reference_x = mesh.geometry.x.copy()  # the undeformed nodes (what a restore makes again)
        set_reference_coordinates(mesh, self._reference_x)  # keys of random draws, curved cells' sizes
        self.W = function_space(mesh, "Lagrange", coordinate_map(mesh).degree)
        self.w = dolfinx.fem.Function(self.W, name="mesh_velocity")
        self._node = _node_of_dof(self.W)
        fdim = mesh.topology.dim - 1
        self._surface = np.unique(np.concatenate([
            dolfinx.fem.locate_dofs_topological(self.W, fdim, domain.locate_facets(mesh, name))
            for name in terms.names]))
        bottom = dolfinx.fem.locate_dofs_topological(self.W, fdim, domain.locate_facets(mesh, domain.bottom))
        self._w_surface = dolfinx.fem.Function(self.W)
        self._bcs = [dolfinx.fem.dirichletbc(self._w_surface, self._surface),
                     dolfinx.fem.dirichletbc(PETSc.ScalarType(0.0), bottom, self.W)]
        w, phi = ufl.TrialFunction(self.W), ufl.TestFunction(self.W)
        self._laplace = dolfinx.fem.form(ufl.inner(ufl.grad(w), ufl.grad(phi)) * ufl.dx)
        self._zero = dolfinx.fem.form(dolfinx.fem.Constant(mesh, PETSc.ScalarType(0.0)) * phi * ufl.dx)
        self._A = dolfinx.fem.petsc.create_matrix(self._laplace)
        self._b = create_vector(self._zero)
        self._ksp = _laplace_solver(mesh.comm, self._A)
        self._rate_forms: tuple[Any, Any, Any] | None = None
        self._mesh_vector: dolfinx.fem.Function | None = None
        self._orientation = np.sign(cell_quality(mesh))  # DOLFINx does not orient cells alike
        self.quality_min = self._quality()
        self.moves = 0

    def raise_surface(self, height: Callable[[np.ndarray], np.ndarray], /) -> None:
        """Give the surface an initial topography: ``height(x)`` above the reference level
        (``x`` shape=(3, n) -> shape=(n,)), every node raised in proportion to its height above the
        bottom. Before anything else is built on the mesh. Collective."""
        _deform_initially(self.mesh, self.domain, height)
        self.quality_min = self._quality()

    # ------------------------------------------------------------------ the mesh velocity
    def velocity(self, u: dolfinx.fem.Function, /) -> dolfinx.fem.Function:
        """The mesh velocity ``w`` along ``e_up`` for the flow ``u`` (module docstring). Collective."""
        if self._rate_forms is None or self._rate_forms[0] is not u:
            self._rate_forms = (u, *_surface_rate_forms(self.W, self.domain, self.terms.names, u))
        rate = [dolfinx.fem.petsc.assemble_vector(form) for form in self._rate_forms[1:]]
        for vector in rate:
            vector.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        owned = self.W.dofmap.index_map.size_local
        surface = self._surface[self._surface < owned]
        values = self._w_surface.x.array
        values[:] = 0.0
        values[surface] = rate[0].array_r[surface] / rate[1].array_r[surface]
        self._w_surface.x.scatter_forward()
        for vector in rate:
            vector.destroy()
        self._A.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(self._A, self._laplace, bcs=self._bcs)
        self._A.assemble()
        with self._b.localForm() as local:
            local.set(0.0)
        dolfinx.fem.petsc.apply_lifting(self._b, [self._laplace], bcs=[self._bcs])
        self._b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        dolfinx.fem.petsc.set_bc(self._b, self._bcs)
        self._ksp.solve(self._b, petsc_vector(self.w))
        if self._ksp.getConvergedReason() < 0:
            raise RuntimeError(f"mesh velocity solve did not converge (PETSc reason {self._ksp.getConvergedReason()})")
        self.w.x.scatter_forward()
        return self.w

    def relative(self, u: dolfinx.fem.Function, /) -> dolfinx.fem.Function:
        """``u - w e_up`` in ``u``'s space: the velocity relative to the moving mesh (after
        :meth:`velocity`). Collective."""
        V = u.function_space
        if self._mesh_vector is None or self._mesh_vector.function_space is not V:
            self._mesh_vector = dolfinx.fem.Function(V)
            x = ufl.SpatialCoordinate(self.mesh)
            self._mesh_expression = dolfinx.fem.Expression(self.w * self.domain.gravity.up(x), interpolation_points(V))
        self._mesh_vector.interpolate(self._mesh_expression)
        out = dolfinx.fem.Function(V)
        out.x.array[:] = u.x.array - self._mesh_vector.x.array
        return out

    # ------------------------------------------------------------------ the motion
    def move(self, dt: float, /) -> None:
        """Move every node by ``dt w e_up`` (after :meth:`velocity`); raises if a cell turns
        inside out. Collective."""
        x = self.mesh.geometry.x
        gdim = self.mesh.geometry.dim
        up = self.domain.up(x[self._node])
        x[self._node, :gdim] += dt * self.w.x.array[:, None] * up
        self.moves += 1
        self.quality_min = self._quality()
        if self.quality_min <= 0.0:
            raise RuntimeError("the free surface's mesh motion turned a cell inside out "
                               f"(quality {self.quality_min:.3g}): take shorter steps (time.cfl, time.dt_max)")

    def _quality(self) -> float:
        """The lowest cell quality over all ranks, negative if a cell turned inside out."""
        local = (self._orientation * cell_quality(self.mesh)).min(initial=np.inf)
        return float(self.mesh.comm.allreduce(float(local), op=MPI.MIN))

    def heights(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """This rank's owned surface nodes: their positions, shape=(n, gdim), and heights above
        the reference level, shape=(n,)."""
        owned = self.W.dofmap.index_map.size_local
        nodes = self._node[self._surface[self._surface < owned]]
        x = self.mesh.geometry.x[nodes, : self.mesh.geometry.dim]
        return x, 0.0 - self.domain.gravity.depth_at(x)  # 0.0 -: no -0.0 at the reference level

    # ------------------------------------------------------------------ checkpoints
    def state(self) -> State:
        """The nodes' coordinates (a vector field of the geometry's degree) and the counters."""
        return State(fields={"coordinates": self._coordinates(), "reference": self._coordinates(self._reference_x)},
                     scalars={"moves": self.moves, "quality_min": self.quality_min})

    def restore(self, scalars: Mapping[str, Any], /) -> dict[str, dolfinx.fem.Function]:
        """The counters; the coordinates to fill (:meth:`restored` puts them into the mesh)."""
        self.moves, self.quality_min = int(scalars["moves"]), float(scalars["quality_min"])
        self._restored = dolfinx.fem.Function(self._vector_space(), name="coordinates")
        return {"coordinates": self._restored, "reference": dolfinx.fem.Function(self._vector_space())}

    def restored(self) -> None:
        """Put the filled coordinates into the mesh (the factory does it before anything else is
        built on the mesh; :func:`convection.io.checkpoint.restore_state` again, to the same values)."""
        gdim = self.mesh.geometry.dim
        self.mesh.geometry.x[self._node, :gdim] = self._restored.x.array.reshape(-1, gdim)

    @contextlib.contextmanager
    def undeformed(self) -> Iterator[None]:
        """The mesh's nodes at their undeformed positions for the ``with`` block (what a restore
        makes the mesh from, before the checkpoint's coordinates; its fingerprint is taken so)."""
        deformed = self.mesh.geometry.x.copy()
        self.mesh.geometry.x[:] = self._reference_x
        try:
            yield
        finally:
            self.mesh.geometry.x[:] = deformed

    # ------------------------------------------------------------------ a new mesh
    def positions(self) -> dolfinx.fem.Function:
        """The nodes' deformed positions as a vector field of the geometry's degree (what a new
        mesh takes: :meth:`to_mesh`)."""
        return self._coordinates()

    def to_mesh(self, mesh: dolfinx.mesh.Mesh, positions: dolfinx.fem.Function,
                transfer: Callable[[dolfinx.fem.Function, dolfinx.fem.Function], None], /) -> FreeSurface:
        """This free surface on ``mesh``, a mesh made from the undeformed one (an adaptation, a
        repartition), in the reference configuration: ``mesh`` is undeformed and this one's mesh
        too (inside :meth:`undeformed`); the deformed ``positions`` (:meth:`positions`), a field
        over the undeformed mesh, are carried over by ``transfer`` (nodal interpolation) and wait
        for :meth:`displace`. Collective.

        A node of both meshes keeps its position (to the bit, with a snapping transfer); a refined
        cell's new nodes go to the middle of the deformed cell's edges, so the surface keeps its
        shape exactly; the nodes of a coarsened cell keep theirs, so the coarser cells' surface is
        the chord of the finer one's.
        """
        new = FreeSurface(mesh, self.domain, self.terms)
        new._positions = dolfinx.fem.Function(new._vector_space(), name="positions")
        transfer(positions, new._positions)
        new.moves = self.moves
        return new

    def release(self) -> None:
        """Put the mesh's nodes back undeformed for good: the run left this mesh for a new one
        (:meth:`to_mesh`), and it may be the mesh hierarchy's base, which the next adaptation
        refines again."""
        self.mesh.geometry.x[:] = self._reference_x

    def displace(self) -> None:
        """Move the nodes to the positions :meth:`to_mesh` carried over (outside
        :meth:`undeformed`). Collective."""
        gdim = self.mesh.geometry.dim
        self.mesh.geometry.x[self._node, :gdim] = self._positions.x.array.reshape(-1, gdim)
        self.quality_min = self._quality()
        if self.quality_min <= 0.0:
            raise RuntimeError(f"the free surface's deformation folds the new mesh (quality {self.quality_min:.3g})")

    def _vector_space(self) -> dolfinx.fem.FunctionSpace:
        return function_space(self.mesh, "Lagrange", coordinate_map(self.mesh).degree, shape=(self.mesh.geometry.dim,))

    def _coordinates(self, x: npt.NDArray[np.float64] | None = None) -> dolfinx.fem.Function:
        """The nodes' positions (``x``: these instead of the mesh's) as a vector field."""
        f = dolfinx.fem.Function(self._vector_space(), name="coordinates")
        gdim = self.mesh.geometry.dim
        f.x.array[:] = (self.mesh.geometry.x if x is None else x)[self._node, :gdim].reshape(-1)
        return f

    def move_nodes_as_saved(self, reference: npt.NDArray[np.float64], moved: npt.NDArray[np.float64], /) -> None:
        """Move every node to the saved position ``moved[i]`` of the saved node whose undeformed
        position ``reference[i]`` is this node's (both shape=(n, gdim), all the saved nodes): a
        checkpoint written on another number of ranks. Collective.

        Raises:
            ValueError: A node has no saved node at its undeformed position (on every rank).
        """
        gdim = self.mesh.geometry.dim
        x = self.mesh.geometry.x
        from scipy.spatial import cKDTree  # here, not at import: scipy.spatial is 23 MB a process
        distance, index = cKDTree(reference).query(x[:, :gdim])
        scale = max(1.0, float(np.abs(reference).max(initial=0.0)))
        worst = self.mesh.comm.allreduce(float(distance.max(initial=0.0)), op=MPI.MAX)
        if worst > 1e-9 * scale:
            raise ValueError(f"a node of the mesh is {worst:.3g} away from every saved node")
        x[:, :gdim] = moved[index]
        self.quality_min = self._quality()

    def destroy(self) -> None:
        """Free the PETSc objects."""
        for obj in (self._ksp, self._A, self._b):
            obj.destroy()


def _node_of_dof(W: dolfinx.fem.FunctionSpace) -> npt.NDArray[np.int64]:
    """The geometry node of every local dof (owned and ghost) of ``W``, a scalar Lagrange space of
    the geometry's degree, shape=(num_local_dofs,): cell by cell, the space's and the geometry's
    local numbering agree."""
    mesh = W.mesh
    map_ = W.dofmap.index_map
    out = np.full(map_.size_local + map_.num_ghosts, -1, dtype=np.int64)
    dofs = cell_dofmap(W)
    nodes = geometry_dofmap(mesh)
    out[dofs.reshape(-1)] = nodes[: dofs.shape[0]].reshape(-1)
    if np.any(out < 0):
        raise RuntimeError("a dof of the mesh velocity's space has no geometry node")
    return out


def _surface_rate_forms(W: dolfinx.fem.FunctionSpace, domain: Domain, names: tuple[str, ...], u: Any
                        ) -> tuple[Any, Any]:
    """``(u . n, phi)`` and ``(n . e_up, phi)`` on the free surfaces (compiled linear forms)."""
    mesh = W.mesh
    phi = ufl.TestFunction(W)
    n = ufl.FacetNormal(mesh)
    up = domain.gravity.up(ufl.SpatialCoordinate(mesh))
    tags = domain.facet_tags(mesh)
    rate = sum(ufl.dot(u, n) * phi * domain.measure(mesh, name, tags=tags) for name in names)
    slope = sum(ufl.dot(n, up) * phi * domain.measure(mesh, name, tags=tags) for name in names)
    return dolfinx.fem.form(rate), dolfinx.fem.form(slope)


def _laplace_solver(comm: MPI.Comm, A: PETSc.Mat) -> PETSc.KSP:
    """A direct solve (MUMPS) of the mesh velocity's Laplacian: its result does not depend on the
    solver's history (an AMG's eigenvalue estimates draw random vectors, so a resumed run's first
    solve would differ from the uninterrupted run's in round-off), and the scalar P1 problem is
    small beside Stokes."""
    ksp = PETSc.KSP().create(comm)
    ksp.setOperators(A)
    ksp.setType("preonly")
    ksp.getPC().setType("lu")
    ksp.getPC().setFactorSolverType("mumps")
    return ksp
