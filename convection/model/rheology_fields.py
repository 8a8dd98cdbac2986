"""Mesh fields of the rheology: the plastic strain rate (for the ``plastic_strain`` particle
property) and the viscosity (for output).

``plastic_strain_rate = eps_II sum_l C_l [eta_yield,l < eta_viscous,l]``
(:meth:`convection.physics.approximation.ViscosityLaw.plastic_strain_rate`): the second invariant of the
strain rate where a visco-plastic law yields, weighted by the volume fractions. It is interpolated
into the discontinuous space of degree ``k - 1`` of a P(k) velocity (where ``eps(u)`` lives) after
every Stokes solve; the particles integrate it over the next step (explicit Euler).

``viscosity``: the viscosity of the current flow (all laws, mixing and bounds), cell by cell at the
cell midpoints (DG0, cell data in ParaView), written with the fields.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable

import dolfinx.fem
import ufl

from fembase.dolfinx_compat import function_space, interpolation_points

if TYPE_CHECKING:
    from convection.model.model import Model

__all__ = ["ExpressionField", "PlasticStrainRate", "ViscosityField", "flow_viscosity"]


class ExpressionField:
    """A UFL expression of a model's flow interpolated into a discontinuous space, rebuilt when
    the model's Stokes solver (hence the mesh) changes.

    Args:
        name: The Function's name.
        expression: ``f(model, fields) -> UFL`` on the model's current mesh.
        degree: ``f(model) -> int``, the DG degree.
    """

    def __init__(self, name: str, expression: Callable[["Model", dict[str, Any]], Any],
                 degree: Callable[["Model"], int]) -> None:
        self.name = name
        self.function: dolfinx.fem.Function | None = None
        self._make = expression
        self._degree = degree
        self._expression: Any = None
        self._stokes: Any = None

    def update(self, model: "Model", fields: dict[str, Any], /) -> dolfinx.fem.Function:
        """Interpolate the field for the model's current flow (collective); returns it."""
        stokes = model.stokes
        if self._stokes is not stokes or self.function is None:
            space = function_space(stokes.mesh, "DG", self._degree(model))
            self.function = dolfinx.fem.Function(space, name=self.name)
            self._expression = dolfinx.fem.Expression(self._make(model, fields), interpolation_points(space))
            self._stokes = stokes
        self.function.interpolate(self._expression)
        self.function.x.scatter_forward()
        return self.function


def _plastic_rate(model: "Model", fields: dict[str, Any]) -> Any:
    stokes = model.stokes
    law = stokes.approximation.viscosity_law
    if not law.yields:
        raise ValueError("particle property plastic_strain needs a material with a viscoplastic law "
                         "(it accumulates strain where the material yields)")
    T = model.T if model.T is not None else 0.0
    return law.plastic_strain_rate(T, model.fractions or None, u=stokes.u, p=stokes.p, fields=fields,
                                   x=ufl.SpatialCoordinate(stokes.mesh))


def flow_viscosity(model: "Model", fields: dict[str, Any] | None = None) -> Any:
    """The model's viscosity as UFL at its current temperature, fractions, flow and rheology
    fields (``fields``; None: :meth:`convection.model.model.Model.rheology_fields`)."""
    if fields is None:
        fields = model.rheology_fields()
    stokes = model.stokes
    T = model.T if model.T is not None else 0.0
    return stokes.discretisation.viscosity(T, model.fractions or None, {"u": stokes.u, "p": stokes.p, "fields": fields})


class PlasticStrainRate(ExpressionField):
    """The field ``plastic_strain_rate`` of a model, DG(k-1) for a P(k) velocity."""

    def __init__(self, name: str = "plastic_strain_rate") -> None:
        super().__init__(name, _plastic_rate, lambda model: max(model.stokes.degree - 1, 0))


class ViscosityField(ExpressionField):
    """The field ``viscosity`` of a model, DG0 (its value at each cell's midpoint)."""

    def __init__(self, name: str = "viscosity") -> None:
        super().__init__(name, flow_viscosity, lambda model: 0)
