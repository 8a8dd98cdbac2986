"""The ``elasticity`` statistics of a visco-elastic run (issue 48; :mod:`convection.physics.elastic_outputs`):

================================== ===================================================================
``elastic_stress_invariant_max``    the largest second invariant of the deviatoric stress (cell midpoints)
``elastic_stress_invariant_mean``   its volume average
``elastic_strain_rate_mean``        the volume average of the elastic strain rate's second invariant
``viscous_strain_rate_mean``        the same of the viscous strain rate
``elastic_share``                   ``int eps_el_II / int eps_II``: the elastic share of the deformation
================================== ===================================================================

By default with ``physics.elasticity.enabled`` (and refused without it); the stresses in
``units.stress``, the rates in ``units.strain_rate`` in a model with units.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import dolfinx.fem
import numpy as np
import ufl
from mpi4py import MPI

from convection.model.elastic_fields import flow_split
from convection.model.model import Model
from convection.physics.elastic_outputs import second_invariant
from convection.postprocess.base import Column, Forms, ModelFeatures, integral
from fembase.dolfinx_compat import evaluate_expression, function_space, interpolation_points

__all__ = ["ElasticityStatistics"]


class ElasticityStatistics(Column):
    """The stress and the split of the deformation of a visco-elastic flow (module docstring)."""

    name: ClassVar[str] = "elasticity"
    description: ClassVar[str] = ("largest and mean second invariant of the deviatoric stress, mean elastic and "
                                  "viscous strain rates, and the elastic share of the deformation")
    columns = ("elastic_stress_invariant_max", "elastic_stress_invariant_mean", "elastic_strain_rate_mean",
               "viscous_strain_rate_mean", "elastic_share")
    quantities: ClassVar[Mapping[str, str]] = {
        "elastic_stress_invariant_max": "stress", "elastic_stress_invariant_mean": "stress",
        "elastic_strain_rate_mean": "strain_rate", "viscous_strain_rate_mean": "strain_rate"}

    def __init__(self) -> None:
        self._forms = Forms()
        self._midpoints: Any = None

    @classmethod
    def missing(cls, features: ModelFeatures) -> str | None:
        return None if features.elasticity else "needs elasticity (physics.elasticity.enabled: true)"

    @classmethod
    def by_default(cls, model: Model) -> bool:
        return model.stokes.discretisation.elasticity is not None

    def _build(self, model: Model) -> dict[str, Any]:
        split = flow_split(model.flow())
        invariants = {name: second_invariant(tensor) for name, tensor in
                      (("stress", split.stress), ("elastic", split.elastic), ("viscous", split.viscous),
                       ("total", split.total))}
        dx = ufl.dx(domain=model.mesh, metadata={"quadrature_degree": 2 * model.stokes.degree})
        forms = {name: dolfinx.fem.form(value * dx) for name, value in invariants.items()}
        forms["volume"] = dolfinx.fem.form(dolfinx.fem.Constant(model.mesh, 1.0) * dx)
        self._midpoints = dolfinx.fem.Expression(invariants["stress"],
                                                 interpolation_points(function_space(model.mesh, "DG", 0)))
        return forms

    def __call__(self, model: Model, /) -> dict[str, float]:
        forms = self._forms.get(model, lambda: self._build(model))
        mesh = model.mesh
        owned = np.arange(mesh.topology.index_map(mesh.topology.dim).size_local, dtype=np.int32)
        values = np.asarray(evaluate_expression(self._midpoints, mesh, owned))
        largest = mesh.comm.allreduce(float(values.max(initial=-np.inf)), op=MPI.MAX)
        volume = integral(model, forms["volume"])
        means = {name: integral(model, forms[name]) / volume for name in ("stress", "elastic", "viscous", "total")}
        return {"elastic_stress_invariant_max": largest, "elastic_stress_invariant_mean": means["stress"],
                "elastic_strain_rate_mean": means["elastic"], "viscous_strain_rate_mean": means["viscous"],
                "elastic_share": means["elastic"] / means["total"] if means["total"] > 0.0 else 0.0}
