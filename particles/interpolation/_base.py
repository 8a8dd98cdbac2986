"""Shared pieces of the particle-to-mesh interpolators: stats, target space, samples, output."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple, Protocol

import basix
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.fem
import dolfinx.la

from fembase.dolfinx_compat import SCATTER_ADD, cell_dofmap
from particles.parallel.ghosts import GhostExchange, ghost_exchange_for
from particles.interpolation.fill import fill_cells
from particles.storage.swarm import Swarm

__all__ = [
    "InterpolationStats",
    "Interpolator",
    "InterpolatorContext",
    "Samples",
    "TargetSpace",
    "cell_means",
    "gather_samples",
    "property_values",
    "write_result",
    "write_with_cell_means",
]


@dataclass(frozen=True)
class InterpolationStats:
    """What one interpolation did.

    Attributes:
        method: Registered name of the interpolator.
        empty_cells: Owned cells whose value came from the empty-cell rule (no particle in reach).
        filled_dofs: Owned dofs of the target set by the empty-cell rule.
        fill_rounds: Rounds of the outward filling (0 if nothing was empty anywhere).
        ghost_particles: Ghost particles received and used on this rank.
        global_empty_cells, global_filled_dofs, global_ghost_particles: Sums over all ranks.
    """

    method: str
    empty_cells: int
    filled_dofs: int
    fill_rounds: int
    ghost_particles: int
    global_empty_cells: int
    global_filled_dofs: int
    global_ghost_particles: int


class InterpolatorContext(NamedTuple):
    """What an interpolator is made from beside its settings: nothing yet (the swarm, the property
    and the target come with every call); the family's ``build(settings, context)`` takes it so that
    an interpolator that needs more (the mesh, a dimension) adds a field here."""


class Interpolator(Protocol):
    """A particle-to-mesh interpolator (:class:`fembase.registry.Plugin`): made by
    ``build(settings, context)`` from its ``Settings``, with a collective call."""

    name: ClassVar[str]
    description: ClassVar[str]
    Settings: ClassVar[type]
    discontinuous: ClassVar[bool]
    """Its fields are cell-wise (a DG space of the tracked fields' degree), not continuous."""
    target_degree: ClassVar[int | None]
    """The degree its (DG) targets must have (None: any it supports)."""
    settings: Any

    @classmethod
    def build(cls, settings: Any, context: InterpolatorContext, /) -> Interpolator: ...

    def interpolate(self, swarm: Swarm, property_name: str, target: dolfinx.fem.Function, /, *,
                    component: int | None = None) -> InterpolationStats: ...


class TargetSpace:
    """What the interpolators need to know about a scalar Lagrange target space.

    Attributes:
        V: The function space.
        element: Its basix element.
        continuous: False for discontinuous Lagrange (DG) spaces.
        degree: Polynomial degree.
        dofs: Dofs of every owned cell, shape=(num_owned_cells, dofs_per_cell), int32.
        num_owned_dofs: Owned dofs (the first ones of the local numbering).
        num_local_dofs: Owned + ghost dofs.
    """

    def __init__(self, target: dolfinx.fem.Function, num_owned_cells: int, /) -> None:
        V = target.function_space
        self.V = V
        element = V.element.basix_element
        if element.family != basix.ElementFamily.P or element.map_type != basix.MapType.identity:
            raise ValueError("interpolation targets must be (discontinuous) Lagrange spaces")
        if V.dofmap.index_map_bs != 1 or V.dofmap.bs != 1 or element.value_size != 1:
            raise ValueError("interpolation targets must be scalar; interpolate one component at a time")
        if V.element.needs_dof_transformations:
            raise ValueError("targets that need dof transformations are not supported")
        self.element = element
        self.continuous = not element.discontinuous
        self.degree = int(element.degree)
        self.dofs = np.ascontiguousarray(cell_dofmap(V)[:num_owned_cells], dtype=np.int32)
        imap = V.dofmap.index_map
        self.num_owned_dofs = int(imap.size_local)
        self.num_local_dofs = int(imap.size_local + imap.num_ghosts)

    def dof_points(self) -> npt.NDArray[np.float64]:
        """Coordinates of the local dofs, shape=(num_local_dofs, gdim)."""
        gdim = self.V.mesh.geometry.dim
        return np.ascontiguousarray(self.V.tabulate_dof_coordinates()[:, :gdim])

    def require(self, method: str, *, continuous: bool | None = None, max_degree: int | None = None,
                degree: int | None = None) -> None:
        """Raise ValueError if this space is not one that ``method`` supports."""
        kind = "continuous" if self.continuous else "discontinuous"
        if continuous is not None and continuous != self.continuous:
            raise ValueError(f"{method} does not support {kind} targets")
        if max_degree is not None and self.degree > max_degree:
            raise ValueError(f"{method} supports targets of degree <= {max_degree}, got {self.degree}")
        if degree is not None and self.degree != degree:
            raise ValueError(f"{method} needs a target of degree {degree}, got {self.degree}")


@dataclass(frozen=True)
class Samples:
    """Particle values sorted by cell over the owned + halo cell index space.

    Attributes:
        ids: Global ids, shape=(m,), int64.
        x: Positions, shape=(m, gdim): the swarm's particles first, then ghost particles.
        values: The interpolated values, shape=(m,).
        offsets: CSR offsets over cells ``0 .. num_owned + num_halo``, shape=(num_cells + 1,), int64.
        num_owned_cells: Owned cells (the first cells of the index space).
        exchange: The ghost exchange of the mesh (None if ghosts were not exchanged).
        num_ghosts: Ghost particles included.
    """

    ids: npt.NDArray[np.int64]
    x: npt.NDArray[np.float64]
    values: npt.NDArray[np.float64]
    offsets: npt.NDArray[np.int64]
    num_owned_cells: int
    exchange: GhostExchange | None
    num_ghosts: int


def property_values(swarm: Swarm, name: str, component: int | None) -> npt.NDArray[np.float64]:
    """Column ``component`` of property ``name`` (size-1 properties need no component), shape=(n,)."""
    lay = swarm.layout(name)
    if component is None:
        if lay.size != 1:
            raise ValueError(f"property {name!r} has {lay.size} columns; pass component=")
        component = 0
    if not 0 <= component < lay.size:
        raise ValueError(f"component {component} out of range for property {name!r} of size {lay.size}")
    return np.ascontiguousarray(swarm.properties[:, lay.start + component])


def gather_samples(swarm: Swarm, name: str, component: int | None, *, ghosts: bool) -> Samples:
    """The swarm's values of ``name`` and, if ``ghosts``, those of the halo cells (collective then)."""
    values = property_values(swarm, name, component)
    n_owned = swarm.num_owned_cells
    if not ghosts:
        return Samples(swarm.ids, swarm.x, values, swarm.offsets.copy(), n_owned, None, 0)
    exchange = ghost_exchange_for(swarm.mesh)
    g = exchange.exchange(swarm, [name])
    col = 0 if component is None else component
    counts = np.bincount(g.cells - n_owned, minlength=exchange.num_halo_cells)
    offsets = np.concatenate([swarm.offsets, swarm.offsets[-1] + np.cumsum(counts)]).astype(np.int64)
    x = np.concatenate([swarm.x, g.x])
    v = np.concatenate([values, g.values[:, col]])
    return Samples(np.concatenate([swarm.ids, g.ids]), x, v, offsets, n_owned, exchange, g.num_particles)


def cell_means(swarm: Swarm, values: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    """Arithmetic mean of ``values`` (shape=(n,)) over each owned cell's particles, and whether it has any."""
    counts = np.diff(swarm.offsets)
    sums = np.bincount(swarm.cells, weights=values, minlength=swarm.num_owned_cells)
    known = counts > 0
    return np.where(known, sums / np.where(known, counts, 1), 0.0), known


def write_result(swarm: Swarm, space: TargetSpace, target: dolfinx.fem.Function, method: str, *,
                 num: npt.NDArray[np.float64], den: npt.NDArray[np.float64],
                 cell_values: npt.NDArray[np.float64], cell_known: npt.NDArray[np.bool_],
                 ghost_particles: int) -> InterpolationStats:
    """Finish an interpolation: divide, fill empty dofs and cells, write ``target`` (collective).

    Dof values are ``num / den`` where ``den > 0``. For continuous targets ``num`` and ``den`` hold
    local (owned + ghost dof) partial sums over this rank's cells and are summed over ranks by a
    reverse scatter first. Dofs with ``den == 0`` take the filled cell values (see
    :func:`particles.interpolation.fill.fill_cells`): in a DG target the value of their cell, in
    a continuous one the average over the cells around the dof.

    Args:
        num, den: Weighted sums per local dof, shape=(num_local_dofs,).
        cell_values: A representative value per owned cell, shape=(num_owned_cells,), used only
            for filling (valid where ``cell_known``).
        cell_known: Whether the cell had particles in reach, shape=(num_owned_cells,).
    """
    comm = swarm.comm
    n_owned = swarm.num_owned_cells
    exchange = ghost_exchange_for(swarm.mesh)
    filled, rounds = fill_cells(exchange, cell_values, cell_known)
    if space.continuous:
        imap = space.V.dofmap.index_map
        sums = dolfinx.la.vector(imap, 4)
        table = np.zeros((space.num_local_dofs, 4))
        table[:, 0], table[:, 1] = num, den
        flat_dofs = space.dofs.reshape(-1)
        table[:, 2] = np.bincount(flat_dofs, weights=np.repeat(filled, space.dofs.shape[1]),
                                  minlength=space.num_local_dofs)
        table[:, 3] = np.bincount(flat_dofs, minlength=space.num_local_dofs)
        sums.array[:] = table.reshape(-1)
        sums.scatter_reverse(SCATTER_ADD)
        t = sums.array.reshape(-1, 4)[: space.num_owned_dofs]
        empty = ~(t[:, 1] > 0)
        values = np.where(empty, t[:, 2] / np.where(t[:, 3] > 0, t[:, 3], 1.0), t[:, 0] / np.where(empty, 1.0, t[:, 1]))
        target.x.array[: space.num_owned_dofs] = values
        filled_dofs = int(np.count_nonzero(empty))
    else:
        dofs = space.dofs
        d_num, d_den = num[dofs], den[dofs]
        empty = ~(d_den > 0)
        values = np.where(empty, filled[:, None], d_num / np.where(empty, 1.0, d_den))
        target.x.array[dofs.reshape(-1)] = values.reshape(-1)
        filled_dofs = int(np.count_nonzero(empty))
    target.x.scatter_forward()
    empty_cells = int(np.count_nonzero(~cell_known[:n_owned]))
    local = np.array([empty_cells, filled_dofs, ghost_particles], dtype=np.int64)
    totals = comm.allreduce(local, op=MPI.SUM)
    return InterpolationStats(method, empty_cells, filled_dofs, rounds, ghost_particles,
                              int(totals[0]), int(totals[1]), int(totals[2]))


def write_with_cell_means(swarm: Swarm, space: TargetSpace, target: dolfinx.fem.Function, method: str, *,
                          num: npt.NDArray[np.float64], den: npt.NDArray[np.float64],
                          values: npt.NDArray[np.float64], ghost_particles: int = 0) -> InterpolationStats:
    """:func:`write_result` whose empty-cell rule starts from the arithmetic mean of this rank's
    particle ``values`` (shape=(num_particles,)) in each owned cell (collective)."""
    means, known = cell_means(swarm, values)
    return write_result(swarm, space, target, method, num=num, den=den, cell_values=means, cell_known=known,
                        ghost_particles=ghost_particles)
