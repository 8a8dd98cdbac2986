"""Postprocessors: the statistics of a run, each declaring its own columns.

Every postprocessor is registered under a name in :data:`POSTPROCESSORS`; ``output.statistics``
lists the ones a run uses (default: every one that applies to the model). ``statistics.csv`` has
the union of their columns, in registry order:

=============== =======================================================================
name            columns
=============== =======================================================================
``time``        step, time, dt
``velocity``    vrms = sqrt(int |u|^2 dx / |Omega|)
``nusselt``     nusselt (top), nusselt_bottom: consistent boundary-flux Nusselt numbers (shells:
                outer and inner surface)
``temperature`` T_mean (volume average), T_min, T_max (nodal)
``mesh``        cells (global)
``stokes``      stokes_iterations
``particles``   n_particles, n_lost (cumulative), n_added, n_removed (population control),
                ppc_min, ppc_mean, ppc_max (particles per cell)
``particle_distribution`` distribution_score (mean over cells), distribution_score_min, _max, _std:
                how evenly the particles spread inside their cells, ASPECT's particle distribution
                score (:mod:`particles.population.distribution`; only when asked for)
``load``        cell_imbalance, particle_imbalance (max/mean over ranks)
``entrainment`` entrainment: volume of a material above a height / its initial volume
                (one column per material, ``entrainment_<name>``, for ``all``)
``wall_time``   wall_time (seconds since the run started)
``nonlinear``   nonlinear_iterations, nonlinear_residual (relative) of the last Stokes solve
``rheology``    eta_min, eta_max: the viscosity's extremes at the velocity nodes of every cell
``energy``      W = <T u . e_up>, Phi_over_Ra = <2 eta eps(u):eps(u)> / Ra (volume averages) and
                delta = |W - Phi/Ra| / max(W, Phi/Ra): the energy balance of steady convection
``heating``     heating_W = <Di rho_r (T + T0) u . e_up>, the work against gravity (adiabatic cooling),
                heating_Phi = <(Di / Ra) Phi>, the shear heating, heating_misfit = |Phi - W| / W,
                heating_pressure_work = P, what the compression adds (TALA, ALA; 0 under EBA), and
                heating_balance = |Phi - W - P| / W, the energy balance with it
                (EBA, TALA: :mod:`convection.physics.compressible`; by default there only)
``adiabat``     T_adiabatic_mean, T_nonadiabatic_mean: volume means of the adiabatic temperature T_ad and of
                T - T_ad (EBA, TALA, ALA; only when asked for)
``surface``     vrms_surface = sqrt(int_top |u|^2 ds / |top|), vmax_surface (largest nodal |u| on
                the top; shells: the outer surface)
``materials``   per material ``<m>``: volume_<m>, centroid x_<m>, y_<m> (, z_<m>), vup_<m> (mean
                upward velocity), vrms_<m>, vmax_<m>, depth_<m> (deepest point)
                (:mod:`convection.postprocess.geodynamics`)
``points``      every output field at the named points of ``diagnostics.points``: T_<p>,
                vx_<p>, vy_<p> (, vz_<p>), p_<p>, <material>_<p>, ...
``topography``  topography_max, topography_min, topography_rms: the free surface's height above the
                box's top; without one, the surface under the material
                ``diagnostics.topography_material`` (sticky air), about its mean level
``free_surface`` mesh_quality_min, particles_pulled_in: the deforming mesh's worst cell and the
                particles the sinking surface passed (:mod:`convection.deform`)
``elasticity``  elastic_stress_invariant_max, elastic_stress_invariant_mean, elastic_strain_rate_mean,
                viscous_strain_rate_mean, elastic_share: the deviatoric stress and the split of the
                deformation of a visco-elastic run (:mod:`convection.postprocess.elasticity`; by
                default there only)
=============== =======================================================================

``nonlinear``, ``rheology``, ``energy`` and ``surface`` apply by default to a model whose viscosity
depends on the flow (the others may ask for them in ``output.statistics``); ``materials``,
``points`` and ``topography`` only when asked for. A postprocessor says what a model needs for it (``missing``), and
a config that asks for one its model lacks is refused when it is checked. Columns that have a unit
are named in ``quantities`` (column -> ``time``, ``velocity``, ``temperature``, ...): a model with
units (:mod:`convection.physics.scaling`) writes them converted to ``statistics_physical.csv``.

A postprocessor has the one plugin shape (docs/developers.md): its ``Settings`` are the
``diagnostics`` section (:class:`DiagnosticsSettings`, shared by every postprocessor) and
``build(settings, context)`` makes it for the model of a :class:`PostprocessorContext` (None when
it does not apply, e.g. ``nusselt`` without a temperature equation). It is made only through
:data:`POSTPROCESSORS` (:func:`create_postprocessors`) and called with the model after every step;
all calls are collective.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
import ufl
from mpi4py import MPI

import dolfinx.fem

from fembase.dolfinx_compat import evaluate_expression, interpolation_points
from convection.postprocess.diagnostics import nusselt
from convection.model.model import Model
from convection.adapt.rebalance import RankLoads
from convection.model.rheology_fields import flow_viscosity
from convection.postprocess.base import (
    NEEDS_ENERGY, Column, DiagnosticsSettings, Forms, ModelFeatures, Postprocessor, PostprocessorContext, integral,
)
from convection.postprocess.elasticity import ElasticityStatistics
from convection.postprocess.geodynamics import FreeSurfaceStatistics, MaterialStatistics, PointValues, Topography
from fembase.registry import Registry
from particles.manager import ParticleManager
from fembase.state import State, Stateful

__all__ = ["POSTPROCESSORS", "DiagnosticsSettings", "ModelFeatures", "Postprocessor", "PostprocessorContext",
           "check_statistics", "create_postprocessors"]


class TimeColumns(Column):
    name: ClassVar[str] = "time"
    description: ClassVar[str] = "step number, time and the last step length"
    columns = ("step", "time", "dt")
    quantities: ClassVar[Mapping[str, str]] = {"time": "time", "dt": "time"}

    def __call__(self, model: Model, /) -> dict[str, float]:
        return {"step": model.timestep, "time": model.time, "dt": model.dt_previous}


class Velocity(Column):
    name: ClassVar[str] = "velocity"
    description: ClassVar[str] = "root-mean-square velocity"
    columns = ("vrms",)
    quantities: ClassVar[Mapping[str, str]] = {"vrms": "velocity"}

    def __init__(self) -> None:
        self._forms = Forms()

    def __call__(self, model: Model, /) -> dict[str, float]:
        u = model.stokes.u
        forms = self._forms.get(model, lambda: {
            "u2": dolfinx.fem.form(ufl.inner(u, u) * ufl.dx),
            "volume": dolfinx.fem.form(dolfinx.fem.Constant(model.mesh, 1.0) * ufl.dx(domain=model.mesh)),
        })
        return {"vrms": float(np.sqrt(integral(model, forms["u2"]) / integral(model, forms["volume"])))}


class Nusselt(Column):
    name: ClassVar[str] = "nusselt"
    description: ClassVar[str] = ("Nusselt numbers at the top and bottom (shells: outer and inner surface) from the "
                                  "consistent boundary flux")
    columns = ("nusselt", "nusselt_bottom")

    @classmethod
    def missing(cls, features: ModelFeatures) -> str | None:
        return None if features.energy else NEEDS_ENERGY

    def __call__(self, model: Model, /) -> dict[str, float]:
        assert model.temperature is not None
        domain = model.domain
        return {"nusselt": nusselt(model.temperature, model.stokes.u, domain.top, domain),
                "nusselt_bottom": nusselt(model.temperature, model.stokes.u, domain.bottom, domain)}


class TemperatureStatistics(Column):
    name: ClassVar[str] = "temperature"
    description: ClassVar[str] = "volume-mean, minimum and maximum temperature"
    columns = ("T_mean", "T_min", "T_max")
    quantities: ClassVar[Mapping[str, str]] = dict.fromkeys(columns, "temperature")

    def __init__(self) -> None:
        self._forms = Forms()

    def __call__(self, model: Model, /) -> dict[str, float]:
        T = model.T
        forms = self._forms.get(model, lambda: {
            "T": dolfinx.fem.form(T * ufl.dx),
            "volume": dolfinx.fem.form(dolfinx.fem.Constant(model.mesh, 1.0) * ufl.dx(domain=model.mesh)),
        })
        comm = model.mesh.comm
        owned = T.x.array[: T.function_space.dofmap.index_map.size_local]
        lo = comm.allreduce(float(owned.min()) if owned.size else np.inf, op=MPI.MIN)
        hi = comm.allreduce(float(owned.max()) if owned.size else -np.inf, op=MPI.MAX)
        return {"T_mean": integral(model, forms["T"]) / integral(model, forms["volume"]), "T_min": lo, "T_max": hi}


class MeshStatistics(Column):
    name: ClassVar[str] = "mesh"
    description: ClassVar[str] = "global number of cells"
    columns = ("cells",)

    def __call__(self, model: Model, /) -> dict[str, float]:
        return {"cells": model.num_cells}


class StokesStatistics(Column):
    name: ClassVar[str] = "stokes"
    description: ClassVar[str] = "iterations of the last Stokes solve"
    columns = ("stokes_iterations",)

    def __call__(self, model: Model, /) -> dict[str, float]:
        return {"stokes_iterations": model.flow_result.iterations if model.flow_result else 0}


class ParticleStatistics(Column):
    """The primary particle system's counts (the one whose fields the model reads), and with
    several systems each other system's under its name (``n_particles_<name>``, ...)."""

    name: ClassVar[str] = "particles"
    description: ClassVar[str] = ("particle count, lost/added/removed particles, particles per cell min/mean/max "
                                  "(other particle systems: the same columns suffixed _<name>)")
    columns = ("n_particles", "n_lost", "n_added", "n_removed", "ppc_min", "ppc_mean", "ppc_max")

    def __init__(self, others: tuple[str, ...] = (), /) -> None:
        self.others = others
        self.columns = (*type(self).columns, *(f"{c}_{name}" for name in others for c in type(self).columns))

    @classmethod
    def missing(cls, features: ModelFeatures) -> str | None:
        return None if features.particles else "needs particles (particles.enabled: true)"

    @classmethod
    def build(cls, settings: DiagnosticsSettings, context: PostprocessorContext, /) -> ParticleStatistics | None:
        model = context.model
        if not cls.applies(model):
            return None
        systems = model.particles
        return cls(tuple(name for name in systems.names if name != systems.primary_name))

    def __call__(self, model: Model, /) -> dict[str, float]:
        systems = model.particles
        assert systems is not None
        out = self._counts(systems.primary, "")
        for name in self.others:
            out.update(self._counts(systems[name], f"_{name}"))
        return out

    @staticmethod
    def _counts(manager: ParticleManager, suffix: str) -> dict[str, float]:
        lo, mean, hi = manager.particles_per_cell()
        values = {"n_particles": manager.num_particles, "n_lost": manager.lost, "n_added": manager.added,
                  "n_removed": manager.removed, "ppc_min": lo, "ppc_mean": mean, "ppc_max": hi}
        return {f"{key}{suffix}": value for key, value in values.items()}


class ParticleDistribution(Column):
    """ASPECT's particle distribution score (:func:`particles.population.distribution.distribution_score`,
    granularity 2): per cell ``S = sum_b (c_b - n/B)^2 / (n^2 (B - 1) / B)`` over its ``B = 2**tdim``
    equal-volume sub-cells, 0 for an even spread, 1 for all particles in one sub-cell or none;
    min, mean, max and standard deviation over all cells, of the primary particle system (the one
    carrying the composition). Collective; only when asked for."""

    name: ClassVar[str] = "particle_distribution"
    description: ClassVar[str] = "particle distribution score per cell (0 even .. 1 clustered): mean, min, max, std"
    columns = ("distribution_score", "distribution_score_min", "distribution_score_max", "distribution_score_std")

    @classmethod
    def missing(cls, features: ModelFeatures) -> str | None:
        return ParticleStatistics.missing(features)

    @classmethod
    def by_default(cls, model: Model) -> bool:
        return False

    def __call__(self, model: Model, /) -> dict[str, float]:
        from particles.population.distribution import distribution_score
        assert model.particles is not None
        score = distribution_score(model.particles.primary.swarm, 2)
        return {"distribution_score": score.mean, "distribution_score_min": score.min,
                "distribution_score_max": score.max, "distribution_score_std": score.std}


class LoadStatistics(Column):
    name: ClassVar[str] = "load"
    description: ClassVar[str] = "imbalance (max/mean over ranks) of owned cells and particles"
    columns = ("cell_imbalance", "particle_imbalance")

    def __call__(self, model: Model, /) -> dict[str, float]:
        swarms = model.particles.swarms if model.particles is not None else []
        loads = RankLoads.measure(model.mesh, swarms, particle_weight=0.0)
        return {"cell_imbalance": loads.cell_imbalance, "particle_imbalance": loads.particle_imbalance}


class Entrainment:
    """Volume of a material above ``height`` (in shells: outside the radius ``height``) divided by its
    volume at the first call.

    ``material``: a material name; ``all`` (one column per material); or, with exactly one
    material, ``dense`` (its fraction C) or ``light`` (the background, 1 - C).
    """

    name: ClassVar[str] = "entrainment"
    description: ClassVar[str] = "fraction of a material's initial volume above a height"
    Settings: ClassVar[type] = DiagnosticsSettings

    def __init__(self, amounts: dict[str, tuple[int, bool]], height: float) -> None:
        self.amounts = amounts  # column -> (material index, background instead)
        self.height = height
        self.columns = tuple(amounts)
        self._forms = Forms()
        self._initial: dict[str, float] | None = None

    @classmethod
    def missing(cls, features: ModelFeatures) -> str | None:
        if not features.materials:
            return "needs materials (the materials section or initial.composition)"
        return None if features.entrainment_material is not None else \
            "needs diagnostics.entrainment_material (a material name, all, dense or light)"

    @classmethod
    def build(cls, settings: DiagnosticsSettings, context: PostprocessorContext, /) -> Entrainment | None:
        model = context.model
        material = settings.entrainment_material
        names = [f.name for f in model.fractions]
        if cls.missing(ModelFeatures.of_model(model, settings)) is not None:
            return None
        if material == "all":
            amounts = {f"entrainment_{n}": (i, False) for i, n in enumerate(names)}
        elif material in ("dense", "light"):
            if len(names) != 1:
                raise ValueError(f"entrainment material {material!r} needs exactly one material; name one of {names}")
            amounts = {"entrainment": (0, material == "light")}
        elif material in names:
            amounts = {"entrainment": (names.index(material), False)}
        else:
            raise ValueError(f"unknown entrainment material {material!r}; valid: {['all', 'dense', 'light', *names]}")
        return cls(amounts, float(settings.entrainment_height))

    def _build(self, model: Model) -> dict[str, Any]:
        x = ufl.SpatialCoordinate(model.mesh)
        z = model.domain.gravity.height(x)  # the radius in shells, else the last coordinate
        forms = {}
        for column, (i, light) in self.amounts.items():
            C = model.fractions[i]
            amount = 1.0 - C if light else C
            forms[column] = (dolfinx.fem.form(ufl.conditional(ufl.gt(z, self.height), amount, 0.0) * ufl.dx),
                             dolfinx.fem.form(amount * ufl.dx))
        return forms

    def state(self) -> State:
        """The initial volumes by column (empty before they are measured)."""
        return State(scalars=dict(self._initial or {}))

    def restore(self, scalars: Mapping[str, Any] | None, /) -> dict[str, Any]:
        self._initial = dict(scalars) if scalars else None
        return {}

    def __call__(self, model: Model, /) -> dict[str, float]:
        forms = self._forms.get(model, lambda: self._build(model))
        if self._initial is None:
            self._initial = {column: integral(model, total) for column, (_, total) in forms.items()}
        return {column: integral(model, above) / self._initial[column] for column, (above, _) in forms.items()}


class WallTime(Stateful):
    """Nothing in a checkpoint: the run loop keeps the wall time of a resumed run."""

    name: ClassVar[str] = "wall_time"
    description: ClassVar[str] = "wall seconds since the run started"
    Settings: ClassVar[type] = DiagnosticsSettings
    columns = ("wall_time",)

    def __init__(self, start: float) -> None:
        self.start = start

    @classmethod
    def build(cls, settings: DiagnosticsSettings, context: PostprocessorContext, /) -> WallTime:
        return cls(context.start)

    def __call__(self, model: Model, /) -> dict[str, float]:
        return {"wall_time": time.monotonic() - self.start}


class _Rheology(Column):
    """Columns for models whose viscosity depends on the flow (by default there only)."""

    @classmethod
    def by_default(cls, model: Model) -> bool:
        return model.stokes.is_nonlinear


class NonlinearStatistics(_Rheology):
    name: ClassVar[str] = "nonlinear"
    description: ClassVar[str] = "iterations and final relative residual of the last nonlinear Stokes solve"
    columns = ("nonlinear_iterations", "nonlinear_residual")

    def __call__(self, model: Model, /) -> dict[str, float]:
        result = model.flow_result.nonlinear if model.flow_result is not None else None
        if result is None:
            return {"nonlinear_iterations": 0, "nonlinear_residual": 0.0}
        return {"nonlinear_iterations": result.iterations, "nonlinear_residual": result.residual}


class ViscosityRange(_Rheology):
    name: ClassVar[str] = "rheology"
    description: ClassVar[str] = "smallest and largest viscosity at the velocity nodes of every cell"
    columns = ("eta_min", "eta_max")
    quantities: ClassVar[Mapping[str, str]] = dict.fromkeys(columns, "viscosity")

    def __init__(self) -> None:
        self._version: int | None = None
        self._expression: Any = None

    def __call__(self, model: Model, /) -> dict[str, float]:
        if self._version != model.mesh_version or self._expression is None:
            points = interpolation_points(model.stokes.V)
            self._expression = dolfinx.fem.Expression(flow_viscosity(model.flow()), points)
            self._version = model.mesh_version
        mesh = model.mesh
        owned = np.arange(mesh.topology.index_map(mesh.topology.dim).size_local, dtype=np.int32)
        values = np.asarray(evaluate_expression(self._expression, mesh, owned))
        lo = float(values.min()) if values.size else np.inf
        hi = float(values.max()) if values.size else -np.inf
        return {"eta_min": mesh.comm.allreduce(lo, op=MPI.MIN), "eta_max": mesh.comm.allreduce(hi, op=MPI.MAX)}


class EnergyBalance(_Rheology):
    name: ClassVar[str] = "energy"
    description: ClassVar[str] = "work against gravity W, dissipation Phi/Ra and their balance delta (volume averages)"
    columns = ("W", "Phi_over_Ra", "delta")

    def __init__(self) -> None:
        self._forms = Forms()

    @classmethod
    def missing(cls, features: ModelFeatures) -> str | None:
        if not features.energy:
            return NEEDS_ENERGY
        return None if features.Ra > 0.0 else "needs physics.Ra > 0 (it reports the dissipation over Ra)"

    def __call__(self, model: Model, /) -> dict[str, float]:
        stokes = model.stokes

        def build() -> dict[str, Any]:
            u = stokes.u
            x = ufl.SpatialCoordinate(model.mesh)
            up = stokes.approximation.up(x)
            eps = ufl.sym(ufl.grad(u))
            dx = ufl.dx(domain=model.mesh, metadata={"quadrature_degree": 3 * stokes.degree})
            return {"W": dolfinx.fem.form(model.T * ufl.dot(u, up) * dx),
                    "Phi": dolfinx.fem.form(2.0 * flow_viscosity(model.flow()) * ufl.inner(eps, eps) * dx),
                    "volume": dolfinx.fem.form(dolfinx.fem.Constant(model.mesh, 1.0) * dx)}
        forms = self._forms.get(model, build)
        volume = integral(model, forms["volume"])
        W = integral(model, forms["W"]) / volume
        ra = stokes.approximation.Ra
        phi = integral(model, forms["Phi"]) / volume / ra if ra else float("nan")
        scale = max(abs(W), abs(phi))
        return {"W": W, "Phi_over_Ra": phi, "delta": abs(W - phi) / scale if scale > 0 else 0.0}


class Heating(Column):
    name: ClassVar[str] = "heating"
    description: ClassVar[str] = ("work against gravity W (adiabatic cooling), shear heating Phi (volume averages), "
                                  "|Phi - W| / W, the compression's work P and the balance |Phi - W - P| / W")
    columns = ("heating_W", "heating_Phi", "heating_misfit", "heating_pressure_work", "heating_balance")

    def __init__(self) -> None:
        self._forms = Forms()

    @classmethod
    def missing(cls, features: ModelFeatures) -> str | None:
        heating = None if features.dissipation else "needs adiabatic and shear heating (physics.approximation)"
        return heating if features.energy else NEEDS_ENERGY

    def __call__(self, model: Model, /) -> dict[str, float]:
        stokes = model.stokes

        def build() -> dict[str, Any]:
            x = ufl.SpatialCoordinate(model.mesh)
            W, Phi = stokes.approximation.heating_rates(model.T, model.T, stokes.u, x)
            P = stokes.approximation.pressure_work(model.T, stokes.u, stokes.p, x)
            dx = ufl.dx(domain=model.mesh, metadata={"quadrature_degree": 3 * stokes.degree})
            return {"W": dolfinx.fem.form(W * dx), "Phi": dolfinx.fem.form(Phi * dx), "P": dolfinx.fem.form(P * dx),
                    "volume": dolfinx.fem.form(dolfinx.fem.Constant(model.mesh, 1.0) * dx)}
        forms = self._forms.get(model, build)
        volume = integral(model, forms["volume"])
        W, phi, P = (integral(model, forms[k]) / volume for k in ("W", "Phi", "P"))
        return {"heating_W": W, "heating_Phi": phi, "heating_misfit": abs(phi - W) / abs(W) if W else 0.0,
                "heating_pressure_work": P, "heating_balance": abs(phi - W - P) / abs(W) if W else 0.0}


class Adiabat(Heating):
    """The reference state's temperatures (applies where :class:`Heating` does; only when asked for)."""

    name: ClassVar[str] = "adiabat"
    description: ClassVar[str] = "volume means of the adiabatic temperature T_ad and of the non-adiabatic T - T_ad"
    columns = ("T_adiabatic_mean", "T_nonadiabatic_mean")
    quantities: ClassVar[Mapping[str, str]] = {"T_adiabatic_mean": "temperature",
                                               "T_nonadiabatic_mean": "temperature_difference"}

    @classmethod
    def by_default(cls, model: Model) -> bool:
        return False

    def __call__(self, model: Model, /) -> dict[str, float]:
        def build() -> dict[str, Any]:
            approximation = model.stokes.approximation
            T_ad = approximation.reference.adiabat(approximation.gravity.depth(ufl.SpatialCoordinate(model.mesh)))
            dx = ufl.dx(domain=model.mesh, metadata={"quadrature_degree": 2 * model.stokes.degree + 2})
            return {"T_ad": dolfinx.fem.form(T_ad * dx), "T": dolfinx.fem.form(model.T * dx),
                    "volume": dolfinx.fem.form(dolfinx.fem.Constant(model.mesh, 1.0) * dx)}
        forms = self._forms.get(model, build)
        volume = integral(model, forms["volume"])
        T_ad = integral(model, forms["T_ad"]) / volume
        return {"T_adiabatic_mean": T_ad, "T_nonadiabatic_mean": integral(model, forms["T"]) / volume - T_ad}


class SurfaceVelocity(_Rheology):
    name: ClassVar[str] = "surface"
    description: ClassVar[str] = "rms and largest nodal speed on the top (shells: outer) surface"
    columns = ("vrms_surface", "vmax_surface")
    quantities: ClassVar[Mapping[str, str]] = dict.fromkeys(columns, "velocity")

    def __init__(self) -> None:
        self._forms = Forms()
        self._dofs: Any = None
        self._version: int | None = None

    def __call__(self, model: Model, /) -> dict[str, float]:
        stokes = model.stokes
        domain = model.domain

        def build() -> dict[str, Any]:
            ds = domain.measure(model.mesh, domain.top)
            u = stokes.u
            return {"u2": dolfinx.fem.form(ufl.inner(u, u) * ds),
                    "area": dolfinx.fem.form(dolfinx.fem.Constant(model.mesh, 1.0) * ds)}
        forms = self._forms.get(model, build)
        if self._version != model.mesh_version or self._dofs is None:
            V0, to_parent = stokes.V.sub(0).collapse()
            gdim = model.mesh.geometry.dim
            # the nodes (blocked dofs of V) on the surface: parent indices are unrolled, node * gdim + 0
            self._dofs = np.asarray(to_parent)[np.asarray(domain.locate_dofs(V0, domain.top))] // gdim
            self._version = model.mesh_version
        gdim = model.mesh.geometry.dim
        n_owned = stokes.V.dofmap.index_map.size_local
        nodes = np.asarray(self._dofs)
        nodes = nodes[nodes < n_owned]
        values = stokes.u.x.array.reshape(-1, gdim)[nodes]
        local = float(np.sqrt((values ** 2).sum(axis=1)).max()) if len(nodes) else 0.0
        rms = np.sqrt(integral(model, forms["u2"]) / integral(model, forms["area"]))
        return {"vrms_surface": float(rms), "vmax_surface": model.mesh.comm.allreduce(local, op=MPI.MAX)}


def check_statistics(names: list[str] | tuple[str, ...] | None, features: ModelFeatures) -> None:
    """Refuse a postprocessor asked for by name that does not apply to a model with ``features``.

    Raises:
        ValueError: naming the first such postprocessor and what it needs.
    """
    for name in names or ():
        cls = POSTPROCESSORS.get(name)
        problem = getattr(cls, "missing", lambda _: None)(features) if cls is not None else None
        if problem is not None:
            raise ValueError(f"{name!r} {problem}")


POSTPROCESSORS: Registry[type] = Registry("postprocessor", (
    TimeColumns, Velocity, Nusselt, TemperatureStatistics, MeshStatistics, StokesStatistics, ParticleStatistics,
    ParticleDistribution, LoadStatistics, Entrainment, WallTime, NonlinearStatistics, ViscosityRange, EnergyBalance,
    Heating, Adiabat, SurfaceVelocity, MaterialStatistics, PointValues, Topography, FreeSurfaceStatistics,
    ElasticityStatistics))
"""Postprocessor classes by their config name (``output.statistics``), in column order."""


def create_postprocessors(model: Model, names: list[str] | tuple[str, ...] | None = None, /, *,
                          start: float | None = None, diagnostics: DiagnosticsSettings | None = None
                          ) -> list[Postprocessor]:
    """The postprocessors ``names`` (default: all that apply to ``model``), in registry order, each
    built through :data:`POSTPROCESSORS` with ``diagnostics`` (default: the section's defaults) and a
    :class:`PostprocessorContext` (``start``: the run's start on ``time.monotonic``'s clock, for the
    wall time; default: now).

    A name asked for explicitly that does not apply to the model is an error.

    Raises:
        ValueError: Unknown name (listing the valid ones) or one that does not apply.
    """
    if names is not None:
        unknown = [n for n in names if n not in POSTPROCESSORS]
        if unknown:
            raise ValueError(f"unknown postprocessor {unknown[0]!r}; valid: {list(POSTPROCESSORS)}")
    settings = diagnostics or DiagnosticsSettings()
    context = PostprocessorContext(model, time.monotonic() if start is None else start)
    out = []
    for name, cls in POSTPROCESSORS.items():
        if names is not None and name not in names:
            continue
        if names is None and hasattr(cls, "by_default") and not cls.by_default(model):
            continue
        pp = POSTPROCESSORS.build(name, settings, context)
        if pp is None and names is not None:
            problem = getattr(cls, "missing", lambda _: None)(ModelFeatures.of_model(model, settings))
            raise ValueError(f"postprocessor {name!r} does not apply to this model: {problem or 'not measurable'}")
        if pp is not None:
            out.append(pp)
    return out
