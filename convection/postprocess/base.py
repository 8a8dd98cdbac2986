"""What every postprocessor is made of: the protocol, the features of a model that decide which
apply (:class:`ModelFeatures`, also made from a config so that ``check`` refuses a statistic that
cannot be measured), its settings (the ``diagnostics`` section, :class:`DiagnosticsSettings`) and
context (:class:`PostprocessorContext`), and the helpers of the column classes (:class:`Column`,
:class:`Forms`, :func:`integral`)."""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Mapping
from typing import Any, ClassVar, NamedTuple, Protocol

import dolfinx.fem
from mpi4py import MPI

from convection.model.model import Model
from convection.schema import param
from fembase.state import State, Stateful

__all__ = ["NEEDS_ENERGY", "Column", "DiagnosticsSettings", "Forms", "ModelFeatures", "Postprocessor",
           "PostprocessorContext", "integral"]

NEEDS_ENERGY = "needs the energy equation (energy.enabled: true)"


@dataclass(frozen=True)
class DiagnosticsSettings:
    """The ``diagnostics`` config section: what the :class:`Entrainment` column measures."""

    entrainment_material: str | None = param(None, help="material whose entrainment is reported: a material name, "
                                                        "all, or with one material dense (C) or light (1 - C)")
    entrainment_height: float = param(0.2, help="entrainment = volume of that material above this height (shells: "
                                                "radius) / its initial volume")
    topography_material: str | None = param(None, help="the material above the surface whose height the topography "
                                                       "statistic reports (sticky air): h = top - int C dz")
    points: Mapping[str, Any] = param({}, help="named points {name: [x, y(, z)]} whose field values the points "
                                               "statistic reports (coordinates may have units: [100 km, 600 km])")


class PostprocessorContext(NamedTuple):
    """What a postprocessor is made from, beside its settings (each takes what it needs).

    Attributes:
        model: The model it measures.
        start: When the run started, on :func:`time.monotonic`'s clock (the ``wall_time`` column).
    """

    model: Model
    start: float


class Postprocessor(Protocol):
    """Computes some statistics columns of a model (collective); made by ``build(settings,
    context)`` with the ``diagnostics`` section and a :class:`PostprocessorContext` (None: it does
    not apply to the model)."""

    name: ClassVar[str]
    description: ClassVar[str]
    Settings: ClassVar[type]
    columns: tuple[str, ...]

    @classmethod
    def build(cls, settings: DiagnosticsSettings, context: PostprocessorContext, /) -> Postprocessor | None: ...

    def __call__(self, model: Model, /) -> dict[str, float]: ...

    def state(self) -> State:
        """What a checkpoint keeps (:mod:`fembase.state`): JSON-able scalars, no fields."""

    def restore(self, scalars: Mapping[str, Any], /) -> dict[str, Any]:
        """Take the saved scalars back (empty: measure afresh); returns no fields."""


def integral(model: Model, form: Any) -> float:
    return float(model.mesh.comm.allreduce(dolfinx.fem.assemble_scalar(form), op=MPI.SUM))


class Forms:
    """Compiled forms of one postprocessor, rebuilt when the model's mesh changes."""

    def __init__(self) -> None:
        self._version: int | None = None
        self._forms: dict[str, Any] = {}

    def get(self, model: Model, build: Any) -> dict[str, Any]:
        if self._version != model.mesh_version or not self._forms:
            self._forms = build()
            self._version = model.mesh_version
        return self._forms


@dataclass(frozen=True)
class ModelFeatures:
    """What a model has that decides which postprocessors apply to it; made from a model
    (:meth:`of_model`) or, before any model exists, from a checked config (the loader), so that a
    statistic that cannot be measured is refused when the config is checked.

    Attributes:
        energy: The temperature equation is solved.
        particles: The model carries particles.
        materials: The material names (the fields of the composition).
        entrainment_material: ``diagnostics.entrainment_material`` (None: not set).
        Ra: The thermal Rayleigh number.
        points: ``diagnostics.points`` names points.
        topography_material: ``diagnostics.topography_material``.
        columns: The geometry has lines along ``up`` through it (a box).
        free_surface: A boundary is a free surface (:mod:`convection.deform`).
        dissipation: The approximation heats adiabatically and by shear (EBA, TALA).
        elasticity: The rheology is visco-elastic (``physics.elasticity``).
    """

    energy: bool
    particles: bool
    materials: tuple[str, ...]
    entrainment_material: str | None
    Ra: float
    points: bool = False
    topography_material: str | None = None
    columns: bool = True
    free_surface: bool = False
    dissipation: bool = False
    elasticity: bool = False

    @classmethod
    def of_model(cls, model: Model, diagnostics: DiagnosticsSettings | None = None) -> ModelFeatures:
        diagnostics = diagnostics or DiagnosticsSettings()
        return cls(energy=model.solve_temperature, particles=model.particles is not None,
                   materials=tuple(f.name for f in model.fractions),
                   entrainment_material=diagnostics.entrainment_material, Ra=model.stokes.approximation.Ra,
                   points=bool(diagnostics.points), topography_material=diagnostics.topography_material,
                   columns=model.domain.columns(1, 1) is not None, free_surface=model.free_surface is not None,
                   dissipation=model.stokes.approximation.dissipates,
                   elasticity=model.stokes.discretisation.elasticity is not None)


class Column(Stateful):
    """Default construction: no parameters; applies to every model unless :meth:`missing` says otherwise;
    nothing to keep in a checkpoint (the columns are measured afresh every step)."""

    name: ClassVar[str]
    description: ClassVar[str]
    Settings: ClassVar[type] = DiagnosticsSettings
    columns: tuple[str, ...]
    quantities: ClassVar[Mapping[str, str]] = {}
    """Column -> what it measures (a kind of :data:`convection.physics.scaling.UNIT_KINDS`: a model with
    units writes it in that kind's unit); columns not named are numbers without a unit."""

    @classmethod
    def missing(cls, features: ModelFeatures) -> str | None:
        """What a model lacks for these columns (None: they apply), e.g. ``"needs the energy equation
        (energy.enabled: true)"``."""
        return None

    @classmethod
    def applies(cls, model: Model) -> bool:
        return cls.missing(ModelFeatures.of_model(model)) is None

    @classmethod
    def by_default(cls, model: Model) -> bool:
        """Whether a run without ``output.statistics`` gets these columns."""
        return True

    @classmethod
    def build(cls, settings: DiagnosticsSettings, context: PostprocessorContext, /) -> Any:
        """The postprocessor for ``context.model`` (None when it does not apply)."""
        return cls() if cls.applies(context.model) else None

