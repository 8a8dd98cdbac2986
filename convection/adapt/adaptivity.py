"""Adaptive mesh refinement and coarsening: where the mesh should be finer or coarser
(:func:`kelly_indicator`, :func:`wanted_levels`) and when (:class:`Adaptivity`); the new mesh is
rebuilt from the coarse base mesh by :class:`convection.adapt.hierarchy.MeshHierarchy`.

Indicator (Kelly-type): for a continuous field f, ``eta_K^2 = sum over interior facets F of K of
h_F * integral_F [df/dn]^2``; for a discontinuous field (e.g. DG0 composition), ``[f]^2`` replaces
the jump of the normal derivative. Each field's indicator is scaled by its global maximum and the
largest scaled value is used. The ``refine_fraction`` of cells with the largest indicator go up one
level, the ``coarsen_fraction`` with the smallest go down one, within [min_level, max_level].

Geometric bounds (:class:`LevelBounds`): ``min_level_where`` and ``max_level_where`` are expressions
of position and time ``t`` (config expressions, with the config's constants) giving the coarsest and
finest level a cell may have, evaluated at the cell's midpoint (rounded down); the indicator's
choice is clipped to them, and they to [min_level, max_level]. So ``min_level_where: "3*(z > 0.9)"``
keeps the top tenth at level 3 whatever the indicator says; with both fractions 0 the mesh follows
the expressions alone.
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.fem
import dolfinx.la
import dolfinx.mesh
import ufl

from convection.adapt.hierarchy import MeshHierarchy
from convection.adapt.transfer import PointEvaluator
from convection.geometry.mesh import cell_diameter
from convection.expressions import Expression
from convection.schema import Names, param
from fembase.dolfinx_compat import SCATTER_ADD, cell_dofmap, function_space, is_discontinuous

__all__ = ["INDICATOR_FIELDS", "MAX_INITIAL_ROUNDS", "Adaptivity", "AdaptivitySettings", "LevelBounds",
           "kelly_indicator", "wanted_levels"]

INDICATOR_FIELDS: dict[str, str] = {
    "temperature": "the temperature",
    "composition": "every material fraction",
}
"""Registry of the fields that can drive the refinement indicator (name -> one-line description)."""


MAX_INITIAL_ROUNDS = 100
"""Most rounds of adapting the mesh to the initial condition (each rebuilds the mesh)."""


@dataclass(frozen=True)
class AdaptivitySettings:
    """The ``adaptivity`` config section: whether, when and how the mesh adapts (:class:`Adaptivity`)."""

    enabled: bool = param(False, help="refine and coarsen the mesh by an error indicator during the run")
    every: int = param(10, minimum=1, help="adapt every N steps")
    min_level: int = param(0, minimum=0, help="coarsest refinement level of a cell (0: the base mesh)")
    max_level: int = param(2, minimum=0, help="finest refinement level of a cell (each level halves the cell size)")
    refine_fraction: float = param(0.3, minimum=0.0, maximum=1.0, help="fraction of cells (by indicator) to refine")
    coarsen_fraction: float = param(0.3, minimum=0.0, maximum=1.0, help="fraction of cells to coarsen")
    initial_steps: int | None = param(None, minimum=0, maximum=MAX_INITIAL_ROUNDS,
                                      help="adapt this many times to the initial condition (default max_level - "
                                           "min_level)")
    fields: tuple[str, ...] = param(("temperature",), choices=Names(INDICATOR_FIELDS),
                                    help="fields whose Kelly error indicators (each normalised, summed) choose the "
                                         "cells")
    min_level_where: str | None = param(None, help="coarsest level by position and time: an expression of x, y, z, "
                                                   "t (rounded down at each cell's midpoint), e.g. \"3*(z > 0.9)\"")
    max_level_where: str | None = param(None, help="finest level by position and time, e.g. \"1 + 2*(x < 0.5)\"")

    def __post_init__(self) -> None:
        unknown = sorted(set(self.fields) - set(INDICATOR_FIELDS))
        if unknown:
            raise ValueError(f"unknown adaptivity fields {unknown}; valid: {list(INDICATOR_FIELDS)}")


def kelly_indicator(fields: Sequence[dolfinx.fem.Function], /) -> npt.NDArray[np.float64]:
    """Scaled Kelly-type indicator per owned cell, shape=(num_owned_cells,), values in [0, 1].

    Collective. Continuous fields use the jump of the normal derivative, DG fields the jump of
    the value (see the module docstring).
    """
    if not fields:
        raise ValueError("the refinement indicator needs at least one field")
    mesh = fields[0].function_space.mesh
    tdim = mesh.topology.dim
    num_owned = mesh.topology.index_map(tdim).size_local
    V0 = function_space(mesh, "DG", 0)
    w = ufl.TestFunction(V0)
    h = cell_diameter(mesh)
    n = ufl.FacetNormal(mesh)
    combined = np.zeros(num_owned)
    for f in fields:
        if is_discontinuous(f.function_space):
            integrand = ufl.avg(h) ** (1 - tdim) * ufl.jump(f) ** 2
        else:
            integrand = ufl.avg(h) * ufl.jump(ufl.grad(f), n) ** 2
        vec = dolfinx.fem.assemble_vector(dolfinx.fem.form(integrand * ufl.avg(w) * ufl.dS))
        vec.scatter_reverse(SCATTER_ADD)
        eta = np.sqrt(np.maximum(vec.array[cell_dofmap(V0).reshape(-1)[:num_owned]], 0.0))
        scale = mesh.comm.allreduce(float(eta.max(initial=0.0)), op=MPI.MAX)
        if scale > 0.0:
            combined = np.maximum(combined, eta / scale)
    return combined


def wanted_levels(
    indicator: npt.NDArray[np.float64], levels: npt.NDArray[np.int32], params: AdaptivitySettings, comm: MPI.Comm, /
) -> npt.NDArray[np.int32]:
    """Wanted level per owned cell from a global ranking of the indicator (collective).

    Args:
        indicator: Per owned cell, shape=(num_owned_cells,).
        levels: Current level per owned cell, shape=(num_owned_cells,).
        params: Fractions and level bounds.
        comm: The mesh communicator.
    """
    # Round to 9 significant digits relative to the (global) maximum before ranking: cells along a
    # straight interface share an indicator value, and round-off from a different partition (the
    # order of facet contributions) must not decide which of them cross the threshold.
    scale = comm.allreduce(float(np.abs(indicator).max(initial=0.0)), op=MPI.MAX)
    if scale > 0.0:
        indicator = np.round(indicator / scale, 9)
    everything = np.concatenate(comm.allgather(indicator))
    wanted = levels.astype(np.int32).copy()
    if everything.size:
        refine_at = np.quantile(everything, 1.0 - params.refine_fraction) if params.refine_fraction > 0 else np.inf
        coarsen_at = np.quantile(everything, params.coarsen_fraction) if params.coarsen_fraction > 0 else -np.inf
        refine = (indicator > refine_at) & (indicator > 0.0)
        coarsen = (indicator <= coarsen_at) & ~refine
        wanted[refine] += 1
        wanted[coarsen] -= 1
    return np.clip(wanted, params.min_level, params.max_level).astype(np.int32)


class LevelBounds:
    """Coarsest and finest level by position and time (module docstring).

    Args:
        lowest, highest: Expression texts (None: no bound).
        constants: Named constants of the expressions (the config's); ``t`` is added, set to the
            time of each evaluation.
        gdim: Geometric dimension.
    """

    def __init__(self, lowest: str | None, highest: str | None, /, *, constants: dict[str, float] | None = None,
                 gdim: int = 2) -> None:
        names = {**(constants or {}), "t": 0.0}
        self.expressions = [None if text is None else Expression(text, constants=names, gdim=gdim)
                            for text in (lowest, highest)]

    def clip(self, wanted: npt.NDArray[np.int32], midpoints: npt.NDArray[np.float64], time: float, /
             ) -> npt.NDArray[np.int32]:
        """``wanted`` clipped to the bounds at ``midpoints`` (shape=(n, 3)) at ``time``."""
        out = wanted.astype(np.int32).copy()
        for i, expression in enumerate(self.expressions):
            if expression is None or not len(out):
                continue
            expression.constants["t"] = float(time)
            bound = np.floor(expression(np.ascontiguousarray(midpoints.T))).astype(np.int64)
            out = np.maximum(out, bound) if i == 0 else np.minimum(out, bound)
        return out.astype(np.int32)


class Adaptivity:
    """The mesh-adaptivity component of a model: every ``params.every`` steps, a new mesh rebuilt
    from the base mesh with one level more where the indicator of the chosen fields is largest and
    one less where it is smallest (see the module docstring).

    Args:
        hierarchy: The base mesh the adapted meshes are refined from (shared with load balancing).
        params: Levels, fractions, interval and the fields that drive the indicator
            (``"temperature"`` and/or ``"composition"``, every material fraction; the model hands
            their Functions to :meth:`new_mesh`).
    """

    def __init__(self, hierarchy: MeshHierarchy, params: AdaptivitySettings = AdaptivitySettings(), /, *,
                 bounds: LevelBounds | None = None) -> None:
        self.hierarchy = hierarchy
        self.params = params
        self.fields = params.fields
        self.bounds = bounds

    def due(self, timestep: int, /) -> bool:
        """Whether the mesh is adapted after step ``timestep``."""
        return timestep % self.params.every == 0

    def new_mesh(self, mesh: dolfinx.mesh.Mesh, fields: Sequence[dolfinx.fem.Function], /, *,
                 locator: PointEvaluator | None = None, time: float = 0.0) -> dolfinx.mesh.Mesh:
        """The adapted mesh for the indicator of ``fields`` on ``mesh`` within the level bounds at
        ``time`` (collective); ``locator``: a :class:`PointEvaluator` of ``mesh`` to reuse."""
        indicator = kelly_indicator(fields)
        wanted = wanted_levels(indicator, self.hierarchy.levels(mesh), self.params, mesh.comm)
        if self.bounds is not None:
            owned = np.arange(mesh.topology.index_map(mesh.topology.dim).size_local, dtype=np.int32)
            midpoints = dolfinx.mesh.compute_midpoints(mesh, mesh.topology.dim, owned)
            wanted = np.clip(self.bounds.clip(wanted, midpoints, time), self.params.min_level,
                             self.params.max_level).astype(np.int32)
        return self.hierarchy.rebuild(mesh, wanted, locator=locator)

    def initial_mesh(self, fields_on: Callable[[dolfinx.mesh.Mesh], Sequence[dolfinx.fem.Function]], /, *,
                     rounds: int | None = None) -> dolfinx.mesh.Mesh:
        """A mesh adapted to the initial condition (collective).

        Starts from the base mesh refined to ``min_level`` and adapts ``rounds`` times (default
        ``max_level - min_level``), each time to the fields that ``fields_on(mesh)`` sets from the
        initial condition on the current mesh.
        """
        mesh = self.hierarchy.uniform(self.params.min_level)
        if rounds is None:
            rounds = self.params.max_level - self.params.min_level
        for _ in range(rounds):
            mesh = self.new_mesh(mesh, fields_on(mesh))
        return mesh

