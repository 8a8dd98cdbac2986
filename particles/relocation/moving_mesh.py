"""Particles on a mesh whose nodes move (a free surface, ALE): find every particle again.

When the mesh deforms, a particle keeps its physical position ``x`` but its cell and reference
position are those of the old node positions. :func:`follow_mesh` takes the new positions into the
swarm's cell geometry and the migrator's rank boxes, then relocates every particle with the same
compiled path a time step uses (:func:`particles.relocation.between_cells.relocate`: the old cell, its facet
neighbour, its vertex neighbours, then the bounding-box tree) and migrates those that are now in
another rank's cell.

A moving boundary and the particles near it do not move alike: in a time step the particles move
in the flow on the mesh of the step's start, so near a rising surface they leave that mesh (the
surface catches up when the mesh moves after them), and where the surface sinks the moved mesh
can leave a particle just above it (a thinning column; the surface's piecewise-linear shape lags
the flow). The rule here (:func:`pull_in`, where the swarm has ``inward`` directions, e.g. down,
against "up"): a particle found in no local cell after a relocation is looked for along
``inward(x)``: the first point inside the local mesh within one cell size, found by bisection
between its position and a point inside along that line. If that point is on the domain's
boundary (the facet the line enters through is a boundary facet, not the edge of this rank's
owned and ghost cells), the particle lay outside the domain: it is moved there (to round-off,
inside its new cell), keeps its properties and is counted (``pulled_in``). The same rule applies
to the stage positions of an advection step
(:class:`particles.advection.Advector`). The others (found nowhere locally, and not outside the
boundary: they went beyond the ghost cells) go to the migration as always, which drops a particle
no rank has (counted as lost).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh
from petsc4py import PETSc

from fembase.dolfinx_compat import cell_dofmap, function_space, petsc_vector
from fembase.geometry import CellGeometry
from particles.parallel.migration import migrate, migrator_for
from particles.storage.swarm import Swarm
from particles.relocation.between_cells import relocate

__all__ = ["FollowStats", "follow_mesh", "pull_in"]

Inward = Callable[[npt.NDArray[np.float64]], npt.NDArray[np.float64]]
"""``inward(x)``: unit directions into the domain at points shape=(n, gdim) -> shape=(n, gdim)
(:attr:`particles.storage.swarm.Swarm.inward`)."""

_DOUBLINGS = 40  # from 2^-40 of a cell size up to one cell size along the inward line
_BISECTIONS = 60  # halves the bracket below round-off of any coordinate


class FollowStats(NamedTuple):
    """What :func:`follow_mesh` did (global counts; seconds on this rank).

    Attributes:
        pulled_in: Particles that the moved boundary had left outside, moved back inside.
        sent: Particles that changed rank.
        lost: Particles found nowhere (dropped).
        seconds: Time spent (geometry update, relocation, migration).
    """

    pulled_in: int
    sent: int
    lost: int
    seconds: float


def _reach(geom: CellGeometry, cells: npt.NDArray[np.int32]) -> npt.NDArray[np.float64]:
    """Twice the largest distance from a node to the centre of each given cell, shape=(m,)."""
    nodes = geom.coords[geom.nodes[cells]]
    return 2.0 * np.linalg.norm(nodes - geom.centres[cells][:, None, :], axis=2).max(axis=1)


def _exterior_marks(swarm: Swarm) -> npt.NDArray[np.bool_]:
    """Whether each vertex of each local cell lies on the domain's boundary, shape=(num_local_cells,
    num_vertices). Collective on the first call (a rank knows the exterior facets it owns; the
    marks of their vertices are summed over the ranks that share them); kept with the swarm's cell
    geometry (the topology does not move)."""
    geom = swarm.geometry
    marks = getattr(geom, "_exterior_marks", None)
    if marks is None:
        mesh = swarm.mesh
        tdim = mesh.topology.dim
        mesh.topology.create_connectivity(tdim - 1, tdim)
        V = function_space(mesh, "Lagrange", 1)
        flag = dolfinx.fem.Function(V)
        facets = np.asarray(dolfinx.mesh.exterior_facet_indices(mesh.topology), dtype=np.int32)
        flag.x.array[dolfinx.fem.locate_dofs_topological(V, tdim - 1, facets)] = 1.0
        petsc_vector(flag).ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        flag.x.scatter_forward()
        marks = flag.x.array[cell_dofmap(V)[: geom.num_local_cells]] > 0.0
        geom._exterior_marks = marks
    return marks


def _entered_through_boundary(swarm: Swarm, points: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
    """Whether each point, just inside the local mesh where a line from outside entered it, lies
    on the domain's boundary (not on the boundary of this rank's owned + ghost cells): the facet of
    its cell it is on (the smallest barycentric coordinate's) has its vertices on the boundary
    and, in an owned cell, no cell across it. Other cells than affine simplices: a vertex of the
    cell on the boundary."""
    geom = swarm.geometry
    marks = _exterior_marks(swarm)
    located = geom.locate(points)
    cells = located.cells
    ok = cells >= 0
    out = np.zeros(points.shape[0], dtype=bool)
    if not geom.affine:
        out[ok] = marks[cells[ok]].any(axis=1)
        return out
    c = cells[ok]
    barycentric = np.concatenate([1.0 - located.xref[ok].sum(axis=1, keepdims=True), located.xref[ok]], axis=1)
    facet = np.argmin(barycentric, axis=1)
    vertices = marks[c].copy()
    vertices[np.arange(c.shape[0]), facet] = True  # the facet's vertices: all but the opposite one
    owned = c < swarm.num_owned_cells
    out[ok] = vertices.all(axis=1) & (~owned | (geom.facet_neighbours[c, facet] < 0))
    return out


def _inside_along(geom: CellGeometry, x: npt.NDArray[np.float64], direction: npt.NDArray[np.float64],
                  reach: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    """The first points inside the local mesh along ``direction`` from ``x`` (shape=(m, gdim)),
    within ``reach`` (shape=(m,)), and which were found: steps doubling from ``reach 2^-40`` find
    a point inside at most twice as far as the boundary, bisection then the boundary itself (to
    round-off, on its inner side)."""
    inside = x.copy()
    found = np.zeros(x.shape[0], dtype=bool)
    step = reach * 2.0**-_DOUBLINGS
    for _ in range(_DOUBLINGS + 1):
        todo = np.flatnonzero(~found)
        if not todo.size:
            break
        trial = x[todo] + direction[todo] * step[todo, None]
        hit = geom.locate(trial).cells >= 0
        inside[todo[hit]] = trial[hit]
        found[todo[hit]] = True
        step *= 2.0
    rows = np.flatnonzero(found)
    outside = x[rows].copy()
    inner = inside[rows]
    for _ in range(_BISECTIONS):
        middle = 0.5 * (outside + inner)
        hit = geom.locate(middle).cells >= 0
        inner[hit] = middle[hit]
        outside[~hit] = middle[~hit]
    inside[rows] = inner
    return inside, found


def pull_in(swarm: Swarm, old_cells: npt.NDArray[np.int32], /) -> int:
    """Move the particles a relocation found in no local cell that had an owned cell before it
    (``old_cells``, in the swarm's order) and lie outside the domain's boundary along
    ``swarm.inward``, back into the mesh (module docstring); relocate again. Returns how many were
    moved (this rank). Nothing happens without ``swarm.inward``. Collective (every rank calls it
    with the same ``swarm.inward`` set or not): the first call finds the boundary's vertices.

    Call after :func:`particles.relocation.between_cells.relocate` with ``sort=False`` (the relocation here
    hands the swarm new per-cell counts for the next sort)."""
    if swarm.inward is None:
        return 0
    _exterior_marks(swarm)  # collective on the first call
    rows = np.flatnonzero((swarm.cells < 0) & (old_cells >= 0) & (old_cells < swarm.num_owned_cells))
    if not rows.size:
        return 0
    geom = swarm.geometry
    x = np.ascontiguousarray(swarm.x[rows])
    inside, found = _inside_along(geom, x, np.asarray(swarm.inward(x), dtype=np.float64), _reach(geom, old_cells[rows]))
    found[found] = _entered_through_boundary(swarm, inside[found])
    if not found.any():
        return 0
    swarm.x[rows[found]] = inside[found]
    swarm.cells[rows] = old_cells[rows]  # start the walk there again
    relocate(swarm, sort=False)
    return int(np.count_nonzero(found))


def follow_mesh(swarm: Swarm, /) -> FollowStats:
    """Find every particle again after the mesh's nodes moved (collective; module docstring).

    Args:
        swarm: The particles (sorted, in owned cells of the mesh before it moved); afterwards
            sorted and in owned cells of the moved mesh. Particles the moved boundary left
            outside are moved back in along ``swarm.inward`` (:func:`pull_in`); without it they go
            to the migration's fallback (lost if no rank has them).
    """
    t0 = time.perf_counter()
    swarm.mesh_moved()
    migrator = migrator_for(swarm.mesh)
    migrator.moved()
    old_cells = swarm.cells.copy()
    relocate(swarm, sort=False)
    pulled = pull_in(swarm, old_cells)
    stats = migrate(swarm, migrator=migrator)
    pulled = swarm.comm.allreduce(pulled, op=MPI.SUM)
    return FollowStats(pulled, int(stats.global_sent), int(stats.global_lost), time.perf_counter() - t0)
