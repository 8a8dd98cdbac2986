"""The registry of geometries: ``mesh.geometry`` name -> :class:`convection.geometry.domain.Domain`
subclass. A new geometry is one class registered here."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from convection.geometry.box import BoxDomain
from convection.geometry.domain import Domain, DomainContext, MeshSection
from convection.geometry.sector import Sector
from convection.geometry.shell import Annulus, SphericalShell
from convection.schema import Names, param, section_schema
from fembase.registry import Registry

__all__ = ["DOMAINS", "MeshSettings", "boundary_descriptions", "domain_from_settings", "mesh_section_schema"]

DOMAINS: Registry[type[Domain]] = Registry("geometry", (BoxDomain, Annulus, SphericalShell, Sector))
"""Every geometry by its ``mesh.geometry`` name."""


@dataclass(frozen=True)
class MeshSettings:
    """The ``mesh`` keys of every geometry: which one, and a bound on the cells."""

    geometry: str = param("box", choices=Names(DOMAINS),
                          help="box (cells, lower, upper), annulus or spherical_shell (radii, resolution), sector "
                               "(radii, angles, resolution)")
    max_cells: int = param(2_000_000, minimum=1,
                           help="refuse configs whose mesh can grow beyond this many cells (base x refinement)")


def mesh_section_schema() -> dict[str, Any]:
    """The ``mesh`` config section: ``geometry``, every geometry's keys
    (:attr:`~convection.geometry.domain.Domain.Settings`, in the order of :data:`DOMAINS`,
    a key shared by several geometries once), then ``max_cells``.

    Raises:
        ValueError: Two geometries declare one key differently.
    """
    common = section_schema(MeshSettings)
    out = {"geometry": common["geometry"]}
    for cls in DOMAINS.values():
        for key, field in section_schema(cls.Settings).items():
            if out.setdefault(key, field) != field:
                raise ValueError(f"mesh key {key!r} is declared differently by the {cls.name!r} geometry")
    out["max_cells"] = common["max_cells"]
    return out


def domain_from_settings(mesh: MeshSection, /) -> Domain:
    """The domain of a typed ``mesh`` section, built through :data:`DOMAINS`."""
    return DOMAINS.build(mesh.geometry, mesh.keys, DomainContext())


def boundary_descriptions() -> dict[str, str]:
    """Every boundary name of every geometry, with the geometries that have it and where it is:
    ``{"left": "box: x = lower", ..., "inner": "annulus, spherical_shell, sector: the inner
    surface r = r_inner", ...}``."""
    where: dict[str, dict[str, list[str]]] = {}
    for name, cls in DOMAINS.items():
        for boundary in cls.config_boundaries:
            where.setdefault(boundary, {}).setdefault(cls.boundary_descriptions[boundary], []).append(name)
    return {boundary: "; ".join(f"{', '.join(names)}: {text}" for text, names in texts.items())
            for boundary, texts in where.items()}
