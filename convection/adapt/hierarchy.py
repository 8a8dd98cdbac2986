"""The mesh hierarchy: a coarse base mesh and meshes refined from it, rebuilt from the base at every
change (:class:`MeshHierarchy`).

DOLFINx 0.5 refines (Plaza) but cannot coarsen. Every adaptation therefore rebuilds the mesh from
the coarse base mesh, refining level by level the cells whose level is below the wanted level found
at their midpoint (:meth:`MeshHierarchy.rebuild`). The refinement keeps each cell on the rank of
its base ancestor (``redistribute=False``), so old and new meshes cover the same part of the domain
on every rank and fields move between them without communication (see
:mod:`convection.adapt.transfer`). The nesting also replaces the bounding-box search between the
two meshes: a point inside a base cell lies only in cells descending from it, so particles, the
nodes of transferred fields and the refinement rounds' midpoints are looked for among those cells
first (:meth:`MeshHierarchy.candidates`). A repartition moves the base mesh and the current mesh
together (:meth:`MeshHierarchy.repartition`); :class:`MeshRecipe` is how to make both again.

Curved domains (``manifold=``, :class:`fembase.manifold.ShellManifold`): the base mesh and every
mesh the refinement rounds make are straight-sided (P1; DOLFINx refines those only); the meshes the
hierarchy hands out are curved (P2) by the manifold, which puts every geometry node where the
straight node maps to (boundary nodes on the circles or spheres). Levels, base cells and the
refinement rounds' midpoints are computed on the straight mesh a curved mesh was made from
(:class:`CurvedMeshes` keeps the last three), or, for a curved mesh made elsewhere (a repartition,
a checkpoint), from the straight positions of its vertices
(:meth:`fembase.manifold.ShellManifold.straight_points`), so the nesting is exact either way.

The level of a simplex is measured from its volume: ``level = floor(log2(V_base / V) / tdim)`` with
``V_base`` the volume of the base cell it descends from, so a cell split uniformly once is level 1
and a cell only bisected for conformity stays at its level.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh
import ufl

from convection.adapt.transfer import PointEvaluator
from fembase.distribute import MeshPiece, create_mesh_from_piece, mesh_piece, refine_on_ranks
from fembase.dolfinx_compat import (cell_dofmap, coordinate_element_from, coordinate_map, function_space,
                                    geometry_dofmap, mesh_domain)
from fembase.geometry import Candidates
from fembase.manifold import ShellManifold
from fembase.partition import PARTITIONERS, partition

__all__ = ["CurvedMeshes", "MeshHierarchy", "MeshRecipe", "RefinementChain"]


@dataclass
class MeshRecipe:
    """How a :class:`MeshHierarchy` made its base and its latest mesh, to make both again, bit for
    bit, on the same number of ranks (a checkpoint stores it; DOLFINx builds meshes
    deterministically from the same input). Every rank holds its own part only.

    Attributes:
        base: This rank's piece of the base mesh handed to ``create_mesh`` at the latest
            repartition (its cells, nodes, new owners and canonical indices), or None: the base
            mesh the hierarchy was created with.
        rounds: The latest mesh refined from the base: per refinement round the marked local
            cells (None: a uniform round). Used when ``mesh`` is None.
        mesh: This rank's piece of the latest mesh handed to ``create_mesh`` at a repartition, or
            None.
        levels: With ``mesh``: this rank's pieces of the meshes of the refinement chain between the
            base and the mesh (coarse to fine) handed to ``create_mesh`` at that repartition
            (:attr:`MeshHierarchy.keep_levels`); empty otherwise.
    """

    base: MeshPiece | None = None
    rounds: list[npt.NDArray[np.int32] | None] = field(default_factory=list)
    mesh: MeshPiece | None = None
    levels: list[MeshPiece] = field(default_factory=list)


class RefinementChain:
    """The meshes a :class:`MeshHierarchy` refined in turn, from its base, at its last rebuild,
    replay or uniform refinement: each nested in the next, every cell on the rank of the coarser cell
    it lies in (:func:`fembase.distribute.refine_on_ranks`), so a geometric multigrid on an adaptive
    mesh takes them as its levels (:class:`convection.adapt.levels.MeshLevels`)."""

    def __init__(self) -> None:
        self.meshes: list[dolfinx.mesh.Mesh] = []

    def add(self, coarse: dolfinx.mesh.Mesh, fine: dolfinx.mesh.Mesh, /) -> dolfinx.mesh.Mesh:
        """Record that ``fine`` was refined from ``coarse`` (a new chain unless ``coarse`` ends
        this one); returns ``fine``."""
        if not self.meshes or self.meshes[-1] is not coarse:
            self.meshes = [coarse]
        self.meshes.append(fine)
        return fine

    def create(self, comm: MPI.Comm, recipe: MeshRecipe, base: dolfinx.mesh.Mesh, level_domain: Callable[[], ufl.Mesh],
               mesh_domain: ufl.Mesh, /, *, nested: bool) -> dolfinx.mesh.Mesh:
        """The mesh of a repartition's ``recipe`` (its ``mesh`` piece), made with the meshes of its
        ``levels`` (each with a new ``level_domain()``); ``nested`` (every cell went with its base
        cell, straight meshes): the chain starts anew with ``base``, those and the mesh (collective)."""
        assert recipe.mesh is not None, "a repartition's recipe has its mesh piece"
        meshes = [base, *(create_mesh_from_piece(comm, piece, level_domain()).mesh for piece in recipe.levels)]
        mesh = create_mesh_from_piece(comm, recipe.mesh, mesh_domain).mesh
        if nested:
            self.meshes = [*meshes, mesh]
        return mesh

    def below(self, mesh: dolfinx.mesh.Mesh, base: dolfinx.mesh.Mesh, /) -> tuple[dolfinx.mesh.Mesh, ...] | None:
        """The meshes ``mesh`` was refined from, coarse to fine, ``base`` first (empty: ``mesh`` is
        ``base``), or None: the chain from ``base`` did not make ``mesh`` (e.g. a repartition did)."""
        if mesh is base:
            return ()
        if len(self.meshes) >= 2 and self.meshes[-1] is mesh and self.meshes[0] is base:
            return tuple(self.meshes[:-1])
        return None


def _vertex_coordinates(mesh: dolfinx.mesh.Mesh, num_cells: int, manifold: ShellManifold | None = None
                        ) -> npt.NDArray[np.float64]:
    """Vertex coordinates of the first ``num_cells`` local cells, shape=(num_cells, tdim + 1, gdim);
    of a curved mesh (geometry degree > 1) with a ``manifold``: the straight positions."""
    tdim, gdim = mesh.topology.dim, mesh.geometry.dim
    dofs = geometry_dofmap(mesh)[:num_cells, : tdim + 1]
    if manifold is not None and coordinate_map(mesh).degree > 1:
        nodes, inverse = np.unique(dofs, return_inverse=True)  # each vertex once (~20 cells share one in 3D)
        straight = manifold.straight_points(mesh.geometry.x[nodes, :gdim])
        return straight[inverse.reshape(dofs.shape)]
    return mesh.geometry.x[dofs][:, :, :gdim]


def _simplex_volumes(mesh: dolfinx.mesh.Mesh, num_cells: int, manifold: ShellManifold | None = None
                     ) -> npt.NDArray[np.float64]:
    """Volumes (areas in 2D) of the first ``num_cells`` local cells of an affine simplex mesh (or of
    a curved mesh's straight cells, see :func:`_vertex_coordinates`), shape=(num_cells,), from the
    vertex coordinates (no form to compile for every new mesh)."""
    tdim, gdim = mesh.topology.dim, mesh.geometry.dim
    x = _vertex_coordinates(mesh, num_cells, manifold)
    edges = x[:, 1:, :] - x[:, :1, :]  # shape=(num_cells, tdim, gdim)
    if tdim == gdim:
        return np.abs(np.linalg.det(edges)) / math.factorial(tdim)
    return np.sqrt(np.abs(np.linalg.det(edges @ edges.transpose(0, 2, 1)))) / math.factorial(tdim)


def _gather_midpoints(base: dolfinx.mesh.Mesh, canonical: npt.NDArray[np.int64]) -> npt.NDArray[np.float64] | None:
    """Midpoints of all base cells by canonical index on rank 0 (None elsewhere; collective): the
    input of the partition decision, gdim numbers per base cell."""
    gdim = base.geometry.dim
    num_owned = canonical.shape[0]
    # The mean of the vertex coordinates taken in a fixed (lexicographic) order of the vertices, so
    # the bits do not depend on the order a mesh lists them in (a replayed base may list them
    # otherwise than the base the uninterrupted run gathered them from).
    dofs = geometry_dofmap(base)[:num_owned]
    corners = base.geometry.x[dofs][:, :, :gdim]
    order = np.lexsort(corners.transpose(2, 0, 1)[::-1], axis=-1)  # per cell, by x then y (then z)
    midpoints = np.take_along_axis(corners, order[:, :, None], axis=1).mean(axis=1)
    gathered = base.comm.gather((np.asarray(canonical, dtype=np.int64), midpoints), root=0)
    if base.comm.rank != 0:
        return None
    index = np.concatenate([g[0] for g in gathered])
    if not np.array_equal(np.sort(index), np.arange(index.size)):
        raise ValueError("canonical cell indices are not a permutation of the global cells")
    out = np.empty((index.size, gdim))
    out[index] = np.concatenate([g[1] for g in gathered])
    return out


def _with_ghost_values(mesh: dolfinx.mesh.Mesh, owned_values: npt.NDArray[np.int32]) -> npt.NDArray[np.int32]:
    """Per-cell integers of the owned cells extended to the ghost cells (collective)."""
    V0 = function_space(mesh, "DG", 0)
    f = dolfinx.fem.Function(V0)
    dofs = cell_dofmap(V0).reshape(-1)
    num_owned = owned_values.shape[0]
    f.x.array[dofs[:num_owned]] = owned_values
    f.x.scatter_forward()
    return np.rint(f.x.array[dofs]).astype(np.int32)


def _same_base(where_base: npt.NDArray[np.int32], search_base: npt.NDArray[np.int32], cells: npt.NDArray[np.int32],
               num_base_owned: int) -> Candidates | None:
    """:meth:`MeshHierarchy.candidates` from the local base cell of every owned cell of the two
    meshes: the cells of ``search`` grouped by base cell, each point's group that of its cell."""
    for base_of in (where_base, search_base):
        if np.any((base_of < 0) | (base_of >= num_base_owned)):  # not refined from this rank's base cells
            return None
    num_groups = num_base_owned + 1  # the last one is empty
    offsets = np.zeros(num_groups + 1, dtype=np.int64)
    offsets[1:] = np.cumsum(np.bincount(search_base, minlength=num_groups))
    owned = cells < where_base.size
    groups = np.full(cells.size, num_groups - 1, dtype=np.int64)
    groups[owned] = where_base[cells[owned]]
    return Candidates(groups, offsets, np.argsort(search_base, kind="stable").astype(np.int32))


def _base_owners(comm: MPI.Comm, midpoints: npt.NDArray[np.float64] | None, base_of: npt.NDArray[np.int64],
                 particles: npt.NDArray[np.float64], num_base_cells: int, *, method: str,
                 particle_weight: float) -> npt.NDArray[np.int32]:
    """The new owner rank of every base cell by canonical index (collective): rank 0 partitions
    the base cells' ``midpoints`` by ``method``, weighing the cells and particles of the current
    mesh (``base_of``: the base cell of each owned cell; ``particles`` in each owned cell)."""
    counts = np.zeros((2, num_base_cells))
    counts[0] = np.bincount(base_of, minlength=num_base_cells)
    counts[1] = np.bincount(base_of, weights=particles, minlength=num_base_cells)
    total = np.zeros_like(counts)
    comm.Reduce(counts, total, op=MPI.SUM, root=0)
    owners = None
    if comm.rank == 0:
        assert midpoints is not None, "rank 0 has the base cells' midpoints"
        owners = partition(method, midpoints, total[0], total[1], comm.size, particle_weight=particle_weight)
    return comm.bcast(owners, root=0)


class CurvedMeshes:
    """The straight meshes behind the curved meshes a hierarchy hands out.

    For the last three meshes curved it keeps (curved mesh, the straight mesh it was curved from,
    the straight owned cell of each curved owned cell): the straight cells answer the hierarchy's
    questions (levels, base cells, which old cell holds a midpoint) with affine maps, without
    inverting the manifold. A curved mesh made elsewhere (a repartition, a checkpoint) is
    straightened once (:meth:`straight_view`).

    Args:
        manifold: The manifold that curves the meshes.
        tdim: The cells' dimension.
    """

    def __init__(self, manifold: ShellManifold, tdim: int, /) -> None:
        self.manifold = manifold
        self.tdim = tdim
        self._straight: list[tuple[dolfinx.mesh.Mesh, dolfinx.mesh.Mesh, npt.NDArray[np.int32]]] = []

    def curve(self, mesh: dolfinx.mesh.Mesh, /) -> dolfinx.mesh.Mesh:
        """``mesh`` (straight) curved by the manifold, remembered with it (collective)."""
        curved = self.manifold.curve(mesh)
        # curve() keeps every cell on its rank, in the straight mesh's owned order as the input
        # order: the curved cell's original index minus the rank's offset is the straight cell.
        self._remember(curved, mesh, self._made_from(curved))
        return curved

    def _made_from(self, made: dolfinx.mesh.Mesh) -> npt.NDArray[np.int32]:
        """For a mesh made from another one's owned cells, rank by rank in their order (curve(),
        straighten()): the source's owned cell of each owned cell, shape=(num_owned,) (collective)."""
        num_owned = made.topology.index_map(self.tdim).size_local
        offset = made.comm.exscan(num_owned) or 0
        perm = (np.asarray(made.topology.original_cell_index, dtype=np.int64)[:num_owned] - offset).astype(np.int32)
        if num_owned and (perm.min() < 0 or perm.max() >= num_owned):
            raise RuntimeError("the new mesh's cells are not the old mesh's cells of the same rank")
        return perm

    def _remember(self, curved: dolfinx.mesh.Mesh, straight: dolfinx.mesh.Mesh, perm: npt.NDArray[np.int32]) -> None:
        self._straight = [*self._straight[-2:], (curved, straight, perm)]

    def straight_view(self, mesh: dolfinx.mesh.Mesh, /) -> tuple[dolfinx.mesh.Mesh, npt.NDArray[np.int32]]:
        """:meth:`straight_of`, made (collective, :meth:`ShellManifold.straighten`) for a curved
        mesh the hierarchy did not curve itself (a repartitioned mesh, a restored checkpoint)."""
        known = self.straight_of(mesh)
        if known is not None:
            return known
        straight = self.manifold.straighten(mesh)
        # straighten() lists the straight cells in the curved mesh's owned order: invert the map.
        made = self._made_from(straight)  # curved owned cell of each straight owned cell
        perm = np.empty_like(made)
        perm[made] = np.arange(made.size, dtype=np.int32)
        self._remember(mesh, straight, perm)
        return straight, perm

    def straight_of(self, mesh: dolfinx.mesh.Mesh, /) -> tuple[dolfinx.mesh.Mesh, npt.NDArray[np.int32]] | None:
        """The straight mesh a curved mesh of this hierarchy was made from and the straight owned
        cell of each owned cell (shape=(num_owned,)), if it is one of the last three curved here."""
        for curved, straight, perm in self._straight:
            if curved is mesh:
                return straight, perm
        return None

    def midpoints(self, mesh: dolfinx.mesh.Mesh, cells: npt.NDArray[np.int32], /) -> npt.NDArray[np.float64]:
        """Midpoints (shape=(len(cells), 3)) of the straight cells behind local cells of a curved
        mesh: of its straight mesh if known, else of the straight positions of its vertices."""
        straight = self.straight_of(mesh)
        if straight is not None and np.all(cells < straight[1].size):
            return dolfinx.mesh.compute_midpoints(straight[0], self.tdim, straight[1][cells])
        x = _vertex_coordinates(mesh, int(cells.max(initial=-1)) + 1, self.manifold)[cells]
        out = np.zeros((cells.size, 3))
        out[:, : x.shape[2]] = x.mean(axis=1)
        return out

    def to_straight(self, mesh: dolfinx.mesh.Mesh, values: npt.NDArray, /) -> tuple[dolfinx.mesh.Mesh, npt.NDArray]:
        """The straight mesh of a curved mesh and per-owned-cell ``values`` put on its cells
        (collective: :meth:`straight_view`)."""
        straight, perm = self.straight_view(mesh)
        out = np.empty_like(values)
        out[perm] = values
        return straight, out


class MeshHierarchy:
    """The coarse base mesh and the level of each cell of meshes refined from it.

    Args:
        base: The coarse, uniformly sized base mesh (simplices; straight-sided with a manifold).
        manifold: Curves the meshes handed out (see the module docstring); None: they are
            refined as they are.
    """

    def __init__(self, base: dolfinx.mesh.Mesh, /, *, manifold: ShellManifold | None = None) -> None:
        if base.topology.cell_type not in (dolfinx.mesh.CellType.triangle, dolfinx.mesh.CellType.tetrahedron):
            raise ValueError("adaptive refinement needs a simplex mesh (mesh.cell_type: simplex)")
        if manifold is not None:
            if coordinate_map(base).degree != 1:
                raise ValueError("a hierarchy with a manifold needs a straight-sided (P1) base mesh")
            manifold.fit(base)
        self.manifold = manifold
        self.base = base
        self.tdim = base.topology.dim
        num_owned = base.topology.index_map(self.tdim).size_local
        self.base_volume = base.comm.allreduce(float(_simplex_volumes(base, num_owned).max(initial=0.0)), op=MPI.MAX)
        # Rank-independent index of each local base cell (the order the base mesh was created in).
        self.base_canonical = np.asarray(base.topology.original_cell_index, dtype=np.int64)
        # Rank 0: the base cells' midpoints by canonical index (the partition's input), once gathered.
        self._midpoints: npt.NDArray[np.float64] | None = None
        self._have_midpoints = False
        self.recipe = MeshRecipe()
        self.chain = RefinementChain()
        self.keep_levels = False  # a repartition moves the chain's meshes too (multigrid levels)
        self._element = base.ufl_domain().ufl_coordinate_element()
        # (base, mesh, local base cell of each owned cell) for the last meshes asked about: an
        # adaptation asks about the old mesh, each refinement round's mesh and the new one.
        self._base_of: list[tuple[dolfinx.mesh.Mesh, dolfinx.mesh.Mesh, npt.NDArray[np.int32]]] = []
        self._base_locator: PointEvaluator | None = None
        self.curved = None if manifold is None else CurvedMeshes(manifold, self.tdim)
        self._volumes_of: tuple[dolfinx.mesh.Mesh, npt.NDArray[np.float64]] | None = None

    @property
    def num_base_cells(self) -> int:
        return int(self.base.topology.index_map(self.tdim).size_global)

    def base_cells(self, mesh: dolfinx.mesh.Mesh, /) -> npt.NDArray[np.int64]:
        """Canonical index of the base cell each owned cell of ``mesh`` descends from (collective).

        ``mesh`` must be refined from the current base without redistribution (a cell's midpoint
        then lies in an owned base cell of the same rank). Returns shape=(num_owned_cells,), int64.
        """
        local = self._local_base_cells(mesh)
        if np.any(local < 0):
            raise RuntimeError("a cell lies outside this rank's base cells: mesh not refined from this base")
        return self.base_canonical[local]

    def _local_base_cells(self, mesh: dolfinx.mesh.Mesh, /) -> npt.NDArray[np.int32]:
        """Local index of the base cell containing each owned cell's midpoint (-1: none on this
        rank), shape=(num_owned_cells,); remembered for the last four meshes (not collective)."""
        for base, known, local in self._base_of:
            if base is self.base and known is mesh:
                return local
        num_owned = mesh.topology.index_map(self.tdim).size_local
        midpoints = self._straight_midpoints(mesh, np.arange(num_owned, dtype=np.int32))
        if self._base_locator is None or self._base_locator.mesh is not self.base:
            self._base_locator = PointEvaluator(self.base)
        local = self._base_locator.locate(midpoints)
        self._base_of = [*self._base_of[-3:], (self.base, mesh, local)]
        return local

    def _base_volumes(self) -> npt.NDArray[np.float64]:
        """Volume of every local (owned and ghost) base cell, shape=(num_local_base_cells,)."""
        if self._volumes_of is None or self._volumes_of[0] is not self.base:
            imap = self.base.topology.index_map(self.tdim)
            self._volumes_of = (self.base, _simplex_volumes(self.base, imap.size_local + imap.num_ghosts))
        return self._volumes_of[1]

    def _straight_midpoints(self, mesh: dolfinx.mesh.Mesh, cells: npt.NDArray[np.int32], /) -> npt.NDArray[np.float64]:
        """Midpoints (shape=(len(cells), 3)) of local cells, of the straight cells for a curved mesh."""
        if self.curved is None or coordinate_map(mesh).degree == 1:
            return dolfinx.mesh.compute_midpoints(mesh, self.tdim, cells)
        return self.curved.midpoints(mesh, cells)

    def curve(self, mesh: dolfinx.mesh.Mesh, /) -> dolfinx.mesh.Mesh:
        """The mesh to hand out for a straight mesh of the hierarchy: curved by the manifold, or
        ``mesh`` itself without one (collective)."""
        return mesh if self.curved is None else self.curved.curve(mesh)

    def mesh_domain(self) -> ufl.Mesh:
        """A new UFL domain for a mesh to hand out (curved with a manifold; see :meth:`new_domain`)."""
        if self.manifold is None:
            return self.new_domain()
        return mesh_domain(coordinate_element_from((self.base.topology.cell_name(), 2, self.base.geometry.dim)))

    def candidates(self, search: dolfinx.mesh.Mesh, where: dolfinx.mesh.Mesh,
                   cells: npt.NDArray[np.int32], /) -> Candidates | None:
        """Where to look in ``search`` for points lying in the cells ``cells`` of ``where``: the owned
        cells of ``search`` that descend from the same base cell (not collective).

        Both meshes must be refined from the current base without redistribution (as
        :meth:`rebuild` and :meth:`repartition` make them): each owned cell then lies in an owned
        base cell of its rank, and a point inside a base cell lies only in cells descending from
        it. Points in ghost cells of ``where`` get no candidates. Returns None when the meshes are
        not related so on this rank.

        Args:
            search: The mesh to search.
            where: The mesh the points lie in.
            cells: The local cell of ``where`` holding each point, shape=(m,).
        """
        return _same_base(self._local_base_cells(where), self._local_base_cells(search), np.asarray(cells),
                          self.base.topology.index_map(self.tdim).size_local)

    def repartition(self, mesh: dolfinx.mesh.Mesh, particles: npt.NDArray[np.float64], /, *,
                    particle_weight: float = 0.01, method: str = "rcb") -> dolfinx.mesh.Mesh:
        """Redistribute the base mesh and ``mesh`` so ranks get equal loads ``cells + W particles``.

        Collective. The base cells, each with its descendants in ``mesh`` and their particles, are
        partitioned by ``method`` (:data:`fembase.partition.PARTITIONERS`) on rank 0 from their
        midpoints and counts (O(base cells)); every cell of ``mesh`` goes with its base cell, so
        later rebuilds (:meth:`rebuild`) keep each region on its rank. Meshes are not gathered:
        every rank hands its own cells to ``create_mesh`` (:func:`fembase.distribute.create_mesh_from_piece`).
        With :attr:`keep_levels` the chain's meshes between the base and ``mesh`` move too.

        Args:
            mesh: The current mesh, refined from the current base.
            particles: Particles in each owned cell of ``mesh``, shape=(num_owned_cells,).
            particle_weight: W in the cell load 1 + W n_particles.
            method: Partition method name.

        Returns:
            The same cells as ``mesh`` on the new partition.
        """
        comm = self.base.comm
        if method not in PARTITIONERS:
            raise ValueError(f"unknown partition method {method!r}; valid names: {sorted(PARTITIONERS)}")
        num_base_owned = self.base.topology.index_map(self.tdim).size_local
        if not self._have_midpoints:  # the same on every rank (None on ranks > 0)
            self._midpoints = _gather_midpoints(self.base, self.base_canonical[:num_base_owned])
            self._have_midpoints = True
        base_of = self.base_cells(mesh)
        owners = _base_owners(comm, self._midpoints, base_of, particles, self.num_base_cells, method=method,
                              particle_weight=particle_weight)
        rounds = self.chain.below(mesh, self.base) if self.keep_levels and self.curved is None else None
        levels = [mesh_piece(level, owners[self.base_cells(level)]) for level in (rounds or ())[1:]]  # nested
        canonical = self.base_canonical[:num_base_owned]
        base_piece = mesh_piece(self.base, owners[canonical], canonical)
        created = create_mesh_from_piece(comm, base_piece, self.new_domain())
        self.base, self.base_canonical = created.mesh, created.canonical
        if self.manifold is not None:
            self.manifold.fit(self.base)
        # The refined mesh is redistributed as it is, not rebuilt from the new base: DOLFINx 0.5's
        # refinement of a repartitioned base with marks computed on another partition gave
        # inconsistent facet ownership (interior facets lost between ranks) in our tests.
        piece = mesh_piece(mesh, owners[base_of])
        self.recipe = MeshRecipe(base_piece, [], piece, levels)
        return self.chain.create(mesh.comm,  # not ``comm``: the old base is gone, and its communicator
                                 self.recipe, self.base, self.new_domain, self.mesh_domain(),
                                 nested=self.curved is None)

    def new_domain(self) -> ufl.Mesh:
        """A new UFL domain for a mesh to create (DOLFINx ties each domain object to one mesh)."""
        return ufl.Mesh(self._element)

    def replay(self, recipe: MeshRecipe, /, *, base: bool = True) -> dolfinx.mesh.Mesh:
        """Make the base and the mesh of ``recipe`` again (collective; bit for bit on the ranks
        it was recorded on). The hierarchy then holds that base. ``base=False``: the hierarchy's
        base already is the recipe's (made again by an earlier call), only the mesh is made."""
        if recipe.base is not None and base:
            created = create_mesh_from_piece(self.base.comm, recipe.base, self.new_domain())
            self.base, self.base_canonical = created.mesh, created.canonical
            if self.manifold is not None:
                self.manifold.fit(self.base)
        self.recipe = recipe
        if recipe.mesh is not None:
            return self.chain.create(self.base.comm, recipe, self.base, self.new_domain, self.mesh_domain(),
                                     nested=self.curved is None)
        mesh = self.base
        for marked in recipe.rounds:
            mesh = self._refine(mesh, marked)
        return self.curve(mesh)

    def _refine(self, mesh: dolfinx.mesh.Mesh, marked: npt.NDArray[np.int32] | None) -> dolfinx.mesh.Mesh:
        """One refinement round: the marked local cells (None: every cell), each new cell on the
        rank of its parent, with a facet ghost layer (collective;
        :func:`fembase.distribute.refine_on_ranks`)."""
        return self.chain.add(mesh, refine_on_ranks(mesh, marked))

    def levels(self, mesh: dolfinx.mesh.Mesh, /) -> npt.NDArray[np.int32]:
        """Refinement level of each owned cell, shape=(num_owned_cells,), int32."""
        num_owned = mesh.topology.index_map(self.tdim).size_local
        straight = self.curved.straight_of(mesh) if self.curved is not None else None
        if straight is not None:
            return self.levels(straight[0])[straight[1]]
        # Against the volume of each cell's own base cell: the base cells of an unstructured
        # (gmsh) mesh differ in volume by more than a factor 2^tdim in 3D.
        reference = np.full(num_owned, self.base_volume)
        parent = self._local_base_cells(mesh)
        known = parent >= 0
        reference[known] = self._base_volumes()[parent[known]]
        ratio = reference / _simplex_volumes(mesh, num_owned, self.manifold)
        return np.floor(np.log2(ratio) / self.tdim + 1e-6).astype(np.int32)

    def uniform(self, level: int, /) -> dolfinx.mesh.Mesh:
        """The base mesh refined uniformly ``level`` times (collective)."""
        mesh = self.base
        for _ in range(level):
            mesh = self._refine(mesh, None)
        self.recipe = MeshRecipe(self.recipe.base, [None] * level)
        return self.curve(mesh)

    def rebuild(self, old: dolfinx.mesh.Mesh, wanted: npt.NDArray[np.int32], /, *,
                locator: PointEvaluator | None = None) -> dolfinx.mesh.Mesh:
        """A mesh refined from the base so each cell reaches the wanted level of ``old`` at its midpoint.

        Args:
            old: The current mesh (any partition: points not found on this rank are looked up on all ranks).
            wanted: Wanted level per owned cell of ``old``, shape=(num_owned_cells of old,).
            locator: A :class:`PointEvaluator` of ``old`` to reuse (built here if omitted).

        Collective.
        """
        # A curved mesh is searched through its straight cells (affine maps, straight midpoints):
        # a straight midpoint mapped by the manifold need not lie in the P2 cell that interpolates
        # the map, and near a facet it would take a neighbour's level.
        if self.curved is not None and coordinate_map(old).degree > 1:
            old, wanted = self.curved.to_straight(old, wanted)
            locator = None
        if locator is None or locator.mesh is not old:
            locator = PointEvaluator(old)
        wanted_local = _with_ghost_values(old, wanted)
        max_wanted = old.comm.allreduce(int(wanted.max(initial=0)), op=MPI.MAX)
        mesh = self.base
        rounds: list[npt.NDArray[np.int32] | None] = []
        for _ in range(max_wanted + 2):
            num_owned = mesh.topology.index_map(self.tdim).size_local
            cells = np.arange(num_owned, dtype=np.int32)
            midpoints = dolfinx.mesh.compute_midpoints(mesh, self.tdim, cells)
            # The largest wanted level among all old cells touching the midpoint: a midpoint on a
            # facet of the old mesh must not take whichever neighbour the local numbering lists
            # first, or the result would depend on the partition. After a repartition of the base
            # the old cells may live on other ranks: the query falls back to all ranks.
            # Candidates: the old cells of each midpoint's base cell (a midpoint lies inside its
            # base cell, so they hold every old cell containing it).
            target = locator.max_over_colliding(midpoints, wanted_local, default=0,
                                                candidates=self.candidates(old, mesh, cells))
            marked = cells[self.levels(mesh) < target]
            if mesh.comm.allreduce(marked.size, op=MPI.SUM) == 0:
                break
            rounds.append(marked)
            mesh = self._refine(mesh, marked)
        self.recipe = MeshRecipe(self.recipe.base, rounds)
        return self.curve(mesh)
