"""Materials: named compositions with their own density contrast and viscosity.

The domain is filled by a *background* material and any number of named materials with volume
fractions ``C_i`` (``sum_i C_i <= 1``; the background takes the rest). Material ``i`` adds the
buoyancy ``-Rb_i C_i e_z`` and its viscosity ``eta_i`` enters the volume-fraction weighted mixing
rule of :class:`convection.physics.approximation.ViscosityLaw` (arithmetic, geometric or harmonic). The
classic two-material setup (``initial.composition``, ``physics.Rb``,
``physics.viscosity.material_viscosities``) is one material named ``composition``.

For pictures, :func:`material_index` combines the fractions into one field ``sum_i i C_i``: 0 in
the background, ``i`` where material ``i`` (counted from 1 in the given order) fills the cell.
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

import dolfinx.fem

from convection.geometry.gravity import Gravity, VerticalGravity
from convection.physics.approximation import VISCOSITY_DEFAULTS, BoussinesqApproximation, ViscosityLaw
from convection.physics.compressible import ReferenceState
from convection.physics.elasticity import Elasticity
from convection.physics.phases import PhaseTransitions
from convection.physics.rheology import Constant, ViscosityLawBase
from convection.schema import REQUIRED, param

__all__ = ["Material", "Materials", "material_index"]

InitialRegion = Callable[[npt.NDArray[np.float64]], npt.NDArray[np.float64]]
"""Initial volume fraction of a material: points shape=(3, n) -> values shape=(n,) in [0, 1]."""


@dataclass(frozen=True)
class MaterialSettings:
    """One entry of the ``materials`` config section (``materials.<name>``); :class:`Material`'s
    defaults come from here."""

    initial: str = param(REQUIRED, help="initial volume fraction: expression in x, y, z (e.g. \"z < 0.2\")")
    Rb: float = param(0.0, help="compositional Rayleigh number: buoyancy -Rb C e_z (> 0: denser)")
    density: str | None = param(None, help="density with a unit (e.g. 3300 kg/m^3; needs the scaling section): "
                                           "gives Rb = (rho - scaling.density) g L^3 / (eta0 kappa)")
    viscosity: Any | None = param(None, help="viscosity of the pure material: a number or a law as "
                                             "physics.viscosity.law (null: the background's)")
    shear_modulus: float | None = param(None, exclusive_minimum=0.0,
                                        help="shear modulus G of the pure material (a stress, e.g. 3e10 Pa), with "
                                             "physics.elasticity (null: the background's)")


_MATERIAL_DEFAULTS = MaterialSettings(initial="0")


@dataclass(frozen=True)
class Material:
    """One named material.

    Attributes:
        name: Name (used for its field, its particle property and statistics columns).
        initial: Initial volume fraction as a function of position (DOLFINx interpolation layout).
        Rb: Compositional Rayleigh number: buoyancy ``-Rb C e_z`` (positive: denser).
        viscosity: Viscosity of the pure material: a number, a :mod:`convection.physics.rheology` law, or
            None (the background's; without any law or number: the reference viscosity 1 for
            every material, i.e. no compositional viscosity contrast).
    """

    name: str
    initial: InitialRegion
    Rb: float = _MATERIAL_DEFAULTS.Rb
    viscosity: float | ViscosityLawBase | None = _MATERIAL_DEFAULTS.viscosity

    def __post_init__(self) -> None:
        if not self.name.isidentifier():
            raise ValueError(f"material name {self.name!r} must be a name (letters, digits, _)")
        if isinstance(self.viscosity, (int, float)) and not self.viscosity > 0.0:
            raise ValueError(f"material {self.name!r}: viscosity must be > 0, got {self.viscosity}")


@dataclass(frozen=True)
class Materials:
    """The materials of a model and how their viscosities mix.

    Attributes:
        materials: The named materials, in order (material ``i`` has index ``i + 1``).
        background_viscosity: Viscosity of the background material.
        mixing: ``"arithmetic"``, ``"geometric"`` or ``"harmonic"`` (volume-fraction weighted).
        background_law: The background's :mod:`convection.physics.rheology` law (replaces
            ``background_viscosity``), or None.
        sharp: Names of the materials that enter the viscosity by threshold rather than by mixing
            (:class:`convection.physics.approximation.ViscosityLaw`'s ``sharp``).
    """

    materials: tuple[Material, ...] = ()
    background_viscosity: float = VISCOSITY_DEFAULTS.background
    mixing: str = VISCOSITY_DEFAULTS.mixing
    background_law: ViscosityLawBase | None = None
    sharp: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        names = self.names
        if len(set(names)) != len(names):
            raise ValueError(f"material names must differ, got {names}")
        unknown = [n for n in self.sharp if n not in names]
        if unknown:
            raise ValueError(f"sharp materials {unknown} are not among the materials {names}")
        if not self.background_viscosity > 0.0:
            raise ValueError(f"background viscosity must be > 0, got {self.background_viscosity}")

    @property
    def names(self) -> list[str]:
        return [m.name for m in self.materials]

    def __len__(self) -> int:
        return len(self.materials)

    def viscosity_law(self, *, temperature_law: str = "none", gamma: float = 0.0,
                      gravity: Gravity = VerticalGravity()) -> ViscosityLaw:
        """The viscosity law of these materials (with an optional temperature dependence): the
        background's law (or its number) and each material's (a number is a
        :class:`~convection.physics.rheology.Constant`; none: the background's), mixed; ``gravity``:
        along which the laws' depth is measured (:class:`convection.physics.approximation.ViscosityLaw`)."""
        law0 = self.background_law if self.background_law is not None else Constant.of(self.background_viscosity)

        def law(value: Any) -> ViscosityLawBase:
            if value is None:
                return law0
            return value if isinstance(value, ViscosityLawBase) else Constant.of(value)
        return ViscosityLaw(mixing=self.mixing, temperature_law=temperature_law, gamma=gamma,
                            laws=(law0, *(law(m.viscosity) for m in self.materials)), gravity=gravity,
                            sharp=tuple(self.names.index(n) + 1 for n in self.sharp))

    def approximation(self, *, Ra: float, H: float = 0.0, temperature_law: str = "none",
                      gamma: float = 0.0, gravity: Gravity = VerticalGravity(), formulation: str = "boussinesq",
                      reference: ReferenceState = ReferenceState(),
                      elasticity: Elasticity | None = None,
                      phases: PhaseTransitions = PhaseTransitions()) -> BoussinesqApproximation:
        """The approximation ``formulation`` (:mod:`convection.physics.compressible`; Boussinesq by
        default) with these materials' buoyancy and viscosity, and the phase transitions ``phases``."""
        rb = tuple(m.Rb for m in self.materials)
        return BoussinesqApproximation(Ra=Ra, Rb=rb if rb else 0.0, H=H, gravity=gravity,
                                       viscosity=self.viscosity_law(temperature_law=temperature_law, gamma=gamma,
                                                                    gravity=gravity),
                                       formulation=formulation, reference=reference, elasticity=elasticity,
                                       phases=phases)


def material_index(fractions: Sequence[dolfinx.fem.Function], /, *, name: str = "material") -> dolfinx.fem.Function:
    """``sum_i i C_i`` (materials counted from 1) in the space of the fractions, for pictures.

    Args:
        fractions: One Function per material, all in the same space.
    """
    if not fractions:
        raise ValueError("material_index needs at least one material fraction")
    space = fractions[0].function_space
    out = dolfinx.fem.Function(space, name=name)
    for i, c in enumerate(fractions, start=1):
        same = c.function_space.mesh is space.mesh and c.function_space.ufl_element() == space.ufl_element()
        if not same:  # the same element on the same mesh numbers its dofs the same way
            raise ValueError("all material fractions must live in one function space (element and mesh)")
        out.x.array[:] += i * c.x.array
    return out
