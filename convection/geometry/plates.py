"""Plate-like surface velocities: rigid rotations of a few plates, smoothed across plate boundaries.

Each plate ``k`` has a centre ``c_k`` on the unit sphere, an Euler pole ``p_k`` (unit vector) and a
rotation rate ``omega_k``; its own velocity at ``x`` is the rigid rotation ``omega_k p_k x x``
(tangent to every sphere around the origin). The plates partition the surface like a Voronoi
diagram of their centres: the point ``x`` belongs to the plate whose centre is the nearest in
angle. The boundaries are smoothed over an angular ``width``: the velocity is the weighted mean

    u(x) = sum_k w_k(x) omega_k (p_k x x),    w_k = exp(-d_k / width) / sum_j exp(-d_j / width),

with ``d_k`` the angle between ``x`` and ``c_k``. Far from a boundary (``d_j - d_k >> width``)
the velocity is that plate's rigid rotation; across a boundary it changes over a few ``width``.
A mean of tangent vectors is tangent, so ``u . x = 0``: the pattern is a valid prescribed velocity
on a spherical surface (zero normal component).

In 2D (annulus) the poles are the z axis and the centres are angles: each plate is an arc moving
at ``omega_k (-y, x)``.

In a config, ``boundary.velocity.outer: {kind: plates, width: ..., plates: [...]}`` with plates
``{centre: [lon, lat], pole: [lon, lat], rate: omega}`` (degrees; 2D: ``centre: [lon]`` and no
pole), see ``configs/shell_plates.yaml``.
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from fembase.params import param

__all__ = ["Plate", "PlateVelocity", "plate_table_problem", "plate_width_problem", "unit_vector"]

_ENTRIES = ("centre", "pole", "rate")


def unit_vector(longitude: float, latitude: float = 0.0) -> npt.NDArray[np.float64]:
    """Unit vector at ``longitude``, ``latitude`` (degrees; x towards longitude 0, z to the north),
    shape=(3,)."""
    lon, lat = np.radians(longitude), np.radians(latitude)
    return np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])


def plate_table_problem(items: Any, /) -> str | None:
    """What is wrong with a plates velocity's ``plates: [{centre, pole, rate}, ...]`` as written
    (None: missing), naming the plate; None if nothing."""
    if not isinstance(items, (list, tuple)) or not items:
        return "a plates velocity needs 'plates: [{centre: [lon, lat], pole: [lon, lat], rate: r}, ...]'"
    for i, item in enumerate(items):
        if not isinstance(item, Mapping):
            return f"plates[{i}]: expected {{centre, pole, rate}}, got {item!r}"
        unknown = set(item) - set(_ENTRIES)
        if unknown or "centre" not in item or "rate" not in item:
            what = f"unknown entry {sorted(unknown)[0]!r}" if unknown else "needs centre and rate"
            return f"plates[{i}]: {what} (entries: centre, pole, rate)"
        try:
            Plate(tuple(item["centre"]), item["rate"], tuple(item.get("pole", (0.0, 90.0))))
        except (TypeError, ValueError, OverflowError) as err:  # TypeError: e.g. keys of mixed types
            return f"plates[{i}]: {err}"
    return None


def plate_width_problem(width: Any, /) -> str | None:
    """What is wrong with a plates velocity's ``width`` as written, or None."""
    try:
        number = float(width) if not isinstance(width, bool) else None
    except (TypeError, ValueError):
        number = None
    if number is None:
        return f"plates width must be a number, got {width!r}"
    return None if number > 0.0 else f"plates width must be positive (radians), got {number}"


@dataclass(frozen=True)
class Plate:
    """One rigid plate.

    Attributes:
        centre: ``(longitude, latitude)`` of the plate's centre in degrees (2D: ``(longitude,)``).
        rate: Rotation rate ``omega`` about the pole (radians per time unit; positive:
            counter-clockwise seen from above the pole).
        pole: ``(longitude, latitude)`` of the Euler pole in degrees (2D: the z axis, ignored).
    """

    centre: tuple[float, ...] = param(help="longitude, latitude of the plate's centre in degrees (2D: [longitude])")
    rate: float = param(help="rotation rate about the pole (radians per time unit; positive: counter-clockwise seen "
                        "from above the pole)")
    pole: tuple[float, ...] = param((0.0, 90.0), help="longitude, latitude of the Euler pole in degrees (2D: the z "
                                    "axis, ignored)")

    def __post_init__(self) -> None:
        object.__setattr__(self, "centre", tuple(float(c) for c in self.centre))
        object.__setattr__(self, "pole", tuple(float(c) for c in self.pole))
        object.__setattr__(self, "rate", float(self.rate))
        if len(self.centre) not in (1, 2) or len(self.pole) != 2:
            raise ValueError(f"a plate needs centre [lon, lat] (2D: [lon]) and pole [lon, lat], got {self}")
        if not np.isfinite(self.rate):
            raise ValueError(f"plate rate must be a finite number, got {self.rate}")

    @property
    def centre_vector(self) -> npt.NDArray[np.float64]:
        return unit_vector(*self.centre)

    @property
    def pole_vector(self) -> npt.NDArray[np.float64]:
        return unit_vector(*self.pole)


@dataclass(frozen=True)
class PlateVelocity:
    """The smoothed plate velocity field (see the module docstring), callable on points.

    Attributes:
        plates: The plates (at least one).
        width: Angular width of the plate boundaries in radians (> 0).
        gdim: 2 (annulus: rotations about z, centres by longitude) or 3.
    """

    plates: tuple[Plate, ...]
    width: float = 0.1
    gdim: int = 3

    def __post_init__(self) -> None:
        if not self.plates:
            raise ValueError("plates: give at least one plate")
        if not self.width > 0.0:
            raise ValueError(f"plates width must be positive (radians), got {self.width}")
        if self.gdim not in (2, 3):
            raise ValueError(f"plates need gdim 2 or 3, got {self.gdim}")

    def weights(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Plate weights ``w_k`` at points x (shape=(3, n)), shape=(num_plates, n); columns sum to 1."""
        points = np.array(x[:3], dtype=np.float64)
        if self.gdim == 2:
            points[2] = 0.0
        norm = np.linalg.norm(points, axis=0)
        unit = points / np.where(norm > 0.0, norm, 1.0)
        centres = np.stack([p.centre_vector if self.gdim == 3 else unit_vector(p.centre[0]) for p in self.plates])
        angle = np.arccos(np.clip(centres @ unit, -1.0, 1.0))
        logits = -(angle - angle.min(axis=0)) / self.width
        w = np.exp(logits)
        return w / w.sum(axis=0)

    def __call__(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Velocity at points x, shape=(3, n) (DOLFINx interpolation layout) -> shape=(gdim, n)."""
        points = np.array(x[:3], dtype=np.float64)
        if self.gdim == 2:
            points[2] = 0.0
        w = self.weights(points)
        u = np.zeros_like(points)
        for weight, plate in zip(w, self.plates):
            pole = plate.pole_vector if self.gdim == 3 else np.array([0.0, 0.0, 1.0])
            u += weight * plate.rate * np.cross(pole, points.T).T
        return u[: self.gdim]
