"""The one module that knows which DOLFINx it runs on: 0.5 (Debian 12), 0.9 (Debian 13), or 0.10
and 0.11 (PyPI's binary wheel ``dolfinx-solver-real``; scripts/setup.sh with PIC_DOLFINX=pypi).

Every DOLFINx call whose spelling differs between the versions goes through a function here, so
the rest of the code (fembase, particles, convection) is written once. The differences absorbed
between 0.5 and 0.9 (0.10 and 0.11 spell these as 0.9 does, except where the second table says):

================================= ================================ ===================================
what                              DOLFINx 0.5                      DOLFINx 0.9
================================= ================================ ===================================
geometry dofmap                   ``AdjacencyList`` (``.array``)   ``ndarray`` (num_cells, nodes)
function-space dofmap             ``dofmap.list`` AdjacencyList    ``dofmap.list`` ndarray
function spaces                   ``FunctionSpace(mesh, (f, k))``, ``functionspace(mesh, (f, k,
                                  ``VectorFunctionSpace``          shape))``
finite elements                   ``ufl.FiniteElement``,           ``basix.ufl.element(f, cell, k,
                                  ``ufl.VectorElement``            shape=...)``
element family of a space         ``ufl_element().family()``       ``ufl_element().discontinuous``
bounding-box tree                 ``geometry.BoundingBoxTree``     ``geometry.bb_tree``
point collisions                  ``compute_collisions``           ``compute_collisions_points``
refinement keeping the partition  ``refine(..., redistribute=      ``refine(..., partitioner=None)``
                                  False)``, with ghost cells       returns a tuple, *no ghost cells*
``create_mesh``                   ``ghost_mode=`` argument         ghost mode in the partitioner
custom cell partitioner           ``create_cell_partitioner(fn)``  ``create_cell_partitioner(fn,
                                                                   ghost_mode)``
C++ mesh object                   ``mesh._mesh``                   ``mesh._cpp_object``
``entities_to_geometry``          ``dolfinx.cpp.mesh``, C++ mesh   ``dolfinx.mesh``, Python mesh
PETSc vector of a Function        ``f.vector``                     ``f.x.petsc_vec``
reverse scatter mode              ``la.ScatterMode.add``           ``la.InsertMode.add``
Dirichlet condition class         ``fem.DirichletBCMetaClass``     ``fem.DirichletBC``
interpolation points              ``element.                       ``element.interpolation_points()``
                                  interpolation_points()``         on 0.9, a property from 0.10
interpolating on some cells       ``f.interpolate(g, cells=...)``  ``f.interpolate(g, cells0=...)``
form compiler options             ``form_compiler_params``,        ``form_compiler_options``,
                                  ``jit_params``                   ``jit_options``
incident entities                 ``compute_incident_entities(     ``compute_incident_entities(
                                  mesh, ...)``                     mesh.topology, ...)``
assembling into a submatrix       ``cpp.fem.petsc.assemble_matrix  the same on ``form._cpp_object``
                                  (A, form, ...)``                 and the conditions' C++ objects
orthonormalising PETSc vectors    ``la.orthonormalize(vecs)``      takes ``la.Vector`` only
Lagrange fields in XDMF           degree 1 on any mesh             the geometry's degree only
================================= ================================ ===================================

And the differences of 0.10 and 0.11 from 0.9 (the PyPI wheel is 0.11; 0.10 is read from its
sources, untried):

================================= ================================ ===================================
what                              DOLFINx 0.9                      DOLFINx 0.10 / 0.11
================================= ================================ ===================================
``create_mesh`` arguments         ``(comm, cells, x, domain,       ``(comm, cells, domain, x,
                                  partitioner)``                   partitioner)``: element before x
default cell partitioner          ``create_cell_partitioner(mode)`` 0.11: ``(mode,
                                                                   max_facet_to_cell_links)``
custom cell partitioner           ``cpp.mesh.create_cell_          0.11: a third argument,
                                  partitioner(fn, ghost_mode)``    ``max_facet_to_cell_links`` (2)
coordinate map, geometry dofmap   ``geometry.cmap``,               0.11: ``geometry.cmaps[0]``,
                                  ``geometry.dofmap``              ``geometry.dofmaps[0]`` (the old
                                                                   names warn: deprecated)
bounding-box tree                 ``bb_tree(mesh, dim, entities,   ``entities`` and ``padding``
                                  padding)``                       keyword-only
block matrices                    ``create_matrix_block(a)``,      ``create_matrix(a, kind="mpi")``,
                                  ``assemble_matrix_block(A, a,    ``assemble_matrix(A, a, bcs)`` on
                                  bcs)``                           the nested list (``_block`` gone)
block vectors                     ``create_vector_block(L)``       ``create_vector(spaces,
                                                                   kind="mpi")``: of function spaces
block right-hand side             ``assemble_vector_block(b, L, a,  ``assemble_vector(b, L)``, then
                                  bcs)`` lifts and sets values     ``apply_lifting`` and ``set_bc``
                                                                   with conditions by block
                                                                   (``bcs_by_block``) and the ghost
                                                                   update between them
vector of a linear form           ``create_vector(L)``             ``create_vector(space)``
gmsh models to meshes             ``io.gmshio.model_to_mesh``:     ``io.gmsh.model_to_mesh``:
                                  a tuple                          ``MeshData`` (``.mesh``)
refinement keeping the partition  ``refine(..., partitioner=None)`` the same call (still no ghost
                                                                   cells; the default keeps the
                                                                   partition *with* a ghost layer)
UFL cell name, domain dimension   ``cell.cellname()``,             UFL 2026 (with 0.11): properties,
                                  ``domain.topological_dimension()`` ``cell.cellname``, ...
``import dolfinx``                as it is                         the wheel needs ``import
                                                                   dolfinx_solver`` first (the
                                                                   venv's .pth file does it)
================================= ================================ ===================================

Nothing outside :mod:`fembase` checks a DOLFINx version (tests/test_layers.py).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt

import dolfinx
import dolfinx.cpp.graph
import dolfinx.cpp.mesh
import dolfinx.fem
import dolfinx.geometry
import dolfinx.la
import dolfinx.mesh
import ufl

__all__ = ["DOLFINX_VERSION", "DirichletBC", "REFINE_KEEPS_GHOSTS", "SCATTER_ADD", "adjacency_list",
           "assemble_block_matrix", "assemble_block_vector", "assemble_matrix_into", "atan2", "bounding_box_tree",
           "cell_dofmap", "cell_partitioner", "compute_collisions", "coordinate_element",
           "coordinate_element_description", "coordinate_element_from", "coordinate_map", "cpp_mesh",
           "create_block_matrix", "create_block_vector", "create_mesh", "create_nest_matrix", "create_vector",
           "element", "element_degree",
           "entities_to_geometry", "evaluate_expression", "form", "function_space", "geometry_dofmap",
           "gmsh_model_to_mesh", "incident_entities", "interpolate_on_cells", "interpolation_points",
           "is_discontinuous", "is_lagrange", "mesh_domain", "orthonormalize", "petsc_vector",
           "refine_keeping_partition", "repartitioned_manifolds_nest", "topological_dimension", "value_size",
           "xdmf_lagrange_degree", "xdmf_value_shape"]

DOLFINX_VERSION: tuple[int, int] = tuple(int(p) for p in dolfinx.__version__.split(".")[:2])  # type: ignore[assignment]
"""(major, minor) of the DOLFINx in use."""

_NEW = DOLFINX_VERSION >= (0, 7)  # numpy dofmaps, basix.ufl elements, functionspace (0.7 and later)
_V010 = DOLFINX_VERSION >= (0, 10)  # create_mesh's new argument order, unified PETSc assembly, io.gmsh
_V011 = DOLFINX_VERSION >= (0, 11)  # geometry cmaps/dofmaps lists, max_facet_to_cell_links

if not (0, 5) <= DOLFINX_VERSION < (0, 12):
    raise ImportError(f"DOLFINx {dolfinx.__version__} is not supported (0.5, 0.9, 0.10 and 0.11 are)")

if _NEW:
    import basix
    import basix.ufl

if _NEW:
    DirichletBC = dolfinx.fem.DirichletBC
    """The class of ``dolfinx.fem.dirichletbc``'s results."""
else:
    DirichletBC = dolfinx.fem.DirichletBCMetaClass

SCATTER_ADD = dolfinx.la.InsertMode.add if _NEW else dolfinx.la.ScatterMode.add
"""The mode of ``x.scatter_reverse`` that adds ghost contributions to their owners."""

REFINE_KEEPS_GHOSTS: bool = not _NEW
"""Whether :func:`refine_keeping_partition` gives the refined mesh ghost cells (0.5) or none (0.9;
:func:`fembase.distribute.refine_on_ranks` makes the facet ghost layer again)."""


def repartitioned_manifolds_nest() -> bool:
    """Whether the refined levels of a repartitioned curved (manifold) mesh nest rank by rank, as
    geometric multigrid's prolongation (:mod:`fembase.multigrid`) needs: on 0.5 they do; on 0.9 a
    node of a repartitioned spherical shell lay in no coarser cell of its rank."""
    return not _NEW


# ---------------------------------------------------------------------- meshes
def geometry_dofmap(mesh: dolfinx.mesh.Mesh, /) -> npt.NDArray[np.int32]:
    """Geometry node indices of every local cell, shape=(num_local_cells, nodes_per_cell), int32."""
    if _V011:
        return mesh.geometry.dofmaps[0]
    dofmap = mesh.geometry.dofmap
    if _NEW:
        return dofmap
    if dofmap.num_nodes == 0:  # a rank without cells (a coarse mesh on many ranks)
        return np.zeros((0, mesh.geometry.cmap.create_dof_layout().num_dofs), dtype=np.int32)
    return dofmap.array.reshape(dofmap.num_nodes, -1)


def coordinate_map(mesh: dolfinx.mesh.Mesh, /) -> Any:
    """The mesh's coordinate map (``degree``, ``push_forward``, ``pull_back``; one cell type)."""
    return mesh.geometry.cmaps[0] if _V011 else mesh.geometry.cmap


def cpp_mesh(mesh: dolfinx.mesh.Mesh, /) -> Any:
    """The C++ mesh behind a Python mesh (what ``dolfinx.cpp`` functions take)."""
    return mesh._cpp_object if _NEW else getattr(mesh, "_mesh", mesh)


def coordinate_element(mesh: dolfinx.mesh.Mesh, /) -> Any:
    """The UFL coordinate element of ``mesh`` (to make another mesh of the same kind)."""
    return mesh.ufl_domain().ufl_coordinate_element()


def coordinate_element_description(mesh: dolfinx.mesh.Mesh, /) -> tuple[str, int, int]:
    """(cell name, degree, gdim) of the mesh's Lagrange coordinate element: what another rank
    needs to make the same element (:func:`coordinate_element_from`; DOLFINx 0.9's elements cannot
    be pickled)."""
    return mesh.topology.cell_name(), int(coordinate_map(mesh).degree), int(mesh.geometry.dim)


def coordinate_element_from(description: tuple[str, int, int], /) -> Any:
    """The vector Lagrange coordinate element of :func:`coordinate_element_description`."""
    cell, degree, gdim = description
    return element("Lagrange", cell if _NEW else getattr(ufl, cell), degree, shape=(gdim,))


def _ufl_value(attribute: Any) -> Any:
    """A UFL attribute that is a method before UFL 2026 and a property since (DOLFINx 0.11)."""
    return attribute() if callable(attribute) else attribute


def topological_dimension(domain: ufl.Mesh, /) -> int:
    """The topological dimension of a UFL domain."""
    return int(_ufl_value(domain.topological_dimension))


def mesh_domain(coordinate: Any, /) -> ufl.Mesh:
    """A new UFL domain for a mesh to create from a coordinate element (DOLFINx ties each domain
    object to one mesh)."""
    return ufl.Mesh(coordinate)


_MAX_FACET_CELLS = 2
"""Cells a facet can have (a manifold mesh without branches; DOLFINx 0.11's partitioners ask)."""


def create_mesh(comm: Any, cells: npt.NDArray[np.int64], x: npt.NDArray[np.float64], domain: ufl.Mesh,
                partitioner: Any = None, /) -> dolfinx.mesh.Mesh:
    """``dolfinx.mesh.create_mesh`` with a cell partitioner (:func:`cell_partitioner`; None:
    DOLFINx's graph partitioner) and the facet ghost layer (collective)."""
    cells = np.asarray(cells, dtype=np.int64)
    if partitioner is None:
        if _V011:
            partitioner = dolfinx.mesh.create_cell_partitioner(dolfinx.mesh.GhostMode.shared_facet, _MAX_FACET_CELLS)
        elif _NEW:
            partitioner = dolfinx.mesh.create_cell_partitioner(dolfinx.mesh.GhostMode.shared_facet)
        else:
            partitioner = dolfinx.cpp.mesh.create_cell_partitioner()
    if _V010:
        return dolfinx.mesh.create_mesh(comm, cells, domain, np.asarray(x, dtype=np.float64), partitioner)
    if _NEW:
        return dolfinx.mesh.create_mesh(comm, cells, np.asarray(x, dtype=np.float64), domain, partitioner)
    return dolfinx.mesh.create_mesh(comm, cells, x, domain, ghost_mode=dolfinx.mesh.GhostMode.shared_facet,
                                    partitioner=partitioner)


def cell_partitioner(graph_partitioner: Callable[[Any, int, Any, bool], Any], /) -> Any:
    """A cell partitioner for :func:`create_mesh` from a graph partitioner
    ``(comm, nparts, graph: AdjacencyList_int64, ghosting) -> AdjacencyList_int32`` (destination
    ranks per cell: owner first, then ghost ranks), with the facet ghost layer."""
    if _V011:
        return dolfinx.cpp.mesh.create_cell_partitioner(graph_partitioner, dolfinx.mesh.GhostMode.shared_facet,
                                                        _MAX_FACET_CELLS)
    if _NEW:
        return dolfinx.cpp.mesh.create_cell_partitioner(graph_partitioner, dolfinx.mesh.GhostMode.shared_facet)
    return dolfinx.cpp.mesh.create_cell_partitioner(graph_partitioner)


def adjacency_list(data: npt.ArrayLike, offsets: npt.ArrayLike | None = None, /) -> Any:
    """An int32 ``AdjacencyList`` (C++), e.g. a graph partitioner's result."""
    data = np.ascontiguousarray(data, dtype=np.int32)
    if offsets is None:
        return dolfinx.cpp.graph.AdjacencyList_int32(data)
    return dolfinx.cpp.graph.AdjacencyList_int32(data, np.ascontiguousarray(offsets, dtype=np.int32))


def refine_keeping_partition(mesh: dolfinx.mesh.Mesh, edges: npt.NDArray[np.int32] | None = None, /
                             ) -> dolfinx.mesh.Mesh:
    """The mesh refined at ``edges`` (None: uniformly), each new cell on the rank of its parent
    (collective). Ghost cells: see :data:`REFINE_KEEPS_GHOSTS`."""
    mesh.topology.create_entities(1)
    if _NEW:
        return dolfinx.mesh.refine(mesh, edges, partitioner=None)[0]
    if edges is None:
        return dolfinx.mesh.refine(mesh, redistribute=False)
    return dolfinx.mesh.refine(mesh, edges, redistribute=False)


def incident_entities(mesh: dolfinx.mesh.Mesh, entities: npt.NDArray[np.int32], d0: int, d1: int, /
                      ) -> npt.NDArray[np.int32]:
    """The entities of dimension ``d1`` incident to the given entities of dimension ``d0``."""
    entities = np.asarray(entities, dtype=np.int32)
    if _NEW:
        return dolfinx.mesh.compute_incident_entities(mesh.topology, entities, d0, d1)
    return dolfinx.mesh.compute_incident_entities(mesh, entities, d0, d1)


def entities_to_geometry(mesh: dolfinx.mesh.Mesh, dim: int, entities: npt.NDArray[np.int32], /
                         ) -> npt.NDArray[np.int32]:
    """Geometry nodes of mesh entities of dimension ``dim``, shape=(len(entities), nodes)."""
    entities = np.asarray(entities, dtype=np.int32)
    if _NEW:
        return dolfinx.mesh.entities_to_geometry(mesh, dim, entities, False)
    return dolfinx.cpp.mesh.entities_to_geometry(cpp_mesh(mesh), dim, entities, False)


# ---------------------------------------------------------------------- point search
def bounding_box_tree(mesh: dolfinx.mesh.Mesh, dim: int, entities: npt.NDArray[np.int32] | None = None, /, *,
                      padding: float = 0.0) -> Any:
    """Bounding-box tree of the entities of dimension ``dim`` (default: every local one)."""
    if entities is None:
        imap = mesh.topology.index_map(dim)
        entities = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
    entities = np.asarray(entities, dtype=np.int32)
    if _NEW:
        return dolfinx.geometry.bb_tree(mesh, dim, entities=entities, padding=padding)
    return dolfinx.geometry.BoundingBoxTree(mesh, dim, entities, padding=padding)


def compute_collisions(tree: Any, points: npt.NDArray[np.float64], /) -> Any:
    """Candidate entities of ``tree`` per point (points shape=(m, 3)): an AdjacencyList."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    if _NEW:
        return dolfinx.geometry.compute_collisions_points(tree, points)
    return dolfinx.geometry.compute_collisions(tree, points)


# ---------------------------------------------------------------------- spaces and elements
def element(family: str, cell: Any, degree: int, /, *, shape: tuple[int, ...] | None = None) -> Any:
    """A finite element: ``family`` ("Lagrange", "DG", ...) of ``degree`` on ``cell`` (a UFL cell
    or its name), scalar or with value ``shape`` (a vector: ``(gdim,)``)."""
    if _NEW:
        name = _ufl_value(cell.cellname) if hasattr(cell, "cellname") else str(cell)
        return basix.ufl.element(family, name, degree, shape=shape)
    if shape is None or shape == ():
        return ufl.FiniteElement(family, cell, degree)
    if len(shape) == 1:
        return ufl.VectorElement(family, cell, degree, dim=shape[0])
    return ufl.TensorElement(family, cell, degree, shape=shape)


def function_space(mesh: dolfinx.mesh.Mesh, family: str | Any, degree: int | None = None, /, *,
                   shape: tuple[int, ...] | None = None) -> dolfinx.fem.FunctionSpace:
    """A function space on ``mesh``: ``function_space(mesh, "Lagrange", 2, shape=(gdim,))``, or of
    an element made by :func:`element` (``function_space(mesh, element(...))``)."""
    if degree is None:
        e = family
    else:
        e = element(family, mesh.ufl_cell(), degree, shape=shape)
    if _NEW:
        return dolfinx.fem.functionspace(mesh, e)
    return dolfinx.fem.FunctionSpace(mesh, e)


def cell_dofmap(V: dolfinx.fem.FunctionSpace, /) -> npt.NDArray[np.int32]:
    """Dofs (blocks) of every local cell, shape=(num_local_cells, dofs_per_cell), int32."""
    dofs = V.dofmap.list
    if _NEW:
        return dofs
    return dofs.array.reshape(dofs.num_nodes, -1)


def _ufl_element(space_or_element: Any) -> Any:
    return space_or_element.ufl_element() if hasattr(space_or_element, "ufl_element") else space_or_element


def is_discontinuous(space_or_element: Any, /) -> bool:
    """Whether a space's (or a UFL element's) element is discontinuous: DG, or not Lagrange at all
    (e.g. a "Real" space)."""
    e = _ufl_element(space_or_element)
    if _NEW:
        return bool(e.discontinuous) or not is_lagrange(e)
    return e.family() not in ("Lagrange", "P", "Q")


def is_lagrange(space_or_element: Any, /) -> bool:
    """Whether the element is (continuous or discontinuous, scalar or blocked) Lagrange, whose dofs
    are values at the dof coordinates."""
    e = _ufl_element(space_or_element)
    if _NEW:
        return e.element_family == basix.ElementFamily.P
    return e.family() in ("Lagrange", "P", "Q", "Discontinuous Lagrange", "DG", "DQ")


def value_size(space_or_element: Any, /) -> int:
    """Number of value components of the element (1 for a scalar)."""
    e = _ufl_element(space_or_element)
    shape = e.reference_value_shape if _NEW else e.value_shape()
    return int(np.prod(shape)) if len(shape) else 1


def element_degree(space_or_element: Any, /) -> int:
    """The polynomial degree of the element."""
    e = _ufl_element(space_or_element)
    return int(e.degree if _NEW else e.degree())


def interpolate_on_cells(f: dolfinx.fem.Function, source: Any, cells: npt.NDArray[np.int32], /) -> None:
    """``f.interpolate(source)`` on the given local cells only (the keyword is ``cells`` on 0.5,
    ``cells0`` on 0.9). ``source``: a callable ``x`` shape=(3, n) -> shape=(value_size, n), an
    Expression or a Function on the same mesh. Not collective."""
    if _NEW:
        f.interpolate(source, cells0=cells)
    else:
        f.interpolate(source, cells=cells)


def interpolation_points(V: dolfinx.fem.FunctionSpace, /) -> npt.NDArray[np.float64]:
    """The reference points at which the space's element interpolates (a method on DOLFINx 0.5
    and 0.9, a property from 0.10)."""
    points = V.element.interpolation_points
    return points() if callable(points) else points


def xdmf_lagrange_degree(mesh: dolfinx.mesh.Mesh, /) -> int:
    """The degree of the continuous Lagrange fields ``XDMFFile.write_function`` accepts on ``mesh``:
    1 on DOLFINx 0.5 (node values at the vertices), the geometry's degree on 0.9 (which refuses any
    other, e.g. P1 fields on curved P2 shells)."""
    return int(coordinate_map(mesh).degree) if _NEW else 1


def xdmf_value_shape(shape: tuple[int, ...], /) -> tuple[int, ...]:
    """The value shape to write a field of ``shape`` with, so that ParaView reads it alike on every
    version: a 2D tensor (2, 2) as VTK's 3 x 3 on DOLFINx 0.9, which would write its 2 x 2 values
    flat and padded with zeros (0.5 embeds them in 3 x 3 itself)."""
    return (3, 3) if _NEW and shape == (2, 2) else shape


def petsc_vector(f: dolfinx.fem.Function, /) -> Any:
    """The PETSc vector that shares a Function's values."""
    return f.x.petsc_vec if _NEW else f.vector


def assemble_matrix_into(A: Any, a: Any, bcs: list[Any], /) -> None:
    """Add the bilinear form ``a`` into the PETSc matrix ``A`` (e.g. a local submatrix of a block
    matrix, block-unrolled indices), skipping the rows and columns of ``bcs``; ``A`` is not
    finalised (collective only through ``A``)."""
    cpp = dolfinx.cpp.fem
    if _NEW:
        f = a._cpp_object
        cpp.petsc.assemble_matrix(A, f, cpp.pack_constants(f), cpp.pack_coefficients(f),
                                  [bc._cpp_object for bc in bcs], True)
    else:
        cpp.petsc.assemble_matrix(A, a, cpp.pack_constants(a), cpp.pack_coefficients(a), bcs, True)


def create_vector(L: Any, /) -> Any:
    """A PETSc vector (ghosted) for the linear form ``L``'s space; not zeroed."""
    import dolfinx.fem.petsc

    if _V010:
        return dolfinx.fem.petsc.create_vector(L.function_spaces[0])
    return dolfinx.fem.petsc.create_vector(L)


def create_block_matrix(a: list[list[Any]], /) -> Any:
    """One PETSc matrix (MPI AIJ, not nested) for the nested list of bilinear forms ``a`` (None:
    an empty block); the rows of each rank: its owned dofs of each block in turn."""
    import dolfinx.fem.petsc

    if _V010:
        return dolfinx.fem.petsc.create_matrix(a, kind="mpi")
    return dolfinx.fem.petsc.create_matrix_block(a)


def create_nest_matrix(a: list[list[Any]], /) -> Any:
    """A PETSc MATNEST of one MPI AIJ matrix per block of the nested list of bilinear forms ``a``
    (None: no block), with :func:`create_block_matrix`'s rows; its blocks are matrices of their
    own, which PETSc's fieldsplit takes as they are (no copies)."""
    import dolfinx.fem.petsc

    if _V010:
        return dolfinx.fem.petsc.create_matrix(a, kind="nest")
    return dolfinx.fem.petsc.create_matrix_nest(a)


def create_block_vector(L: list[Any], /) -> Any:
    """One PETSc vector for the list of linear forms ``L``, laid out as :func:`create_block_matrix`'s
    rows; not zeroed."""
    import dolfinx.fem.petsc

    if _V010:
        return dolfinx.fem.petsc.create_vector([form.function_spaces[0] for form in L], kind="mpi")
    return dolfinx.fem.petsc.create_vector_block(L)


def assemble_block_matrix(A: Any, a: list[list[Any]], /, *, bcs: list[Any]) -> None:
    """Add the nested list of bilinear forms ``a`` into the block matrix ``A`` (from
    :func:`create_block_matrix` or :func:`create_nest_matrix`), with unit diagonal entries on the
    rows and columns of ``bcs``; ``A`` is not finalised (call ``A.assemble()``)."""
    import dolfinx.fem.petsc

    if _V010:
        dolfinx.fem.petsc.assemble_matrix(A, a, bcs=bcs)
    elif A.getType() == "nest":
        dolfinx.fem.petsc.assemble_matrix_nest(A, a, bcs=bcs)
    else:
        dolfinx.fem.petsc.assemble_matrix_block(A, a, bcs=bcs)


def assemble_block_vector(b: Any, L: list[Any], a: list[list[Any]], /, *, bcs: list[Any]) -> None:
    """Add the linear forms ``L`` into the block vector ``b`` (from :func:`create_block_vector`),
    lift the values of ``bcs`` with the bilinear forms ``a`` (``b - a g``), add the ghost
    contributions to their owners and set the values of ``bcs`` on their rows (collective)."""
    import dolfinx.fem.petsc
    from petsc4py import PETSc

    if not _V010:
        dolfinx.fem.petsc.assemble_vector_block(b, L, a, bcs=bcs)
        return
    dolfinx.fem.petsc.assemble_vector(b, L)
    dolfinx.fem.petsc.apply_lifting(b, a, bcs=dolfinx.fem.bcs_by_block(dolfinx.fem.extract_function_spaces(a, 1), bcs))
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    dolfinx.fem.petsc.set_bc(b, dolfinx.fem.bcs_by_block(dolfinx.fem.extract_function_spaces(L), bcs))


def gmsh_model_to_mesh(model: Any, comm: Any, rank: int, /, *, gdim: int) -> dolfinx.mesh.Mesh:
    """The mesh of a gmsh model that lives on ``rank`` of ``comm`` (collective; tags dropped)."""
    if _V010:
        import dolfinx.io.gmsh

        return dolfinx.io.gmsh.model_to_mesh(model, comm, rank, gdim=gdim).mesh
    from dolfinx.io import gmshio

    return gmshio.model_to_mesh(model, comm, rank, gdim=gdim)[0]


def orthonormalize(vectors: list[Any], /) -> None:
    """Orthonormalise PETSc vectors in place (modified Gram-Schmidt; collective)."""
    if not _NEW:
        dolfinx.la.orthonormalize(vectors)
        return
    for i, v in enumerate(vectors):  # DOLFINx 0.9's orthonormalize takes dolfinx.la.Vector only
        for w in vectors[:i]:
            v.axpy(-w.dot(v), w)
        v.scale(1.0 / v.norm())


def evaluate_expression(expression: Any, mesh: dolfinx.mesh.Mesh, cells: npt.NDArray[np.int32], /) -> Any:
    """Values of a ``dolfinx.fem.Expression`` at its points in ``cells``, shape=(len(cells), ...)."""
    cells = np.asarray(cells, dtype=np.int32)
    return expression.eval(mesh, cells) if _NEW else expression.eval(cells)


def atan2(y: Any, x: Any, /) -> Any:
    """UFL's two-argument arctangent (``ufl.atan_2`` in UFL 2022, ``ufl.atan2`` since)."""
    return ufl.atan2(y, x) if hasattr(ufl, "atan2") else ufl.atan_2(y, x)


def form(forms: Any, /, *, form_compiler_options: dict | None = None, jit_options: dict | None = None) -> Any:
    """``dolfinx.fem.form`` with form compiler and JIT options under either version's names."""
    if _NEW:
        return dolfinx.fem.form(forms, form_compiler_options=form_compiler_options, jit_options=jit_options)
    return dolfinx.fem.form(forms, form_compiler_params=form_compiler_options, jit_params=jit_options)
