"""The elastic outputs as mesh fields (issue 48, :mod:`convection.physics.elastic_outputs`): the
deviatoric stress (a tensor), its second invariant, the elastic and viscous strain rates (tensors)
and the elastic share of the deformation, at the cell midpoints (DG0, cell data in ParaView), for
the flow just solved. ``output.extra_fields`` chooses which the field output holds (null: all)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import dolfinx.fem

from convection.model.rheology_fields import ExpressionField, Flow, law_viscosity
from convection.physics.elastic_outputs import ELASTIC_OUTPUTS, ElasticSplit, elastic_split
from convection.solvers.stokes.solver import StokesSolver

__all__ = ["ElasticFields", "flow_split"]

_TENSORS = ("elastic_stress", "elastic_strain_rate", "viscous_strain_rate")


def flow_split(flow: Flow, /) -> ElasticSplit:
    """The stress and strain-rate split of ``flow`` (UFL; its solver must have elasticity)."""
    discretisation = flow.stokes.discretisation
    if discretisation.elasticity is None:
        raise ValueError("the flow has no elasticity (physics.elasticity.enabled: false)")
    return elastic_split(discretisation.elasticity, law_viscosity(flow), flow.fractions, discretisation.elastic_rate,
                         flow.fields, flow.stokes.u)


class ElasticFields:
    """The elastic outputs ``names`` (default: all of :data:`ELASTIC_OUTPUTS`) of a model's flow."""

    def __init__(self, names: Sequence[str] | None = None, /) -> None:
        unknown = [name for name in names or () if name not in ELASTIC_OUTPUTS]
        if unknown:
            raise ValueError(f"unknown elastic output {unknown[0]!r}; valid: {list(ELASTIC_OUTPUTS)}")
        self.names = tuple(ELASTIC_OUTPUTS if names is None else names)
        self._fields = {name: ExpressionField(name, self._expression(name), lambda s: 0, self._shape(name))
                        for name in self.names}

    @staticmethod
    def _expression(name: str) -> Any:
        return lambda flow: flow_split(flow).outputs()[name]

    @staticmethod
    def _shape(name: str) -> Any:
        def shape(stokes: StokesSolver) -> tuple[int, ...] | None:
            gdim = stokes.mesh.geometry.dim
            return (gdim, gdim) if name in _TENSORS else None
        return shape

    def update(self, flow: Flow, /) -> dict[str, dolfinx.fem.Function]:
        """The fields of ``flow`` by name (collective)."""
        return {name: field.update(flow) for name, field in self._fields.items()}
