"""Box meshes for convection runs and per-cell size measures used by adaptivity."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh
import ufl

__all__ = ["BoxSpec", "cell_values", "cell_volumes", "create_box_mesh"]


@dataclass(frozen=True)
class BoxSpec:
    """An axis-aligned box split into ``cells`` per direction.

    Attributes:
        cells: Cells per direction, length 2 or 3.
        lower: Lower corner (same length).
        upper: Upper corner (same length).
        cell_type: "simplex" (triangles/tetrahedra) or "box" (quadrilaterals/hexahedra).
        diagonal: Diagonal direction for 2D simplices.
    """

    cells: tuple[int, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    cell_type: str = "simplex"
    diagonal: str = "right"

    @classmethod
    def from_config(cls, mesh_config: dict) -> "BoxSpec":
        cells = tuple(int(n) for n in mesh_config["cells"])
        gdim = len(cells)
        lower = tuple(mesh_config["lower"] or [0.0] * gdim)
        upper = tuple(mesh_config["upper"] or [1.0] * gdim)
        return cls(cells, lower, upper, mesh_config["cell_type"], mesh_config["diagonal"])

    @property
    def gdim(self) -> int:
        return len(self.cells)

    @property
    def volume(self) -> float:
        return float(np.prod(np.subtract(self.upper, self.lower)))


def create_box_mesh(comm: MPI.Comm, spec: BoxSpec, /) -> dolfinx.mesh.Mesh:
    """Create the (coarse, base) mesh described by ``spec`` (collective)."""
    ghost_mode = dolfinx.mesh.GhostMode.shared_facet
    if spec.gdim == 2:
        cell_type = dolfinx.mesh.CellType.triangle if spec.cell_type == "simplex" else dolfinx.mesh.CellType.quadrilateral
        diagonal = getattr(dolfinx.mesh.DiagonalType, spec.diagonal.replace("/", "_"))
        return dolfinx.mesh.create_rectangle(
            comm, [np.array(spec.lower), np.array(spec.upper)], list(spec.cells), cell_type,
            ghost_mode=ghost_mode, diagonal=diagonal,
        )
    cell_type = dolfinx.mesh.CellType.tetrahedron if spec.cell_type == "simplex" else dolfinx.mesh.CellType.hexahedron
    return dolfinx.mesh.create_box(
        comm, [np.array(spec.lower), np.array(spec.upper)], list(spec.cells), cell_type, ghost_mode=ghost_mode
    )


def cell_values(mesh: dolfinx.mesh.Mesh, integrand: ufl.core.expr.Expr, /) -> npt.NDArray[np.float64]:
    """Integral of ``integrand`` over every local cell (owned and ghost), shape=(num_local_cells,)."""
    V0 = dolfinx.fem.FunctionSpace(mesh, ("DG", 0))
    w = ufl.TestFunction(V0)
    vec = dolfinx.fem.assemble_vector(dolfinx.fem.form(integrand * w * ufl.dx))
    vec.scatter_forward()
    return vec.array[V0.dofmap.list.array.reshape(-1)].copy()


def cell_volumes(mesh: dolfinx.mesh.Mesh, /) -> npt.NDArray[np.float64]:
    """Volume (area in 2D) of every local cell (owned and ghost), shape=(num_local_cells,)."""
    return cell_values(mesh, ufl.as_ufl(1.0))
