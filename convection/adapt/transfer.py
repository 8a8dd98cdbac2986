"""Carry finite element fields from one mesh to another covering the same domain.

DOLFINx 0.5 has no ``interpolate_nonmatching_meshes``: the new Function is interpolated from a
callable that evaluates the old Function at the new interpolation points. Points are searched in
this rank's part of the old mesh first (a bounding-box tree and pull-back); meshes rebuilt from the same
distributed base mesh without redistribution (see :mod:`convection.adapt.adaptivity`) find every point
locally. Points not found locally are resolved collectively: they are shared with all ranks, each
rank evaluates the ones it holds, and the values are combined.

Points in no cell of the source mesh at all but within :data:`NEAR_REACH` (in reference
coordinates, about that fraction of a cell size) of one take the value of the nearest cell's
polynomial there (extrapolation): a curved boundary approximated by second-order cells lies a
little differently on a coarse and on a refined mesh (:mod:`fembase.manifold`), so some boundary
nodes of the new mesh lie just outside the old one.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from fembase.dolfinx_compat import (bounding_box_tree, cell_dofmap, compute_collisions, interpolate_on_cells,
                                    is_lagrange, value_size)
from fembase.evaluation import Evaluator
from fembase.geometry import Candidates, CellGeometry, Located

__all__ = ["NEAR_REACH", "SNAP", "PointEvaluator", "transfer_function"]

NEAR_REACH = 0.05
"""How far outside every cell (reference coordinates) a point may lie and still be evaluated, by
the nearest cell's polynomial."""


SNAP = 1e-10
"""How close (reference coordinates) to a multiple of ``2^-20`` a snapping :class:`PointEvaluator`
puts a point onto it."""


class PointEvaluator:
    """Evaluate Functions on a fixed mesh at arbitrary points (collective for missing points).

    Points are located by :class:`fembase.geometry.CellGeometry` (bounding-box candidates tested
    by pull-back; among several containing cells the lowest local index) and Lagrange P1/P2
    values come from the particles' compiled evaluation kernel at the reference coordinates
    found (:class:`fembase.evaluation.Evaluator`), so the fields of one element on one target
    mesh share one search.

    Args:
        mesh: The mesh the source Functions live on.
        geometry: Its :class:`CellGeometry`, if one exists already (e.g. the particles' swarm's).
        snap: Put reference coordinates within :data:`SNAP` of a multiple of ``2^-20`` onto it: a
            vertex or an edge's midpoint of the source mesh then has exactly the barycentric
            coordinates 0, 1/2 or 1, whichever cell holds it, so a P1 field's value there is the
            same on any partition (without: the pull-back's round-off depends on the cell found).
    """

    def __init__(self, mesh: dolfinx.mesh.Mesh, /, *, geometry: CellGeometry | None = None, snap: bool = False) -> None:
        self.mesh = mesh
        self.snap = snap
        self.geometry = geometry if geometry is not None else CellGeometry(mesh)
        if self.geometry.mesh is not mesh:
            raise ValueError("the geometry belongs to another mesh")
        self._located: dict[bytes, Located] = {}
        self._evaluators: dict[int, Evaluator] = {}

    def colliding(self, points: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int32]]:
        """All local cells containing each point, as CSR (offsets shape=(n+1,), cells), points shape=(n, 3)."""
        offsets, cells, _ = self.geometry.colliding(points[:, : self.geometry.gdim])
        return offsets, cells

    def locate(self, points: npt.NDArray[np.float64]) -> npt.NDArray[np.int32]:
        """Lowest local cell containing each point (-1 where none), points shape=(n, 3)."""
        return self._locate(points).cells

    def _locate(self, points: npt.NDArray[np.float64],
                candidates: Callable[[], Candidates | None] | None = None) -> Located:
        """Cells and reference coordinates of ``points`` (shape=(n, 3); ``candidates``: makes the
        cells to test first, see :meth:`CellGeometry.locate`, called only if the points are new).

        The answers for the last few point sets are remembered: the fields of one element on one
        target mesh (u, T and its history, ...) ask for the same interpolation points.
        """
        key = hashlib.blake2b(np.ascontiguousarray(points).view(np.uint8).data, digest_size=16).digest() + \
            np.int64(points.shape[0]).tobytes()
        found = self._located.get(key)
        if found is None:
            found = self.geometry.locate(points[:, : self.geometry.gdim],
                                         candidates=None if candidates is None else candidates())
            if self.snap:
                found = Located(found.cells, _snapped(found.xref))
            if len(self._located) >= 4:
                self._located.pop(next(iter(self._located)))
            self._located[key] = found
        return found

    def _values(self, function: dolfinx.fem.Function, found: Located, rows: npt.NDArray[np.int64],
                value_size: int) -> npt.NDArray[np.float64]:
        """Values of ``function`` at the located points ``rows``, shape=(len(rows), value_size)."""
        V = function.function_space
        evaluator = self._evaluators.get(id(V))
        if evaluator is None or evaluator.V is not V:
            evaluator = self._evaluators[id(V)] = Evaluator(V, geometry=self.geometry)
        values = evaluator.values(function, np.ascontiguousarray(found.cells[rows]),
                                  np.ascontiguousarray(found.xref[rows]))
        return values.reshape(-1, value_size)

    def max_over_colliding(self, points: npt.NDArray[np.float64], values: npt.NDArray[np.int32], /, *,
                           default: int = -1, candidates: Candidates | None = None) -> npt.NDArray[np.int32]:
        """Largest value among all cells of the (distributed) mesh that contain each point.

        Collective. Points whose colliding cells are all owned here are answered locally; points
        found nowhere here or touching a ghost cell (a partition boundary, where cells of other
        ranks may touch them too) are shared with every rank, which answers from its owned cells.

        Args:
            points: shape=(n, 3).
            values: One integer per local cell (owned and ghost), shape=(num_local_cells,).
            default: Result for points in no cell.
            candidates: Local cells that hold every cell containing each point they hit (see
                :meth:`CellGeometry.max_over_containing`).

        Returns:
            shape=(n,), int32.
        """
        comm = self.mesh.comm
        num_owned = self.mesh.topology.index_map(self.mesh.topology.dim).size_local
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        result, hit, ghost_hit = self.geometry.max_over_containing(points[:, : self.geometry.gdim], values,
                                                                   default=default, candidates=candidates)
        uncertain = np.flatnonzero(~hit | ghost_hit)
        if comm.allreduce(uncertain.size, op=MPI.SUM) == 0:
            return result
        shared = comm.allgather(points[uncertain])
        gathered = np.concatenate(shared)
        g_offsets, g_cells = self.colliding(gathered)
        lowest = np.iinfo(np.int32).min
        answer = np.full(gathered.shape[0], lowest, dtype=np.int32)
        g_hit = g_offsets[1:] > g_offsets[:-1]
        if np.any(g_hit):
            own_values = np.where(g_cells < num_owned, values[g_cells], lowest).astype(np.int32)
            answer[g_hit] = np.maximum.reduceat(own_values, g_offsets[:-1][g_hit])
        total = np.empty_like(answer)
        comm.Allreduce(answer, total, op=MPI.MAX)
        total[total == lowest] = default
        start = sum(p.shape[0] for p in shared[: comm.rank])
        result[uncertain] = total[start: start + uncertain.size]
        return result

    def _near(self, function: dolfinx.fem.Function, points: npt.NDArray[np.float64], value_size: int
              ) -> npt.NDArray[np.float64]:
        """Values at points (the same on every rank, shape=(m, 3)) that lie in no cell: from the owned
        cell, over all ranks, whose reference cell the point's pull-back misses least, if by at most
        :data:`NEAR_REACH` (collective; raises on every rank otherwise)."""
        comm = self.mesh.comm
        g = self.geometry
        m = points.shape[0]
        miss = np.full(m, np.inf)
        cell = np.full(m, -1, dtype=np.int32)
        xref = np.zeros((m, g.tdim))
        if g.num_owned_cells:
            vertices = g.coords[g.nodes[: g.num_owned_cells, : g.num_vertices]]
            size = float((vertices.max(axis=1) - vertices.min(axis=1)).max())
            tree = bounding_box_tree(self.mesh, g.tdim, np.arange(g.num_owned_cells, dtype=np.int32),
                                     padding=2.0 * NEAR_REACH * size + 1.01 * g.curvature_padding)
            hits = compute_collisions(tree, points)
            offsets = np.asarray(hits.offsets, dtype=np.int64)
            links = np.asarray(hits.array, dtype=np.int32)
            rows = np.repeat(np.arange(m), np.diff(offsets))
            if links.size:
                X = g.pull_back(links, points[rows, : g.gdim])
                if g.simplex:
                    by = np.maximum(np.maximum(-X, 0.0).max(axis=1), X.sum(axis=1) - 1.0)
                else:
                    by = np.maximum(-X, X - 1.0).max(axis=1)
                by = np.maximum(by, 0.0)
                order = np.lexsort((links, by, rows))  # per point: least miss, then lowest cell
                first = order[np.r_[True, rows[order][1:] != rows[order][:-1]]]
                miss[rows[first]], cell[rows[first]], xref[rows[first]] = by[first], links[first], X[first]
        best = np.empty_like(miss)
        comm.Allreduce(miss, best, op=MPI.MIN)
        if np.any(best > NEAR_REACH):
            lost = int(np.count_nonzero(best > NEAR_REACH))
            raise RuntimeError(f"{lost} points lie outside the source mesh; cannot transfer the field")
        mine = np.where(miss == best, comm.rank, comm.size).astype(np.int32)
        chooser = np.empty_like(mine)
        comm.Allreduce(mine, chooser, op=MPI.MIN)
        values = np.zeros((m, value_size))
        chosen = np.flatnonzero(chooser == comm.rank)
        if chosen.size:
            found = Located(cell, xref)
            values[chosen] = self._values(function, found, chosen, value_size)
        total = np.empty_like(values)
        comm.Allreduce(values, total, op=MPI.SUM)
        return total

    def evaluate(self, function: dolfinx.fem.Function, points: npt.NDArray[np.float64], /, *,
                 candidates: Callable[[], Candidates | None] | None = None) -> npt.NDArray[np.float64]:
        """Values of ``function`` at ``points`` (shape=(n, 3)); returns shape=(n, value_size).

        Collective: every rank must call it (with its own, possibly empty, point set).
        ``candidates`` makes the local cells to test first for each point
        (:meth:`CellGeometry.locate`); it is called only when these points were not located before.
        """
        comm = self.mesh.comm
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        value_size = int(np.prod(function.ufl_shape)) if function.ufl_shape else 1
        values = np.zeros((points.shape[0], value_size))
        located = self._locate(points, candidates)
        found = np.flatnonzero(located.cells >= 0)
        if found.size:
            values[found] = self._values(function, located, found, value_size)
        missing = np.flatnonzero(located.cells < 0)
        if comm.allreduce(missing.size, op=MPI.SUM) == 0:
            return values
        # Collective fallback: share the missing points with every rank.
        all_points = comm.allgather(points[missing])
        gathered = np.concatenate(all_points) if all_points else np.empty((0, 3))
        glocated = self._locate(gathered)
        gfound = glocated.cells >= 0
        gvalues = np.zeros((gathered.shape[0], value_size))
        if np.any(gfound):
            gvalues[gfound] = self._values(function, glocated, np.flatnonzero(gfound), value_size)
        # Owner of each value: lowest rank that found it.
        rank_found = np.where(gfound, comm.rank, comm.size).astype(np.int32)
        owner = np.empty_like(rank_found)
        comm.Allreduce(rank_found, owner, op=MPI.MIN)
        gvalues[owner != comm.rank] = 0.0
        total = np.empty_like(gvalues)
        comm.Allreduce(gvalues, total, op=MPI.SUM)
        outside = np.flatnonzero(owner == comm.size)
        if outside.size:
            total[outside] = self._near(function, gathered[outside], value_size)
        start = sum(p.shape[0] for p in all_points[: comm.rank])
        values[missing] = total[start: start + missing.size]
        return values


def _snapped(xref: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """``xref`` with the coordinates within :data:`SNAP` of a multiple of ``2^-20`` put onto it."""
    grid = np.round(xref * 2.0**20) * 2.0**-20
    return np.where(np.abs(xref - grid) < SNAP, grid, xref)


def _node_cells(V: dolfinx.fem.FunctionSpace) -> npt.NDArray[np.int32]:
    """A local cell holding each local (unblocked) dof, shape=(num_local_dofs,): the lowest-numbered
    one, so an owned cell wherever one holds it (cells are written from the last to the first;
    owned cells are numbered before ghosts)."""
    index_map = V.dofmap.index_map
    dofs = cell_dofmap(V)
    cell_of_entry = np.repeat(np.arange(dofs.shape[0], dtype=np.int32), dofs.shape[1])[::-1]
    cells = np.full(index_map.size_local + index_map.num_ghosts, -1, dtype=np.int32)
    cells[dofs.reshape(-1)[::-1]] = cell_of_entry
    return cells


def _nodal(V: dolfinx.fem.FunctionSpace) -> bool:
    """True for (blocked) Lagrange spaces, whose dofs are the values at the dof coordinates."""
    return is_lagrange(V) and value_size(V) == V.dofmap.index_map_bs


def transfer_function(
    source: dolfinx.fem.Function, target: dolfinx.fem.Function, /, *, evaluator: PointEvaluator | None = None,
    candidates: Callable[[npt.NDArray[np.int32]], Candidates | None] | None = None,
) -> None:
    """Interpolate ``source`` (on mesh A) into ``target`` (on mesh B): target = I_B(source).

    Collective. Pass an ``evaluator`` built once for mesh A to share its search tree between fields.
    A Lagrange target takes the source's values at its owned dof coordinates, each node once
    (``Function.interpolate`` would visit a P2 node once per cell around it: three times as many
    points in 2D); other elements go through ``Function.interpolate``.

    ``candidates`` maps the local cell of mesh B holding each point to the cells of mesh A to test
    first (e.g. :meth:`convection.adapt.hierarchy.MeshHierarchy.candidates` for nested meshes); points
    not found among them are searched with the bounding-box tree.
    """
    evaluator = evaluator or PointEvaluator(source.function_space.mesh)
    V = target.function_space
    if _nodal(V):
        n = V.dofmap.index_map.size_local
        nodes = V.tabulate_dof_coordinates()[:n]
        first = None if candidates is None else (lambda: candidates(_node_cells(V)[:n]))
        target.x.array[: n * V.dofmap.index_map_bs] = evaluator.evaluate(source, nodes, candidates=first).reshape(-1)
        target.x.scatter_forward()
        return
    mesh = V.mesh
    tdim = mesh.topology.dim
    owned = np.arange(mesh.topology.index_map(tdim).size_local, dtype=np.int32)

    def values(x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        return evaluator.evaluate(source, x.T).T

    interpolate_on_cells(target, values, owned)
    target.x.scatter_forward()
