"""Meshes of any domain: a gmsh model meshed on rank 0 and distributed, and per-cell measures.

The domains (:mod:`convection.geometry.box`, :mod:`convection.geometry.shell`,
:mod:`convection.geometry.sector`) make their own meshes; the curved ones build a gmsh model and
hand it to :func:`gmsh_mesh`.

DOLFINx 0.5's (Plaza) refinement fails on meshes with second-order geometry ("Data size mismatch
between local and global adjacency lists"), and on straight-sided meshes it puts the new boundary
vertices on the chords, inside the circle. Adaptive (and load-balanced) runs on curved domains
therefore refine the straight-sided gmsh mesh and curve every mesh they use by the domain's
manifold (:mod:`fembase.manifold`, :class:`convection.adapt.hierarchy.MeshHierarchy` with
``manifold=``).
"""

from __future__ import annotations

from pathlib import Path
from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.cpp.mesh
import dolfinx.fem
import dolfinx.mesh
import ufl

from fembase.distribute import create_reproducible_mesh
from fembase.dolfinx_compat import cell_dofmap, coordinate_map, function_space, geometry_dofmap, gmsh_model_to_mesh
from fembase.geometry import reference_coordinates

__all__ = ["cell_diameter", "cell_values", "cell_volumes", "gmsh_mesh", "mesh_uniformly"]


def gmsh_mesh(comm: MPI.Comm, build: Callable[[Any], None], /, *, gdim: int, name: str,
              owners: npt.NDArray[np.int32] | None = None, msh_file: str | Path | None = None) -> dolfinx.mesh.Mesh:
    """Mesh a gmsh model on rank 0 and distribute it (collective) on a reproducible partition
    (:func:`fembase.distribute.create_reproducible_mesh`: the same mesh, numbering and all, in every
    run on the same ranks; ``owners``: a partition to impose, owner rank per cell by input index).

    Needs the ``gmsh`` Python module (Debian: ``python3-gmsh``) on rank 0.

    Args:
        build: ``build(gmsh)`` builds and meshes the model in gmsh's current model (rank 0 only).
        gdim: Geometric dimension.
        name: Name of the gmsh model.
        msh_file: A gmsh ``.msh`` file of this model: read if it exists (instead of meshing),
            written after meshing if not. Different gmsh versions mesh the same shape differently
            (Debian 12's 4.8 and Debian 13's 4.13 give 673 and 675 cells for the annulus at cell
            size 0.2), so comparing two installations on the same mesh needs the file of one of
            them (benchmarks/releases). None: mesh, write nothing.
    """
    started = False
    error = None
    if comm.rank == 0:
        import gmsh

        # gmsh < 4.9 (Debian 12 ships 4.8) cannot tell whether it is initialised: start our own session.
        is_initialized = getattr(gmsh, "isInitialized", lambda: False)
        started = not is_initialized()
        if started:
            gmsh.initialize(readConfigFiles=False)
        gmsh.option.setNumber("General.Terminal", 0)
        if msh_file is not None and Path(msh_file).exists():
            gmsh.open(str(msh_file))
        else:
            gmsh.model.add(name)
            try:
                build(gmsh)
            except ValueError as err:  # raised on every rank below: the others would wait for the mesh
                error = str(err)
            if msh_file is not None and error is None:
                gmsh.write(str(msh_file))
    error = comm.bcast(error, root=0)
    try:
        if error is not None:
            raise ValueError(error)
        return create_reproducible_mesh(comm, lambda c: gmsh_model_to_mesh(gmsh.model, c, 0, gdim=gdim),
                                        owners=owners)
    finally:
        if comm.rank == 0:
            gmsh.model.remove()
            if started:
                gmsh.finalize()


def mesh_uniformly(gmsh: Any, dim: int, resolution: float, degree: int, /, *, untangle: bool,
                   optimize_below: float | None = None) -> None:
    """Mesh gmsh's current model (rank 0) with cells of size ``resolution`` everywhere, of geometry
    ``degree`` (2: curved onto the model's curves and surfaces). ``untangle``: run gmsh's high-order
    optimiser after curving, which moves only cells below its quality threshold (boundary nodes stay
    on the surfaces): curving the boundary faces of coarse tetrahedra can invert them (a negative
    Jacobian where a concave face bends into a thin cell). ``optimize_below``: gmsh's tetrahedron
    optimiser works on every cell of quality below this (``Mesh.OptimizeThreshold``; gmsh's own 0.3
    when None), restored afterwards."""
    gmsh.option.setNumber("Mesh.CharacteristicLengthMin", resolution)
    gmsh.option.setNumber("Mesh.CharacteristicLengthMax", resolution)
    gmsh.option.setNumber("Mesh.CharacteristicLengthFromCurvature", 0)
    gmsh.option.setNumber("Mesh.CharacteristicLengthExtendFromBoundary", 0)
    threshold = gmsh.option.getNumber("Mesh.OptimizeThreshold")
    if optimize_below is not None:
        gmsh.option.setNumber("Mesh.OptimizeThreshold", optimize_below)
    try:
        gmsh.model.mesh.generate(dim)
    finally:
        gmsh.option.setNumber("Mesh.OptimizeThreshold", threshold)
    if degree > 1:
        gmsh.model.mesh.setOrder(degree)
        if untangle:
            gmsh.model.mesh.optimize("HighOrder")


def cell_values(mesh: dolfinx.mesh.Mesh, integrand: ufl.core.expr.Expr, /) -> npt.NDArray[np.float64]:
    """Integral of ``integrand`` over every local cell (owned and ghost), shape=(num_local_cells,)."""
    V0 = function_space(mesh, "DG", 0)
    w = ufl.TestFunction(V0)
    vec = dolfinx.fem.assemble_vector(dolfinx.fem.form(integrand * w * ufl.dx))
    vec.scatter_forward()
    return vec.array[cell_dofmap(V0).reshape(-1)].copy()


def cell_volumes(mesh: dolfinx.mesh.Mesh, /) -> npt.NDArray[np.float64]:
    """Volume (area in 2D) of every local cell (owned and ghost), shape=(num_local_cells,)."""
    return cell_values(mesh, ufl.as_ufl(1.0))


def cell_diameter(mesh: dolfinx.mesh.Mesh, /) -> ufl.core.expr.Expr:
    """Cell diameter for forms: ``ufl.CellDiameter`` on straight-sided cells; on curved cells (which
    FFCx 0.5 cannot generate ``CellDiameter`` for) a DG0 Function of the largest vertex distance,
    of the undeformed cells for a moving mesh (:func:`fembase.geometry.reference_coordinates`: the
    forms are made once, and a resumed run makes them on the mesh as it was saved). Not collective
    (ghost cells are computed directly)."""
    if coordinate_map(mesh).degree == 1:
        return ufl.CellDiameter(mesh)
    V0 = function_space(mesh, "DG", 0)
    tdim = mesh.topology.dim
    num_cells = mesh.topology.index_map(tdim).size_local + mesh.topology.index_map(tdim).num_ghosts
    num_vertices = dolfinx.cpp.mesh.cell_num_vertices(mesh.topology.cell_type)
    nodes = geometry_dofmap(mesh)[:num_cells, :num_vertices]
    x = reference_coordinates(mesh)[nodes]
    h = np.zeros(num_cells)
    for i in range(num_vertices):
        for j in range(i + 1, num_vertices):
            h = np.maximum(h, np.linalg.norm(x[:, i] - x[:, j], axis=1))
    f = dolfinx.fem.Function(V0, name="cell_diameter")
    f.x.array[cell_dofmap(V0).reshape(-1)[:num_cells]] = h
    return f
