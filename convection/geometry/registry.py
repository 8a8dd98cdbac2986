"""The registry of geometries: ``mesh.geometry`` name -> :class:`convection.geometry.domain.Domain`
subclass. A new geometry is one class registered here."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from convection.geometry.box import BoxDomain
from convection.geometry.domain import Domain
from convection.geometry.sector import Sector
from convection.geometry.shell import Annulus, SphericalShell
from fembase.registry import Registry

__all__ = ["DOMAINS", "boundary_descriptions", "domain_from_config"]

DOMAINS: Registry[type[Domain]] = Registry("geometry", (BoxDomain, Annulus, SphericalShell, Sector))
"""Every geometry by its ``mesh.geometry`` name."""


def domain_from_config(config: Mapping[str, Any], /) -> Domain:
    """The domain of a resolved config (its ``mesh`` section)."""
    mesh = config["mesh"]
    return DOMAINS.lookup(mesh["geometry"]).from_config(mesh)


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
