"""Entities of simplex meshes: the reference order of a cell's edges and which entities lie on the
domain's boundary (also where a ghost cell's boundary entity is owned by another rank)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

import dolfinx.fem
import dolfinx.mesh

from fembase import dolfinx_compat as compat

__all__ = ["EDGES", "boundary_entities"]

EDGES: dict[int, tuple[tuple[int, int], ...]] = {
    2: ((1, 2), (0, 2), (0, 1)),
    3: ((2, 3), (1, 3), (1, 2), (0, 3), (0, 2), (0, 1)),
}
"""The local vertices of each edge of a triangle / tetrahedron in the reference (basix) order, the
order of the edge nodes of a second-order Lagrange cell."""


def boundary_entities(mesh: dolfinx.mesh.Mesh, dim: int, /) -> npt.NDArray[np.bool_]:
    """Whether each local (owned and ghost) entity of dimension ``dim`` (edges, or faces in 3D)
    lies on the domain's boundary, shape=(num_local_entities,) (collective).

    ``locate_entities_boundary`` sees the boundary facets a rank owns: a ghost cell's boundary face
    owned by another rank, and its edges, are missed. Each rank marks what it found in a Lagrange
    function of degree ``dim + 1`` (one degree of freedom inside each entity of dimension ``dim``),
    the marks are summed onto the owners and sent back to every rank holding the entity.
    """
    tdim = mesh.topology.dim
    mesh.topology.create_entities(dim)
    mesh.topology.create_connectivity(tdim, dim)
    mesh.topology.create_connectivity(tdim - 1, tdim)
    imap = mesh.topology.index_map(dim)
    num_entities = imap.size_local + imap.num_ghosts
    V = compat.function_space(mesh, "Lagrange", dim + 1)
    cells = compat.cell_dofmap(V)
    per_cell = len(EDGES[tdim]) if dim == 1 else tdim + 1
    c2e = np.asarray(mesh.topology.connectivity(tdim, dim).array, dtype=np.int64).reshape(-1, per_cell)
    # Local dof layout of P(dim+1): the vertices' dofs, then dim (edges: 1 each; P3 on a tetrahedron
    # has 2 per edge, then 1 per face), entities in the reference order of c2e.
    first = tdim + 1 if dim == 1 else (tdim + 1) + 2 * len(EDGES[tdim])
    entity_dof = np.full(num_entities, -1, dtype=np.int64)
    local = cells[:, first:first + per_cell]
    entity_dof[c2e[: cells.shape[0]].reshape(-1)] = local.reshape(-1)
    if not np.array_equal(entity_dof[c2e[: cells.shape[0]]], local):
        raise RuntimeError(f"the P{dim + 1} dofs are not one per entity of dimension {dim} in the reference order")
    marker = dolfinx.fem.Function(V)
    marker.x.array[:] = 0.0
    found = dolfinx.mesh.locate_entities_boundary(mesh, dim, lambda x: np.full(x.shape[1], True))
    marker.x.array[entity_dof[found]] = 1.0
    marker.x.scatter_reverse(compat.SCATTER_ADD)
    marker.x.scatter_forward()
    return marker.x.array[entity_dof] > 0.5
