"""The elastic outputs on particles (issue 48): ``elastic_stress_invariant``, ``elastic_strain_rate``,
``viscous_strain_rate`` and ``elastic_share``, from the particle's own stress ``elastic_stress``.

After the stress update ``tau^{n+1} = 2 eta_ve eps + chi R tau^n R^T``
(:mod:`particles.properties.elastic_stress`) the Maxwell law splits the strain rate ``eps`` at the
particle exactly (docs/rheology.md, "Elasticity")::

    eps_v  = tau^{n+1} / (2 eta) = (1 - chi) tau^{n+1} / (2 eta_ve)      (eta = eta_ve / (1 - chi))
    eps_el = eps - eps_v = chi (tau^{n+1} - R tau^n R^T) / (2 eta_ve)
    share  = eps_el_II / eps_II  (0 where eps_II = 0),      X_II = sqrt(X : X / 2)

Tensors in Voigt columns as ``elastic_stress`` (``xx, yy, xy``; 3D ``xx, yy, zz, xy, xz, yz``).
They read ``elastic_stress`` (placed after it) and, but for the invariant, the mesh fields
``eta_ve`` and ``chi``; they are computed when the particles are written (``output_only``) and are
zero before the first step (no elastic step taken yet); a particle added between two outputs is
zero until the next (the invariant: that of its stress).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import numpy.typing as npt

from particles.properties._base import ParticleProperty, PropertyContext, evaluate_at, gradient_at, write_rows
from particles.properties._tensor import strain_rate
from particles.properties.elastic_stress import ElasticStress, from_voigt, to_voigt
from particles.storage.swarm import Swarm

__all__ = ["ElasticShare", "ElasticStrainRate", "ElasticStressInvariant", "ViscousStrainRate", "split_at"]


def _invariant(tensors: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
    """``sqrt(t : t / 2)`` of tensors shape=(n, gdim, gdim), shape=(n,)."""
    return np.sqrt(0.5 * np.einsum("nij,nij->n", tensors, tensors))


def _stress(swarm: Swarm, rows: npt.NDArray[np.int64], /) -> npt.NDArray[np.float64]:
    lay = swarm.layout(ElasticStress.name)
    return from_voigt(swarm.properties[rows, lay.start:lay.start + lay.size], swarm.gdim)


def split_at(swarm: Swarm, rows: npt.NDArray[np.int64], context: PropertyContext, /
             ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """The elastic and the total strain rate at the particles ``rows``, each shape=(m, gdim, gdim)
    (module docstring; ``context`` as for ``elastic_stress``)."""
    missing = [name for name in ElasticStress.mesh_fields if name not in context.fields]
    if missing:
        raise ValueError(f"the elastic strain rates need the mesh fields {missing} in the PropertyContext")
    eps = strain_rate(gradient_at(swarm, rows, context.require("velocity", "elastic_strain_rate"), context))
    eta_ve, chi = (evaluate_at(swarm, rows, context.fields[name], context).reshape(-1, 1, 1)
                   for name in ElasticStress.mesh_fields)
    viscous = (1.0 - chi) * _stress(swarm, rows) / (2.0 * eta_ve)
    return eps - viscous, eps


class _ElasticOutput(ParticleProperty):
    """An output computed from the particle's stress when the particles are written."""

    default_update: ClassVar[str] = "output_only"
    default_new_particles: ClassVar[str] = "reinitialise"
    mesh_fields: ClassVar[tuple[str, ...]] = ElasticStress.mesh_fields

    def requires(self) -> tuple[str, ...]:
        return (ElasticStress.name,)

    def size(self, gdim: int) -> int:
        return 1

    def values(self, swarm: Swarm, rows: npt.NDArray[np.int64], context: PropertyContext, /
               ) -> npt.NDArray[np.float64]:
        """The values at ``rows``, shape=(m, size)."""
        raise NotImplementedError

    def initialise(self, swarm: Swarm, rows: npt.NDArray[np.integer], context: PropertyContext) -> None:
        """Zero (the fields of the flow may not be on the particles' mesh yet: after an adaptation)."""
        write_rows(swarm, self.column, np.asarray(rows, dtype=np.int64), 0.0)

    def refresh(self, swarm: Swarm, context: PropertyContext) -> None:
        """Compute at every particle (zero before the first step)."""
        rows = np.arange(swarm.num_particles, dtype=np.int64)
        if context.dt > 0.0 and rows.size:
            write_rows(swarm, self.column, rows, self.values(swarm, rows, context))
        else:
            write_rows(swarm, self.column, rows, 0.0)


class ElasticStressInvariant(_ElasticOutput):
    """``elastic_stress_invariant = sqrt(tau : tau / 2)`` of the particle's stress."""

    name: ClassVar[str] = "elastic_stress_invariant"
    description: ClassVar[str] = "second invariant of the particle's deviatoric stress elastic_stress"
    mesh_fields: ClassVar[tuple[str, ...]] = ()

    def values(self, swarm: Swarm, rows: npt.NDArray[np.int64], context: PropertyContext, /
               ) -> npt.NDArray[np.float64]:
        return _invariant(_stress(swarm, rows))[:, None]

    def initialise(self, swarm: Swarm, rows: npt.NDArray[np.integer], context: PropertyContext) -> None:
        rows = np.asarray(rows, dtype=np.int64)
        write_rows(swarm, self.column, rows, self.values(swarm, rows, context))

    def refresh(self, swarm: Swarm, context: PropertyContext) -> None:
        self.initialise(swarm, np.arange(swarm.num_particles, dtype=np.int64), context)


class ElasticStrainRate(_ElasticOutput):
    """The elastic strain rate ``eps_el`` (Voigt columns)."""

    name: ClassVar[str] = "elastic_strain_rate"
    description: ClassVar[str] = "elastic part of the strain rate of a Maxwell material (3 columns in 2D, 6 in 3D)"

    def size(self, gdim: int) -> int:
        return 3 if gdim == 2 else 6

    def values(self, swarm: Swarm, rows: npt.NDArray[np.int64], context: PropertyContext, /
               ) -> npt.NDArray[np.float64]:
        return to_voigt(split_at(swarm, rows, context)[0])


class ViscousStrainRate(ElasticStrainRate):
    """The viscous strain rate ``eps_v = eps - eps_el`` (Voigt columns)."""

    name: ClassVar[str] = "viscous_strain_rate"
    description: ClassVar[str] = "viscous part of the strain rate of a Maxwell material (3 columns in 2D, 6 in 3D)"

    def values(self, swarm: Swarm, rows: npt.NDArray[np.int64], context: PropertyContext, /
               ) -> npt.NDArray[np.float64]:
        elastic, total = split_at(swarm, rows, context)
        return to_voigt(total - elastic)


class ElasticShare(_ElasticOutput):
    """``eps_el_II / eps_II``: the elastic share of the deformation at the particle."""

    name: ClassVar[str] = "elastic_share"
    description: ClassVar[str] = "elastic share of the deformation eps_el_II / eps_II of a Maxwell material"

    def values(self, swarm: Swarm, rows: npt.NDArray[np.int64], context: PropertyContext, /
               ) -> npt.NDArray[np.float64]:
        elastic, total = split_at(swarm, rows, context)
        el, tot = _invariant(elastic), _invariant(total)
        return np.divide(el, tot, out=np.zeros_like(el), where=tot > 0.0)[:, None]
