"""Statistics geodynamicists read off a model: per-material statistics (a sinking block's velocity,
a slab tip's depth) and the values of the fields at named points.

``materials`` (one group of columns per material ``<m>``, with fraction ``C``, volume ``V = int C``,
``e_up`` the up direction and ``d`` the depth below the top surface)::

    volume_<m>       V                                      (an area in 2D)
    x_<m>, y_<m>,    centroid int C x / V (per axis: x, y in 2D; x, y, z in 3D)
    vup_<m>          int C u . e_up / V                     (mean upward velocity: < 0 sinks)
    vrms_<m>         sqrt(int C |u|^2 / V)
    vmax_<m>         largest cell-average |u| of the cells the material fills at least half
    depth_<m>        largest cell-average depth of those cells (the deepest point: a slab's tip)

(cell averages ``int_K f / |K|`` of the cells ``K`` whose average fraction is at least 0.5; so
``depth`` is resolution-limited to about half a cell).

``points``: for every point of ``diagnostics.points`` (``{name: [x, y(, z)]}``) and every field of
the field output (temperature, velocity components, pressure, material fractions, viscosity where
it varies, ...), the column ``<field>_<name>`` (a vector field: ``<field>_x_<name>``, ...; the
velocity ``vx_<name>``, ``vy_<name>`` (, ``vz_<name>``)), evaluated in the owned cell that holds
the point (the lowest rank's where several do). A cell field (the viscosity, ``strain_rate_II``)
jumps across the cells' faces: at a point on a face it takes one of the cells' values, which may
differ between rank counts -- keep such points off the faces.

``topography``: with a free surface (:mod:`convection.deform`), the height ``h`` of the surface's
nodes above the box's top (the reference level): ``topography_max``, ``topography_min`` and
``topography_rms`` of ``h`` itself, and the profile ``h`` at every node (x, y). Without one, the
height of the surface under the material ``diagnostics.topography_material``
(sticky air) that fills the top of a box: along vertical lines at ``x_j``,

    h(x_j) = z_top - int C dz          (midpoint samples, 8 per cell height),

and ``topography_max``, ``topography_min``, ``topography_rms`` of ``h - mean_j h`` (the mean over
the lines: the undisturbed level, which the material's volume keeps). Whenever the fields are
written, the profile ``h(x_j) - mean h`` is written too (``topography_profile.csv``: one row per
line and output time, in the model's units).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
import ufl
from mpi4py import MPI

import dolfinx.fem
import dolfinx.fem.petsc

from convection.model.model import Model
from convection.physics.scaling import FIELD_KINDS
from convection.postprocess.base import DiagnosticsSettings, Forms, ModelFeatures, PostprocessorContext, integral
from convection.schema import ConfigError
from fembase.dolfinx_compat import function_space, value_size
from fembase.geometry import locate_owned
from fembase.state import Stateful

__all__ = ["FreeSurfaceStatistics", "FreeSurfaceTopography", "MaterialStatistics", "PointValues", "Topography"]

_AXES = ("x", "y", "z")


class MaterialStatistics(Stateful):
    """Volume, centroid, velocities and deepest point of every material (module docstring)."""

    name: ClassVar[str] = "materials"
    description: ClassVar[str] = ("per material: volume, centroid, mean upward velocity, rms and largest speed, "
                                  "deepest point")
    Settings: ClassVar[type] = DiagnosticsSettings

    def __init__(self, names: list[str], gdim: int) -> None:
        self.names = names
        self.gdim = gdim
        self.columns = tuple(c for n in names for c in self._columns(n))
        self.quantities = {f"volume_{n}": "area" if gdim == 2 else "volume" for n in names}
        for n in names:
            self.quantities |= {f"{a}_{n}": "length" for a in _AXES[:gdim]} | {f"depth_{n}": "length"}
            self.quantities |= dict.fromkeys((f"vup_{n}", f"vrms_{n}", f"vmax_{n}"), "velocity")
        self._forms = Forms()

    def _columns(self, n: str) -> tuple[str, ...]:
        return (f"volume_{n}", *(f"{a}_{n}" for a in _AXES[: self.gdim]), f"vup_{n}", f"vrms_{n}", f"vmax_{n}",
                f"depth_{n}")

    @classmethod
    def missing(cls, features: ModelFeatures) -> str | None:
        return None if features.materials else "needs materials (the materials section or initial.composition)"

    @classmethod
    def by_default(cls, model: Model) -> bool:
        return False

    @classmethod
    def build(cls, settings: DiagnosticsSettings, context: PostprocessorContext, /) -> MaterialStatistics | None:
        model = context.model
        names = [f.name for f in model.fractions]
        return cls(names, model.domain.gdim) if names else None

    def _build(self, model: Model) -> dict[str, Any]:
        mesh = model.mesh
        x = ufl.SpatialCoordinate(mesh)
        u = model.stokes.u
        gravity = model.domain.gravity
        cells = function_space(mesh, "DG", 0)
        v = ufl.TestFunction(cells)
        speed = ufl.sqrt(ufl.inner(u, u))
        forms: dict[str, Any] = {"cell_volume": dolfinx.fem.form(v * ufl.dx),
                                 "cell_speed": dolfinx.fem.form(speed * v * ufl.dx),
                                 "cell_depth": dolfinx.fem.form(gravity.depth(x) * v * ufl.dx)}
        for n, C in zip(self.names, model.fractions):
            forms[f"volume_{n}"] = dolfinx.fem.form(C * ufl.dx)
            for i, a in enumerate(_AXES[: self.gdim]):
                forms[f"{a}_{n}"] = dolfinx.fem.form(C * x[i] * ufl.dx)
            forms[f"vup_{n}"] = dolfinx.fem.form(C * ufl.dot(u, gravity.up(x)) * ufl.dx)
            forms[f"vrms_{n}"] = dolfinx.fem.form(C * ufl.inner(u, u) * ufl.dx)
            forms[f"cell_{n}"] = dolfinx.fem.form(C * v * ufl.dx)
        return forms

    def __call__(self, model: Model, /) -> dict[str, float]:
        forms = self._forms.get(model, lambda: self._build(model))
        owned = model.mesh.topology.index_map(model.mesh.topology.dim).size_local
        cell = {name: _cell_integrals(forms[f"cell_{name}"], owned) for name in ("volume", "speed", "depth")}
        out: dict[str, float] = {}
        for n in self.names:
            volume = integral(model, forms[f"volume_{n}"])
            scale = 1.0 / volume if volume > 0.0 else np.nan
            out[f"volume_{n}"] = volume
            for a in _AXES[: self.gdim]:
                out[f"{a}_{n}"] = integral(model, forms[f"{a}_{n}"]) * scale
            out[f"vup_{n}"] = integral(model, forms[f"vup_{n}"]) * scale
            out[f"vrms_{n}"] = float(np.sqrt(max(integral(model, forms[f"vrms_{n}"]), 0.0) * scale))
            filled = _cell_integrals(forms[f"cell_{n}"], owned) >= 0.5 * cell["volume"]
            for column, what in ((f"vmax_{n}", "speed"), (f"depth_{n}", "depth")):
                local = float((cell[what][filled] / cell["volume"][filled]).max(initial=-np.inf))
                best = model.comm.allreduce(local, op=MPI.MAX)
                out[column] = best if np.isfinite(best) else np.nan
        return out


def _cell_integrals(form: Any, owned: int) -> np.ndarray:
    """``int_K f`` of every owned cell ``K`` (a DG0 vector form; no ghost exchange needed)."""
    vector = dolfinx.fem.petsc.assemble_vector(form)
    values = vector.array[:owned].copy()
    vector.destroy()
    return values


class PointValues(Stateful):
    """The fields at named points (module docstring)."""

    name: ClassVar[str] = "points"
    description: ClassVar[str] = "every output field at the points of diagnostics.points"
    Settings: ClassVar[type] = DiagnosticsSettings

    def __init__(self, points: Mapping[str, list[float]], fields: Mapping[str, int], gdim: int) -> None:
        self.points = {name: np.asarray(x, dtype=np.float64) for name, x in points.items()}
        self.fields = dict(fields)  # field name -> number of components
        self.gdim = gdim
        self.columns = tuple(c for p in self.points for f, size in self.fields.items() for c in self._names(f, size, p))
        self.quantities = {c: FIELD_KINDS[f] for p in self.points for f, size in self.fields.items()
                           if f in FIELD_KINDS for c in self._names(f, size, p)}
        self._version: int | None = None
        self._samples: _Samples | None = None

    @staticmethod
    def _names(field: str, size: int, point: str) -> list[str]:
        if size == 1:
            return [f"{'T' if field == 'temperature' else 'p' if field == 'pressure' else field}_{point}"]
        prefix = "v" if field == "velocity" else f"{field}_"
        if size > len(_AXES):  # a tensor (the elastic stress): xx, xy, yx, yy (3D: xx, ..., zz)
            axes = _AXES[:round(size ** 0.5)]
            return [f"{prefix}{a}{b}_{point}" for a in axes for b in axes]
        return [f"{prefix}{a}_{point}" for a in _AXES[:size]]

    @classmethod
    def missing(cls, features: ModelFeatures) -> str | None:
        return None if features.points else "needs diagnostics.points ({name: [x, y(, z)]})"

    @classmethod
    def by_default(cls, model: Model) -> bool:
        return False

    @classmethod
    def build(cls, settings: DiagnosticsSettings, context: PostprocessorContext, /) -> PointValues | None:
        model = context.model
        if not settings.points:
            return None
        fields = {name: value_size(f.function_space) for name, f in model.fields().items()}
        return cls(settings.points, fields, model.domain.gdim)

    def _locate(self, model: Model) -> None:
        """Which rank evaluates which point (collective)."""
        x = np.zeros((len(self.points), 3))
        x[:, : self.gdim] = np.array([p[: self.gdim] for p in self.points.values()]).reshape(-1, self.gdim)
        self._samples = _Samples(model, x)
        if self._samples.outside.any():
            name = list(self.points)[int(np.flatnonzero(self._samples.outside)[0])]
            raise ConfigError(f"config key 'diagnostics.points.{name}': {self.points[name].tolist()} is not in the "
                              "domain")
        self._version = model.mesh_version

    def __call__(self, model: Model, /) -> dict[str, float]:
        if self._version != model.mesh_version or self._samples is None:
            self._locate(model)
        samples = self._samples
        fields = model.fields()
        values = np.zeros((len(self.points), sum(self.fields.values())))
        start = 0
        for name, size in self.fields.items():
            if len(samples.rows):
                found = np.asarray(fields[name].eval(samples.points, samples.cells)).reshape(len(samples.rows), -1)
                values[samples.rows, start: start + size] = found[:, :size]
            start += size
        total = np.zeros_like(values)
        model.comm.Allreduce(values, total, op=MPI.SUM)
        return dict(zip(self.columns, total.ravel().tolist()))


class _Samples:
    """Points evaluated each on one rank: the lowest that owns a cell holding it (collective)."""

    def __init__(self, model: Model, points: np.ndarray) -> None:
        gdim = model.domain.gdim
        cells = locate_owned(model.mesh, points[:, :gdim]).cells
        rank = np.where(cells >= 0, model.comm.rank, model.comm.size).astype(np.int64)
        lowest = np.empty_like(rank)
        model.comm.Allreduce(rank, lowest, op=MPI.MIN)
        mine = lowest == model.comm.rank
        self.outside = lowest == model.comm.size
        self.rows = np.flatnonzero(mine)
        self.points = np.ascontiguousarray(points[mine])
        self.cells = cells[mine]


class Topography(Stateful):
    """The surface under a material that fills the top (module docstring)."""

    name: ClassVar[str] = "topography"
    description: ClassVar[str] = "max, min and rms height of the surface under diagnostics.topography_material"
    Settings: ClassVar[type] = DiagnosticsSettings
    columns = ("topography_max", "topography_min", "topography_rms")
    quantities: ClassVar[Mapping[str, str]] = dict.fromkeys(columns, "length")

    def __init__(self, index: int) -> None:
        self.index = index
        self._version: int | None = None
        self._samples: _Samples | None = None
        self._shape = (0, 0)
        self._length, self._top = 0.0, 0.0

    @classmethod
    def missing(cls, features: ModelFeatures) -> str | None:
        if features.free_surface:
            return None
        if not features.columns:
            return "needs vertical columns through the domain (a box)"
        return None if features.topography_material is not None else \
            "needs a free surface, or diagnostics.topography_material (the material above the surface, e.g. sticky air)"

    @classmethod
    def by_default(cls, model: Model) -> bool:
        return False

    @classmethod
    def build(cls, settings: DiagnosticsSettings, context: PostprocessorContext, /) -> Topography | None:
        model = context.model
        if model.free_surface is not None:
            return FreeSurfaceTopography(0)
        names = [f.name for f in model.fractions]
        if settings.topography_material not in names or model.domain.columns(1, 1) is None:
            return None
        return cls(names.index(settings.topography_material))

    def _sample(self, model: Model) -> None:
        gdim = model.domain.gdim
        per_side = max(4, round((model.num_cells / (2 if gdim == 2 else 6)) ** (1.0 / gdim)))
        columns = model.domain.columns(2 * per_side, 8 * per_side)
        assert columns is not None
        self._shape = columns.points.shape[:2]
        self._positions = columns.positions
        self._length, self._top = columns.length, columns.top
        self._samples = _Samples(model, columns.points.reshape(-1, 3))
        self._version = model.mesh_version

    def heights(self, model: Model) -> np.ndarray:
        """h at every line, shape=(n,) (collective)."""
        if self._version != model.mesh_version or self._samples is None:
            self._sample(model)
        samples = self._samples
        values = np.zeros(self._shape[0] * self._shape[1])
        if len(samples.rows):
            values[samples.rows] = np.asarray(model.fractions[self.index].eval(samples.points, samples.cells)).ravel()
        local = values.reshape(self._shape).sum(axis=1)
        total = np.zeros_like(local)
        model.comm.Allreduce(local, total, op=MPI.SUM)
        return self._top - total * self._length / self._shape[1]

    profile_quantities: ClassVar[dict[str, str]] = {"x": "length", "y": "length", "topography": "length"}

    def profile(self, model: Model, /) -> dict[str, np.ndarray]:
        """The surface now, for the field output: the lines' horizontal coordinates (``x``, and
        ``y`` in 3D) and ``h - mean h`` there (``topography``), each shape=(n,) (collective)."""
        h = self.heights(model)
        out = {axis: self._positions[:, i].copy() for i, axis in enumerate(_AXES[: self._positions.shape[1]])}
        return {**out, "topography": h - h.mean()}

    def __call__(self, model: Model, /) -> dict[str, float]:
        h = self.heights(model)
        relative = h - h.mean()
        return {"topography_max": float(relative.max()), "topography_min": float(relative.min()),
                "topography_rms": float(np.sqrt(np.mean(relative**2)))}


class FreeSurfaceTopography(Topography):
    """The free surface's nodes' heights above the reference level (module docstring)."""

    def _surface(self, model: Model) -> tuple[np.ndarray, np.ndarray]:
        """Every rank's owned surface nodes, gathered in the order of their positions: positions
        across the surface, shape=(n, gdim - 1) (a box: the horizontal coordinates; an annulus:
        ``x, y`` of the nodes, shape=(n, 2), in the order of their angle), and heights, shape=(n,)
        (collective)."""
        x, h = model.free_surface.heights()
        radial = model.domain.gravity.up_axis(model.domain.gdim) is None
        gathered = model.comm.allgather((x if radial else x[:, :-1], h))
        across = np.concatenate([g[0] for g in gathered])
        heights = np.concatenate([g[1] for g in gathered])
        if radial and across.shape[1] == 2:
            order = np.argsort(np.arctan2(across[:, 1], across[:, 0]), kind="stable")
        else:
            order = np.lexsort(across.T[::-1]) if across.size else np.zeros(0, dtype=np.int64)
        return across[order], heights[order]

    def heights(self, model: Model) -> np.ndarray:
        return self._surface(model)[1]

    def profile(self, model: Model, /) -> dict[str, np.ndarray]:
        across, h = self._surface(model)
        out = {axis: across[:, i].copy() for i, axis in enumerate(_AXES[: across.shape[1]])}
        return {**out, "topography": h}

    def __call__(self, model: Model, /) -> dict[str, float]:
        h = self.heights(model)
        return {"topography_max": float(h.max()), "topography_min": float(h.min()),
                "topography_rms": float(np.sqrt(np.mean(h**2)))}


class FreeSurfaceStatistics(Stateful):
    """The mesh of a free surface: its worst cell, and the particles the sinking surface passed."""

    name: ClassVar[str] = "free_surface"
    description: ClassVar[str] = ("mesh_quality_min (the worst cell's shape, 1: equilateral) and particles_pulled_in "
                                  "(particles moved back under the surface, so far)")
    Settings: ClassVar[type] = DiagnosticsSettings
    columns = ("mesh_quality_min", "particles_pulled_in")

    @classmethod
    def missing(cls, features: ModelFeatures) -> str | None:
        return None if features.free_surface else "needs a free surface (boundary.velocity.top: free_surface)"

    @classmethod
    def by_default(cls, model: Model) -> bool:
        return model.free_surface is not None

    @classmethod
    def build(cls, settings: DiagnosticsSettings, context: PostprocessorContext, /) -> FreeSurfaceStatistics | None:
        return cls() if context.model.free_surface is not None else None

    def __call__(self, model: Model, /) -> dict[str, float]:
        pulled = model.particles.pulled_in if model.particles is not None else 0
        return {"mesh_quality_min": model.free_surface.quality_min, "particles_pulled_in": pulled}
