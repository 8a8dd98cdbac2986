"""Mesh fields of the rheology (:class:`RheologyFields`): the particle fields the viscosity laws
read, the rates the particles integrate, and the viscosity (for output).

- The laws' fields (e.g. ``plastic_strain``) are particle properties averaged onto the mesh by the
  particle manager.
- The rates are declared by the rheology (:meth:`convection.physics.approximation.ViscosityLaw.rate_fields`):
  ``plastic_strain_rate = eps_II sum_l C_l [eta_yield,l < eta_viscous,l]``, the second invariant of
  the strain rate where a visco-plastic law yields, weighted by the volume fractions. Each is
  interpolated into the discontinuous space of degree ``k - 1`` of a P(k) velocity (where
  ``eps(u)`` lives) after every Stokes solve; the particles integrate it over the next step
  (explicit Euler). With elasticity (:mod:`convection.physics.elasticity`) the particles' ``elastic_stress``
  reads ``elastic_viscosity`` (``eta_ve``) and ``elastic_memory`` (``chi``) the same way, and the laws'
  fields include the stress components ``elastic_stress_xx``, ... (the old stress of the forms).
- ``viscosity``: the viscosity of the current flow (all laws, mixing and bounds), cell by cell at
  the cell midpoints (DG0, cell data in ParaView), written with the fields;
- ``strain_rate_II = sqrt(eps : eps / 2)`` and ``stress_II = 2 eta strain_rate_II``, the second
  invariants of the strain rate and of the deviatoric stress (ASPECT's convention), at the cell
  midpoints too, and with elasticity the outputs of ``output.extra_fields``
  (:mod:`convection.model.elastic_fields`);
- ``adiabatic_temperature`` and ``nonadiabatic_temperature`` (``T - T_ad``) of a compressible
  approximation (:mod:`convection.physics.compressible`);
- ``density``: the density anomaly ``rho' = sum_i Rb_i C_i - Ra T`` (in units of ``eta0 kappa /
  (g L^3)``: a model in physical units writes ``rho0 + rho' eta0 kappa / (g L^3)`` in kg/m^3,
  :mod:`convection.io.output_units`), at the cell midpoints.
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Callable
from typing import Any, Protocol

import dolfinx.fem
import ufl

from convection.physics.elasticity import stress_labels
from convection.solvers.stokes.solver import StokesSolver
from fembase.dolfinx_compat import function_space, interpolation_points
from particles.systems import ParticleSystems

__all__ = ["ExpressionField", "Flow", "RheologyFields", "StressFields", "flow_viscosity", "law_viscosity"]


class StressFields(Protocol):
    """The stress history as mesh fields (:class:`convection.model.elastic_stress.FieldStress`)."""

    @property
    def fields(self) -> dict[str, dolfinx.fem.Function]: ...


@dataclass(frozen=True)
class Flow:
    """What the rheology reads of a model now.

    Attributes:
        stokes: The flow solver (velocity, pressure, mesh, approximation).
        T: The temperature (a Function, or 0.0 without one).
        fractions: The material fractions (None without materials).
        fields: The particle fields the viscosity laws read, by name.
    """

    stokes: StokesSolver
    T: Any
    fractions: tuple[dolfinx.fem.Function, ...] | None
    fields: dict[str, dolfinx.fem.Function]


class ExpressionField:
    """A UFL expression of the flow interpolated into a discontinuous space, rebuilt when the flow
    solver (hence the mesh) changes.

    Args:
        name: The Function's name.
        expression: ``f(flow) -> UFL`` on the flow's current mesh.
        degree: ``f(stokes) -> int``, the DG degree.
        shape: The value shape (a tensor: ``(gdim, gdim)``); None: a scalar.
    """

    def __init__(self, name: str, expression: Callable[[Flow], Any], degree: Callable[[StokesSolver], int],
                 shape: Callable[[StokesSolver], tuple[int, ...] | None] = lambda s: None) -> None:
        self.name = name
        self._shape = shape
        self.function: dolfinx.fem.Function | None = None
        self._make = expression
        self._degree = degree
        self._expression: Any = None
        self._stokes: Any = None

    def update(self, flow: Flow, /) -> dolfinx.fem.Function:
        """Interpolate the field for ``flow`` (collective); returns it."""
        stokes = flow.stokes
        if self._stokes is not stokes or self.function is None:
            space = function_space(stokes.mesh, "DG", self._degree(stokes), shape=self._shape(stokes))
            self.function = dolfinx.fem.Function(space, name=self.name)
            self._expression = dolfinx.fem.Expression(self._make(flow), interpolation_points(space))
            self._stokes = stokes
        self.function.interpolate(self._expression)
        self.function.x.scatter_forward()
        return self.function


def flow_viscosity(flow: Flow, /) -> Any:
    """The viscosity as UFL at the flow's temperature, fractions, velocity, pressure and fields."""
    stokes = flow.stokes
    return stokes.discretisation.viscosity(flow.T, flow.fractions, {"u": stokes.u, "p": stokes.p,
                                                                     "fields": flow.fields})


def _phase(transition: Any) -> Callable[[Flow], Any]:
    def expression(flow: Flow) -> Any:
        stokes = flow.stokes
        depth = stokes.approximation.gravity.depth(ufl.SpatialCoordinate(stokes.mesh))
        return transition.phase(flow.T if not isinstance(flow.T, (int, float)) else ufl.as_ufl(float(flow.T)), depth)
    return expression


def _rate(name: str, builder: Callable[..., Any]) -> Callable[[Flow], Any]:
    def expression(flow: Flow) -> Any:
        stokes = flow.stokes
        trial = stokes.discretisation.elastic_trial(flow.fractions, flow.fields)  # visco-elasto-plastic (issue 48)
        return builder(flow.T, flow.fractions, u=stokes.u, p=stokes.p, fields=flow.fields,
                       x=ufl.SpatialCoordinate(stokes.mesh), **({} if trial is None else {"elastic": trial}))
    return expression


class RheologyFields:
    """The mesh fields of a model's rheology (see the module docstring).

    Args:
        stokes: The flow solver (its approximation's viscosity law declares the rates).
        particles: The particles (their properties ask for rates; they average the laws' fields),
            or None.
        stress: With ``physics.elasticity.stress: fields``, what holds the stress fields (its
            ``fields`` by label, :class:`convection.model.elastic_stress.FieldStress`); None: the
            particles' stress.

    Raises:
        ValueError: The particles ask for a rate the rheology does not provide.
    """

    def __init__(self, stokes: StokesSolver, particles: ParticleSystems | None, stress: StressFields | None = None,
                 /) -> None:
        self.particles = particles
        self.stress = stress
        law = stokes.approximation.viscosity_law
        declared = {**{name: _rate(name, builder) for name, builder in law.rate_fields().items()},
                    **_elastic_rates(stokes)}
        wanted = particles.rate_fields if particles is not None else ()
        unknown = [name for name in wanted if name not in declared]
        if unknown:
            raise ValueError(f"no mesh field {unknown[0]!r} for the particles to integrate; the rheology provides "
                             f"{', '.join(sorted(declared))}")
        self.rates = {name: ExpressionField(name, declared[name], lambda s: max(s.degree - 1, 0))
                      for name in wanted}
        self._viscosity = ExpressionField("viscosity", flow_viscosity, lambda s: 0)
        self._density = ExpressionField("density", _density_anomaly, lambda s: 0)
        self._invariants = (ExpressionField("strain_rate_II", _strain_rate_II, lambda s: 0),
                            ExpressionField("stress_II", lambda f: 2.0 * flow_viscosity(f) * _strain_rate_II(f),
                                            lambda s: 0))
        # the elastic outputs of a flow (issue 48; the factory sets ElasticFields.update)
        self.elastic: Callable[[Flow], dict[str, dolfinx.fem.Function]] | None = None
        self._phases = tuple(ExpressionField(f"phase_{t.name}", _phase(t), lambda s: s.degree)
                             for t in stokes.approximation.phases.transitions)
        self._adiabat = (ExpressionField("adiabatic_temperature", _adiabatic_temperature, lambda s: s.degree),
                         ExpressionField("nonadiabatic_temperature",
                                         lambda f: f.T - _adiabatic_temperature(f), lambda s: s.degree)
                         ) if stokes.approximation.dissipates else ()

    def law_fields(self, stokes: StokesSolver, /) -> dict[str, dolfinx.fem.Function]:
        """The mesh fields the viscosity laws read, by name: particle properties averaged onto the
        mesh (the particles' tracked fields, e.g. ``plastic_strain``), and the old elastic stress
        (the particles' or :attr:`stress`'s fields)."""
        stress = _elastic_stress_fields(stokes)
        names = (*stokes.approximation.viscosity_law.field_names, *(stress if self.stress is None else ()))
        out = {} if self.stress is None or not stress else dict(self.stress.fields)
        if not names:
            return out
        if self.particles is None:
            raise ValueError(f"the viscosity laws read the fields {list(names)}, which come from particles")
        return {name: self.particles.field(name) for name in names} | out

    def property_fields(self, rates: Callable[[], dict[str, dolfinx.fem.Function]], /
                        ) -> dict[str, dolfinx.fem.Function]:
        """The mesh fields for the particle properties' context: ``rates()`` with elasticity (what
        ``elastic_stress`` reads), else none (issue 48)."""
        return rates() if "elastic_memory" in self.rates else {}

    def update_rates(self, flow: Flow, /) -> None:
        """Interpolate the rates for the flow just solved (collective)."""
        for rate in self.rates.values():
            rate.update(flow)

    def rate_functions(self, flow: Flow | None, /) -> dict[str, dolfinx.fem.Function]:
        """The rates as of the last flow solve; ``flow`` (the current one, or None before any solve)
        computes them after a restart, which restores the flow without solving it (collective then)."""
        out = {}
        for name, rate in self.rates.items():
            if rate.function is None and flow is not None:
                rate.update(flow)
            if rate.function is not None:
                out[name] = rate.function
        return out

    def density(self, flow: Flow, /) -> dolfinx.fem.Function:
        """The density anomaly ``sum_i Rb_i C_i - Ra T`` of ``flow`` at the cell midpoints (DG0, in
        units of ``eta0 kappa / (g L^3)``; collective)."""
        return self._density.update(flow)

    def viscosity(self, flow: Flow, /) -> dolfinx.fem.Function:
        """The viscosity of ``flow`` at the cell midpoints (DG0; collective)."""
        return self._viscosity.update(flow)

    def phases(self, flow: Flow, /) -> dict[str, dolfinx.fem.Function]:
        """``phase_<name>``: each phase transition's fraction of the deep phase ``Gamma`` for ``flow``
        (:mod:`convection.physics.phases`; discontinuous, of the velocity's degree; collective)."""
        return {field.name: field.update(flow) for field in self._phases}

    def outputs(self, flow: Flow, /) -> dict[str, dolfinx.fem.Function]:
        """:meth:`invariants`, :meth:`phases` and :meth:`adiabat` of ``flow`` (collective)."""
        return {**self.invariants(flow), **self.phases(flow), **self.adiabat(flow)}

    def adiabat(self, flow: Flow, /) -> dict[str, dolfinx.fem.Function]:
        """``adiabatic_temperature`` ``T_ad`` and ``nonadiabatic_temperature`` ``T - T_ad`` of a compressible
        approximation (:meth:`~convection.physics.compressible.ReferenceState.adiabat`; discontinuous, of the
        velocity's degree; none under Boussinesq; collective)."""
        return {field.name: field.update(flow) for field in self._adiabat}

    def invariants(self, flow: Flow, /) -> dict[str, dolfinx.fem.Function]:
        """``strain_rate_II`` and ``stress_II`` of ``flow`` at the cell midpoints (DG0), and the elastic
        outputs of :attr:`elastic` (collective)."""
        out = {field.name: field.update(flow) for field in self._invariants}
        return out if self.elastic is None else out | self.elastic(flow)


def _elastic_stress_fields(stokes: StokesSolver, /) -> tuple[str, ...]:
    """The stress components the elastic term reads (issue 48), or ()."""
    return () if stokes.discretisation.elasticity is None else stress_labels(stokes.mesh.geometry.dim)


def _elastic_rates(stokes: StokesSolver, /) -> dict[str, Callable[[Flow], Any]]:
    """With elasticity, ``elastic_viscosity`` (``eta_ve``) and ``elastic_memory`` (``chi``) for the
    particles' ``elastic_stress`` (:mod:`convection.physics.elasticity`), at the last solve's ``dt_e``."""
    if stokes.discretisation.elasticity is None:
        return {}

    def factor(index: int) -> Callable[[Flow], Any]:
        def expression(flow: Flow) -> Any:
            discretisation = flow.stokes.discretisation
            eta = discretisation.maxwell_viscosity(flow.T, flow.fractions, {"u": flow.stokes.u, "p": flow.stokes.p,
                                                                             "fields": flow.fields})
            elasticity = discretisation.elasticity
            assert elasticity is not None  # made only with elasticity
            return elasticity.update_factors(eta, flow.fractions, discretisation.elastic_rate,
                                             discretisation.elastic_share)[index]
        return expression
    return {"elastic_viscosity": factor(0), "elastic_memory": factor(1)}


def law_viscosity(flow: Flow, /) -> Any:
    """The viscosity of the laws (mixed and bounded; before elasticity's ``eta -> eta_ve``) as UFL."""
    return flow.stokes.approximation.viscosity(flow.T, flow.fractions, u=flow.stokes.u, p=flow.stokes.p,
                                               fields=flow.fields, x=ufl.SpatialCoordinate(flow.stokes.mesh))


def _adiabatic_temperature(flow: Flow, /) -> Any:
    approximation = flow.stokes.approximation
    return approximation.reference.adiabat(approximation.gravity.depth(ufl.SpatialCoordinate(flow.stokes.mesh)))


def _density_anomaly(flow: Flow, /) -> Any:
    return -flow.stokes.approximation.density(flow.T, flow.fractions)


def _strain_rate_II(flow: Flow, /) -> Any:
    eps = ufl.sym(ufl.grad(flow.stokes.u))
    return ufl.sqrt(ufl.inner(eps, eps) / 2.0)
