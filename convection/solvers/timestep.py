"""Advective (CFL) time-step control."""

from __future__ import annotations

import math

import dolfinx
import dolfinx.cpp.mesh
import numpy as np
from mpi4py import MPI

from fembase.dolfinx_compat import cell_dofmap, element_degree, geometry_dofmap


def _cell_min_vertex_distance(mesh: dolfinx.mesh.Mesh, num_cells: int) -> np.ndarray:
    """Shortest distance between two vertices of each of the first ``num_cells`` cells
    (the shortest edge for simplices and boxes), shape=(num_cells,), float64."""
    num_vertices = dolfinx.cpp.mesh.cell_num_entities(mesh.topology.cell_type, 0)
    x_dofs = geometry_dofmap(mesh)
    # Geometry nodes list the cell's vertices first.
    coords = mesh.geometry.x[x_dofs[:num_cells, :num_vertices]]
    h = np.full(num_cells, np.inf)
    for i in range(num_vertices):
        for j in range(i + 1, num_vertices):
            h = np.minimum(h, np.linalg.norm(coords[:, i] - coords[:, j], axis=1))
    return h


def cfl_timestep(u: dolfinx.fem.Function, cfl: float, *, dt_max: float | None = None) -> float:
    """Largest time step satisfying a CFL condition for the velocity ``u``. Collective.

    ``dt = min_K cfl * h_K / (k * |u|_max,K)``, where ``h_K`` is the shortest edge of cell ``K``,
    ``|u|_max,K`` the largest velocity magnitude at the cell's dofs, and ``k`` the polynomial degree
    of ``u``'s space (nodes of a degree-``k`` element are ``h_K / k`` apart, so ``cfl = 1`` means a
    particle moves at most one node spacing per step). The result is capped by ``dt_max``; for a
    zero velocity it is ``dt_max``, or ``math.inf`` without a cap.

    Args:
        u: velocity Function (vector Lagrange space).
        cfl: Courant number (> 0).
        dt_max: optional upper bound.
    """
    if not cfl > 0.0:
        raise ValueError(f"cfl must be positive, got {cfl}")
    V = u.function_space
    mesh = V.mesh
    tdim = mesh.topology.dim
    num_cells = mesh.topology.index_map(tdim).size_local
    bs = V.dofmap.index_map_bs
    cell_dofs = cell_dofmap(V)[:num_cells]
    speed = np.linalg.norm(u.x.array.reshape(-1, bs), axis=1)
    cell_speed = speed[cell_dofs].max(axis=1) if num_cells else np.zeros(0)
    h = _cell_min_vertex_distance(mesh, num_cells)
    degree = element_degree(V)
    moving = cell_speed > 0.0
    local = float(np.min(cfl * h[moving] / (degree * cell_speed[moving]))) if moving.any() else math.inf
    dt = mesh.comm.allreduce(local, op=MPI.MIN)
    if dt_max is not None:
        dt = min(dt, float(dt_max))
    return float(dt)
