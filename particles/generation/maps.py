"""Reference-to-physical maps of owned cells, evaluated identically on every partition.

For affine simplices the map is built on the cell's vertices sorted lexicographically by
coordinates, ``Phi(X) = v0 + sum_i X_i (v_i - v0)``, so it does not depend on the local vertex
order DOLFINx chose on a given partition. Other cells (quadrilaterals, hexahedra, curved cells)
use the coordinate element in DOLFINx's node order, which follows the input mesh. All arithmetic
is elementwise with a fixed operation order (no BLAS), so results are bitwise reproducible.
"""

from __future__ import annotations

import basix
import numpy as np
import numpy.typing as npt

import dolfinx.mesh

from fembase.dolfinx_compat import coordinate_map
from fembase.geometry import cell_nodes, geometry_dofmap, is_affine_simplex, pull_back, reference_coordinates

__all__ = ["CellMaps"]


def _lex_order(nodes: npt.NDArray[np.float64]) -> npt.NDArray[np.int64]:
    """The lexicographic order of the nodes of every cell, shape=(m, n, gdim) -> (m, n)."""
    m, n, gdim = nodes.shape
    order = np.tile(np.arange(n), (m, 1))
    for d in reversed(range(gdim)):
        values = np.take_along_axis(nodes[:, :, d], order, axis=1)
        order = np.take_along_axis(order, np.argsort(values, axis=1, kind="stable"), axis=1)
    return order


def _abs_det(jac: list[list[npt.NDArray[np.float64]]], gdim: int, tdim: int) -> npt.NDArray[np.float64]:
    """|det J| (or the area element for gdim > tdim); ``jac[g][t]`` are arrays of shape (p,)."""
    if tdim == 1:
        return np.sqrt(sum(jac[g][0] * jac[g][0] for g in range(gdim)))
    if tdim == 2 and gdim == 2:
        return np.abs(jac[0][0] * jac[1][1] - jac[0][1] * jac[1][0])
    if tdim == 2 and gdim == 3:
        c0 = jac[1][0] * jac[2][1] - jac[2][0] * jac[1][1]
        c1 = jac[2][0] * jac[0][1] - jac[0][0] * jac[2][1]
        c2 = jac[0][0] * jac[1][1] - jac[1][0] * jac[0][1]
        return np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    return np.abs(
        jac[0][0] * (jac[1][1] * jac[2][2] - jac[2][1] * jac[1][2])
        - jac[0][1] * (jac[1][0] * jac[2][2] - jac[2][0] * jac[1][2])
        + jac[0][2] * (jac[1][0] * jac[2][1] - jac[2][0] * jac[1][1])
    )


class CellMaps:
    """Maps of the owned cells of a mesh.

    Attributes:
        mesh: The mesh.
        cells: Owned local cells, shape=(m,), int32 (all owned cells).
        keys: Partition-independent key of each cell (its sorted node coordinates),
            shape=(m, num_nodes * gdim), float64.
        affine: True for affine simplices (canonical vertex order).
        basix_cell: The reference cell.
    """

    def __init__(self, mesh: dolfinx.mesh.Mesh, /) -> None:
        self.mesh = mesh
        self.gdim, self.tdim = mesh.geometry.dim, mesh.topology.dim
        num_owned = mesh.topology.index_map(self.tdim).size_local
        self.cells = np.arange(num_owned, dtype=np.int32)
        nodes = cell_nodes(mesh, self.cells)
        # keyed by the undeformed positions of a moving mesh (the same bits on every partition)
        key_nodes = reference_coordinates(mesh)[geometry_dofmap(mesh)[self.cells]][:, :, : self.gdim]
        order = _lex_order(key_nodes)[:, :, None]
        self.keys = np.take_along_axis(key_nodes, order, axis=1).reshape(num_owned, nodes.shape[1] * self.gdim)
        self.affine = is_affine_simplex(mesh)
        self.basix_cell = getattr(basix.CellType, mesh.topology.cell_name())
        self._nodes = np.take_along_axis(nodes, order, axis=1) if self.affine else nodes
        if not self.affine:
            self._element = basix.create_element(basix.ElementFamily.P, self.basix_cell,
                                                 coordinate_map(mesh).degree, basix.LagrangeVariant.gll_warped)

    @property
    def reference_volume(self) -> float:
        return float(basix.make_quadrature(self.basix_cell, 0)[1].sum())

    def push(self, idx: npt.NDArray[np.int64], xhat: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Physical points of reference points ``xhat`` (p, tdim) in cells ``self.cells[idx]``; (p, gdim)."""
        nodes = self._nodes[idx]
        if self.affine:
            x = nodes[:, 0, :].copy()
            for t in range(self.tdim):
                x += xhat[:, t : t + 1] * (nodes[:, t + 1, :] - nodes[:, 0, :])
            return x
        phi = self._element.tabulate(0, xhat)[0, :, :, 0]
        x = np.zeros((xhat.shape[0], self.gdim))
        for n in range(nodes.shape[1]):
            x += phi[:, n : n + 1] * nodes[:, n, :]
        return x

    def abs_det(self, idx: npt.NDArray[np.int64], xhat: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """|det J| of the map at ``xhat`` in cells ``self.cells[idx]``, shape=(p,)."""
        nodes = self._nodes[idx]
        if self.affine:
            jac = [[nodes[:, t + 1, g] - nodes[:, 0, g] for t in range(self.tdim)] for g in range(self.gdim)]
        else:
            dphi = self._element.tabulate(1, xhat)[1 : 1 + self.tdim, :, :, 0]
            jac = [[sum(dphi[t][:, n] * nodes[:, n, g] for n in range(nodes.shape[1])) for t in range(self.tdim)]
                   for g in range(self.gdim)]
        return _abs_det(jac, self.gdim, self.tdim)

    def pull(self, idx: npt.NDArray[np.int64], x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Inverse of :meth:`push` for affine simplices: reference points (p, tdim) in this class's
        frame of physical points ``x`` (p, gdim) in cells ``self.cells[idx]`` (each cell's map solved
        on its own, so the bits do not depend on the partition; least squares if gdim > tdim)."""
        if not self.affine:
            raise ValueError("CellMaps.pull needs affine simplex cells")
        nodes = self._nodes[np.asarray(idx, dtype=np.int64)]
        jac = np.swapaxes(nodes[:, 1 : self.tdim + 1, :] - nodes[:, :1, :], 1, 2)  # (p, gdim, tdim)
        rhs = np.asarray(x, dtype=np.float64).reshape(-1, self.gdim) - nodes[:, 0, :]
        if rhs.shape[0] == 0:
            return np.empty((0, self.tdim))
        if self.gdim != self.tdim:
            rhs = np.einsum("pgt,pg->pt", jac, rhs)
            jac = np.einsum("pgt,pgs->pts", jac, jac)
        return np.linalg.solve(jac, rhs[:, :, None])[:, :, 0]

    def to_dolfinx_reference(self, idx: npt.NDArray[np.int64], xhat: npt.NDArray[np.float64],
                             x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Reference coordinates in DOLFINx's frame of cell ``self.cells[idx]`` for the swarm."""
        if self.affine:
            return pull_back(self.mesh, self.cells[idx], x)
        return np.asarray(xhat, dtype=np.float64)
