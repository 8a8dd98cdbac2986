"""The plastic strain rate as a mesh field, for the ``plastic_strain`` particle property.

``plastic_strain_rate = eps_II sum_l C_l [eta_yield,l < eta_viscous,l]``
(:meth:`convection.approximation.ViscosityLaw.plastic_strain_rate`): the second invariant of the
strain rate where a visco-plastic law yields, weighted by the volume fractions. It is interpolated
into the discontinuous space of degree ``k - 1`` of a P(k) velocity (where ``eps(u)`` lives) after
every Stokes solve; the particles integrate it over the next step (explicit Euler).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import dolfinx.fem
import ufl

from fembase.dolfinx_compat import function_space, interpolation_points

if TYPE_CHECKING:
    from convection.model import Model

__all__ = ["PlasticStrainRate"]


class PlasticStrainRate:
    """The field ``plastic_strain_rate`` of a model (rebuilt when the mesh or solver changes).

    Args:
        name: The field's name (the ``rate_field`` of the particle property).
    """

    def __init__(self, name: str = "plastic_strain_rate") -> None:
        self.name = name
        self.function: dolfinx.fem.Function | None = None
        self._expression: Any = None
        self._stokes: Any = None

    def update(self, model: "Model", fields: dict[str, Any], /) -> dolfinx.fem.Function:
        """Interpolate the field for the model's current flow (collective); returns it."""
        stokes = model.stokes
        if self._stokes is not stokes or self.function is None:
            law = stokes.approximation.viscosity_law
            if not law.yields:
                raise ValueError("particle property plastic_strain needs a material with a viscoplastic law "
                                 "(it accumulates strain where the material yields)")
            degree = max(stokes.degree - 1, 0)
            space = function_space(stokes.mesh, "DG", degree)
            self.function = dolfinx.fem.Function(space, name=self.name)
            T = model.T if model.T is not None else 0.0
            rate = law.plastic_strain_rate(T, model.fractions or None, u=stokes.u, p=stokes.p, fields=fields,
                                           x=ufl.SpatialCoordinate(stokes.mesh))
            self._expression = dolfinx.fem.Expression(rate, interpolation_points(space))
            self._stokes = stokes
        self.function.interpolate(self._expression)
        self.function.x.scatter_forward()
        return self.function
