"""The meshes a run's mesh is nested in, for geometric multigrid on fixed and adaptive meshes
(:class:`MeshLevels`).

A fixed box mesh of ``n`` cells per side nests in the boxes of ``n/2``, ``n/4``, ...
(:meth:`convection.geometry.domain.Domain.create_mesh_levels`). An adaptive mesh is refined from the
hierarchy's base mesh round by round at every adaptation (:meth:`convection.adapt.hierarchy.MeshHierarchy.rebuild`):
the meshes after each round are nested in the next, every cell on the rank of the coarser cell it
lies in, and the base nests in the boxes below it. A repartition moves these meshes with the base,
every cell with its base cell (:meth:`convection.adapt.hierarchy.MeshHierarchy.repartition`), so they
stay nested rank by rank; the boxes below the base do not (a box cell holds base cells that went
to several ranks) and are no levels after it: the base is the coarsest level then (its exact
solve is the multigrid's coarse solve). So the levels of an adaptive mesh are the boxes
below the base, the base and the meshes of the rounds that made it
(:class:`convection.adapt.hierarchy.RefinementChain`).

On a curved domain (a shell or an annulus: :class:`convection.adapt.hierarchy.CurvedMeshes`) the
refinement rounds refine straight-sided meshes and the manifold curves what the run gets. The levels
are the straight rounds' meshes (or the straight base) curved by the same manifold: quadratic cells
whose boundary nodes lie on the circles or spheres. Curved levels are not nested as point sets (a
coarse quadratic face interpolates the sphere; a fine node on the sphere may lie just outside
it), but their straight meshes are: a node of a finer level is taken back to its straight position
by the manifold (``Phi^-1``) and found in the straight cell of the coarser level; the prolongation
evaluates the coarse basis at that reference point (:meth:`MeshLevels.locate`), i.e. it maps
parameter space to parameter space. Measured on the adaptive 3D shell (configs/shell_adaptive.yaml
at gmsh size 0.8, repartitioned every 2 steps, 2 ranks): 17-22 iterations a step against
BoomerAMG's 35-45, the same vrms to 1e-6. A fixed shell with the multigrid is a hierarchy too: its
base is gmsh's shell at a coarser size and its mesh the base refined uniformly
(:meth:`convection.geometry.shell.ShellDomain.mesh_levels`), so its levels are those rounds' meshes.

A round that refines a small region leaves a mesh hardly coarser than the next: a multigrid level
that costs a smoothing sweep over nearly the whole mesh and corrects little. Such rounds are
skipped: going from the finest mesh down, a mesh becomes the next level only when it has at most
:data:`MAX_RATIO` times the cells of the last level kept (the meshes stay nested: a mesh nests in
every coarser one of its chain). Uniform refinement coarsens by 1/8 (3D) and 1/4 (2D) a level.
Measured on the 3D thick layer (8^3 base, adaptivity.max_level 2, adapted every 2 steps, 2 ranks):
after the adaptation to 39 543 cells the chain was 3072 -> 9226 -> 33 786 -> 39 543 cells; with
the 33 786-cell round skipped 21, 21, 15 iterations a step, with every round a level 22, 21, 14,
at 1.6 times the solve time (17 against 28 s over the 5 steps, one run each, both beside a
long run on the same cores; BoomerAMG: 32, 30, 31).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

import dolfinx.fem
import dolfinx.mesh

from convection.adapt.hierarchy import MeshHierarchy
from fembase.dolfinx_compat import geometry_dofmap
from fembase.geometry import CellGeometry
from fembase.location import Located
from fembase.multigrid import owned_nodes

__all__ = ["MAX_RATIO", "STRAIGHT_SLACK", "MeshLevels", "coarsening_levels"]

MAX_RATIO = 0.5
"""A coarser mesh becomes a multigrid level when it has at most this fraction of the cells of the
next finer level."""


def _cells(mesh: dolfinx.mesh.Mesh) -> int:
    return mesh.topology.index_map(mesh.topology.dim).size_global


def coarsening_levels(meshes: Sequence[dolfinx.mesh.Mesh], /, *, ratio: float = MAX_RATIO
                      ) -> tuple[dolfinx.mesh.Mesh, ...]:
    """Of nested ``meshes`` (coarse to fine, the last the finest), those a multigrid takes as levels
    (module docstring), coarse to fine: the finest always, the coarsest when it has fewer cells
    (a repartition of an unrefined mesh leaves its base with as many)."""
    if not meshes:
        return ()
    kept = [meshes[-1]]
    for mesh in reversed(meshes[:-1]):
        if _cells(mesh) <= ratio * _cells(kept[-1]):
            kept.append(mesh)
    if kept[-1] is not meshes[0] and _cells(meshes[0]) < _cells(kept[-1]):
        kept.append(meshes[0])
    return tuple(reversed(kept))


def _nearest_cells(straight: dolfinx.mesh.Mesh, points: npt.NDArray[np.float64], /
                   ) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.float64]]:
    """The owned straight simplex each point is deepest in (largest smallest barycentric
    coordinate, at least ``-STRAIGHT_SLACK``; else -1) and its reference point; by every owned
    cell's affine map (for the few points the tree search misses: O(points x cells))."""
    tdim = straight.topology.dim
    num_owned = straight.topology.index_map(tdim).size_local
    x = straight.geometry.x[geometry_dofmap(straight)[:num_owned, : tdim + 1]][:, :, :tdim]  # (cells, tdim+1, tdim)
    inverse = np.linalg.inv(np.swapaxes(x[:, 1:] - x[:, :1], 1, 2))  # (cells, tdim, tdim)
    cells = np.full(len(points), -1, dtype=np.int32)
    xref = np.zeros((len(points), tdim))
    for i, point in enumerate(points[:, :tdim]):
        ref = np.einsum("cij,cj->ci", inverse, point - x[:, 0])
        depth = np.minimum(1.0 - ref.sum(axis=1), ref.min(axis=1))
        best = int(np.argmax(depth)) if num_owned else -1
        if best >= 0 and depth[best] >= -STRAIGHT_SLACK:
            cells[i], xref[i] = best, ref[best]
    return cells, xref


STRAIGHT_SLACK = 1e-4
"""How far outside its straight cell (barycentric) a curved level's node taken back by the
manifold may be found (:meth:`MeshLevels.locate`): ``Phi^-1`` of a node on a circle or sphere
comes back within ~5e-6 of the straight boundary facet it belongs on, sometimes just outside."""


class MeshLevels:
    """The meshes coarser than a run's mesh that it is nested in, coarse to fine (what
    :class:`convection.solvers.stokes.solver.StokesSolver` takes as ``coarse_meshes``).

    Args:
        below: The meshes the base mesh is nested in, coarse to fine, without the base
            (:meth:`convection.geometry.domain.Domain.create_mesh_levels` without its last).
        base: The base mesh.
        hierarchy: The hierarchy the run's meshes are refined from (adaptivity), or None: a fixed
            mesh, the base.
    """

    def __init__(self, below: Sequence[dolfinx.mesh.Mesh], base: dolfinx.mesh.Mesh,
                 hierarchy: MeshHierarchy | None = None, /) -> None:
        self.below, self.base, self.hierarchy = tuple(below), base, hierarchy
        # curved level -> (its straight mesh, the curved owned cell of each straight owned cell)
        self._straight: dict[dolfinx.mesh.Mesh, tuple[dolfinx.mesh.Mesh, npt.NDArray[np.int32]]] = {}

    def __call__(self, mesh: dolfinx.mesh.Mesh, /) -> tuple[dolfinx.mesh.Mesh, ...]:
        """The levels below ``mesh``, coarse to fine (collective: cell counts).

        A mesh the hierarchy's last rebuild did not make (a checkpoint's, made again on another
        rank count) has the base as its next level until the next adaptation. A curved mesh
        (a hierarchy with a manifold) has the curved meshes of the straight levels below its
        straight mesh (:meth:`locate` finds nodes in them).

        Raises:
            ValueError: No hierarchy and ``mesh`` is not the base.
        """
        if mesh is self.base:
            return coarsening_levels((*self.below, mesh))[:-1]
        hierarchy = self.hierarchy
        if hierarchy is None:
            raise ValueError("the multigrid's levels: the mesh was not refined from the base mesh")
        if hierarchy.curved is not None:
            return self._curved_levels(mesh, hierarchy)
        # A repartition moved the base: the boxes below it no longer nest in it rank by rank.
        below = self.below if hierarchy.base is self.base else ()
        # The rounds of the last rebuild, or the meshes a repartition moved with the base
        # (MeshHierarchy.keep_levels).
        rounds = hierarchy.chain.below(mesh, hierarchy.base)
        if rounds is None:
            # Neither: a checkpoint's mesh made again on another rank count. It is still refined
            # from the base, each cell on its base cell's rank: the base is its next level until
            # the next adaptation.
            rounds = (hierarchy.base,)
        return coarsening_levels((*below, *rounds, mesh))[:-1]

    def _curved_levels(self, mesh: dolfinx.mesh.Mesh, hierarchy: MeshHierarchy, /) -> tuple[dolfinx.mesh.Mesh, ...]:
        """The levels of a curved mesh: the straight levels below its straight mesh (the refinement
        rounds, or the base), each curved by the manifold (collective)."""
        assert hierarchy.curved is not None and hierarchy.manifold is not None
        straight, _ = hierarchy.curved.straight_view(mesh)
        rounds = hierarchy.chain.below(straight, hierarchy.base)
        kept = coarsening_levels((*(rounds if rounds is not None else (hierarchy.base,)), straight))[:-1]
        self._straight = {}
        levels = []
        for level in kept:
            curved = hierarchy.manifold.curve(level)
            # curve() keeps each cell on its rank, the straight owned order as input order
            num_owned = curved.topology.index_map(curved.topology.dim).size_local
            offset = curved.comm.exscan(num_owned) or 0
            straight_of = np.asarray(curved.topology.original_cell_index, dtype=np.int64)[:num_owned] - offset
            curved_of = np.empty(num_owned, dtype=np.int32)
            curved_of[straight_of] = np.arange(num_owned, dtype=np.int32)
            self._straight[curved] = (level, curved_of)
            levels.append(curved)
        return tuple(levels)

    def locate(self, coarse: dolfinx.mesh.Mesh, fine: dolfinx.fem.FunctionSpace, /) -> Located | None:
        """Where the owned nodes of ``fine`` lie in the curved level ``coarse`` (not collective):
        each node taken back to the straight mesh by the manifold (``Phi^-1``, exact to
        round-off), found among the owned straight cells of the level (every owned node lies in
        the closure of an owned fine cell, inside an owned coarse cell of its rank) and given the
        curved cell made from that straight cell, with the same reference point: the coarse
        function at the fine node's place in the coarse cell's parameter space. None: a level of
        a straight mesh (the prolongation looks for nodes itself)."""
        if coarse not in self._straight:
            return None
        straight, curved_of = self._straight[coarse]
        manifold = self.hierarchy.manifold if self.hierarchy is not None else None
        assert manifold is not None, "curved levels come from a hierarchy with a manifold"
        points = manifold.straight_points(owned_nodes(fine))
        found = CellGeometry(straight).locate(points, owned_only=True)
        cells, xref = found.cells.copy(), found.xref.copy()
        missing = np.flatnonzero(cells < 0)
        if missing.size:  # just outside (STRAIGHT_SLACK): the basis then extrapolates by as much
            cells[missing], xref[missing] = _nearest_cells(straight, points[missing])
        cells[cells >= 0] = curved_of[cells[cells >= 0]]
        return Located(cells, xref)
