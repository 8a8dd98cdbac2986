"""The meshes a run's mesh is nested in, for geometric multigrid on fixed and adaptive meshes
(:class:`MeshLevels`).

A fixed box mesh of ``n`` cells per side nests in the boxes of ``n/2``, ``n/4``, ...
(:meth:`convection.geometry.domain.Domain.create_mesh_levels`). An adaptive mesh is refined from the
hierarchy's base mesh round by round at every adaptation (:meth:`convection.adapt.hierarchy.MeshHierarchy.rebuild`):
the meshes after each round are nested in the next, every cell on the rank of the coarser cell it
lies in, and the base nests in the boxes below it. So the levels of an adaptive mesh are the boxes
below the base, the base and the meshes of the rounds that made it
(:class:`convection.adapt.hierarchy.RefinementChain`).

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

import dolfinx.mesh

from convection.adapt.hierarchy import MeshHierarchy

__all__ = ["MAX_RATIO", "MeshLevels", "coarsening_levels"]

MAX_RATIO = 0.5
"""A coarser mesh becomes a multigrid level when it has at most this fraction of the cells of the
next finer level."""


def _cells(mesh: dolfinx.mesh.Mesh) -> int:
    return mesh.topology.index_map(mesh.topology.dim).size_global


def coarsening_levels(meshes: Sequence[dolfinx.mesh.Mesh], /, *, ratio: float = MAX_RATIO) -> tuple[dolfinx.mesh.Mesh, ...]:
    """Of nested ``meshes`` (coarse to fine, the last the finest), those a multigrid takes as levels
    (module docstring), coarse to fine, the finest and the coarsest always included."""
    if not meshes:
        return ()
    kept = [meshes[-1]]
    for mesh in reversed(meshes[:-1]):
        if _cells(mesh) <= ratio * _cells(kept[-1]):
            kept.append(mesh)
    if kept[-1] is not meshes[0]:
        kept.append(meshes[0])
    return tuple(reversed(kept))


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

    def __call__(self, mesh: dolfinx.mesh.Mesh, /) -> tuple[dolfinx.mesh.Mesh, ...]:
        """The levels below ``mesh``, coarse to fine (collective: cell counts).

        A mesh the hierarchy's last rebuild did not make (a checkpoint's, made again on another
        rank count) has the base as its next level until the next adaptation.

        Raises:
            ValueError: No hierarchy and ``mesh`` is not the base.
        """
        if mesh is self.base:
            return coarsening_levels((*self.below, mesh))[:-1]
        hierarchy = self.hierarchy
        if hierarchy is None:
            raise ValueError("the multigrid's levels: the mesh was not refined from the base mesh")
        # A repartition moved the base: the boxes below it no longer nest in it rank by rank.
        below = self.below if hierarchy.base is self.base else ()
        rounds = hierarchy.chain.below(mesh, hierarchy.base)
        if rounds is None:
            # Not refined by the hierarchy's last rebuild: a checkpoint's mesh made again on another
            # rank count (or a repartition's). It is still refined from the base, each cell on its
            # base cell's rank: the base is its next level until the next adaptation.
            rounds = (hierarchy.base,)
        return coarsening_levels((*below, *rounds, mesh))[:-1]
