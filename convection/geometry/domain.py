"""The domain of a run (ASPECT's GeometryModel): the one object that knows its shape.

Every component asks the domain instead of testing "box or shell": the boundary names and which
are the top and the bottom, the gravity (``up``, depth and height), the facets of each boundary
(:meth:`Domain.facet_tags`), how free slip is imposed there (:meth:`Domain.normal_axis`), where
the pressure is pinned, whether rigid rotations solve the homogeneous Stokes problem, the
conductive reference of the Nusselt number, the mesh and its manifold (the map that curves refined
cells), how particles are kept inside, the probe points at which a config's expressions are
checked, and the checks and the cell estimate of its config section.

A geometry is one subclass registered in :data:`convection.geometry.registry.DOMAINS` (box,
annulus, spherical shell, sector), in the one plugin shape (docs/developers.md): its ``Settings``
declare its keys of the ``mesh`` section, and ``build(settings, context)`` makes the domain (with a
:class:`DomainContext`). ``mesh.geometry`` in a config names it.
"""

from __future__ import annotations

import dataclasses
import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Any, ClassVar, NamedTuple, Protocol, runtime_checkable

import dolfinx
import numpy as np
import numpy.typing as npt
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from convection.geometry.gravity import Gravity
from fembase.dolfinx_compat import DirichletBC

__all__ = ["Columns", "Domain", "DomainContext", "LevelsByRefinement", "MeshSection", "keep_boundary_facets",
           "kept_facets", "safe_product"]

_KEPT_FACETS = "_convection_kept_facets"
_FACET_TAGS = "_convection_facet_tags"


def keep_boundary_facets(domain: Domain, mesh: dolfinx.mesh.Mesh, /) -> None:
    """Find the facets of every boundary of ``mesh`` now and keep them with the mesh: a mesh whose
    nodes move (a free surface) keeps its boundaries where they were found on the undeformed mesh
    (the domains find them by their coordinates, which the motion changes). Collective."""
    kept = {name: domain.locate_facets(mesh, name) for name in domain.boundaries}
    setattr(mesh, _KEPT_FACETS, kept)


def kept_facets(mesh: dolfinx.mesh.Mesh, name: str, /) -> npt.NDArray[np.int32] | None:
    """The facets of boundary ``name`` kept by :func:`keep_boundary_facets`, or None."""
    kept = getattr(mesh, _KEPT_FACETS, None)
    return None if kept is None else kept[name]


def safe_product(*factors: float) -> float:
    """The product of non-negative numbers as a float: inf instead of an overflow (so an estimate
    from ``cells: [1e18, 4]`` or ``max_level: 10**12`` is a number to compare, not an error)."""
    logs = [math.log2(f) if f > 0 else -math.inf for f in map(float, factors)]
    if -math.inf in logs:
        return 0.0
    total = sum(logs)
    return math.inf if total >= 1024 else 2.0**total


@dataclasses.dataclass(frozen=True)
class Columns:
    """Sample points on lines along ``up`` (:meth:`Domain.columns`).

    Attributes:
        positions: Where each line is, across the domain, shape=(n, gdim - 1).
        points: The samples, shape=(n, m, 3): ``m`` midpoints of equal segments of each line.
        length: The length of the lines (each sample stands for ``length / m``).
        top: The height of the top end of the lines.
    """

    positions: npt.NDArray[np.float64]
    points: npt.NDArray[np.float64]
    length: float
    top: float


@dataclasses.dataclass(frozen=True)
class MeshSection:
    """A checked ``mesh`` config section, typed.

    Attributes:
        geometry: The geometry's name (a key of :data:`convection.geometry.registry.DOMAINS`).
        keys: The geometry's own keys: an instance of its :attr:`Domain.Settings`.
        max_cells: The most cells a run's mesh may reach.
    """

    geometry: str
    keys: Any
    max_cells: int


class DomainContext(NamedTuple):
    """What a domain is made from beside its settings: nothing yet (a geometry is made from its
    ``mesh`` keys alone; one that needs more, such as the folder of a mesh file, adds it here)."""


class Domain(ABC):
    """What a run needs to know about its domain (see the module docstring).

    Class attributes:
        name: The ``mesh.geometry`` name.
        description: One line for the config reference.
        Settings: The settings dataclass declaring the ``mesh`` section keys this geometry
            reads besides ``geometry`` and ``max_cells`` (:func:`convection.schema.param` fields;
            the config schema is made from it).
        config_keys: Their names (from ``Settings``); a config's other keys are refused.
        config_boundaries: The boundary names the ``boundary`` sections of its configs hold.
        size_key: The ``mesh`` key that sets the base mesh's size (named when a mesh is too large).
        boundary_descriptions: Where each of ``config_boundaries`` is (config reference).
        top, bottom: The boundary names of the top and bottom surfaces.
        refinable: Whether runs on it may adapt and repartition (refine a base mesh).
        free_surfaces: The boundaries that may be a free surface (:mod:`convection.deform`; the
            mesh moves along ``up`` there).

    Attributes:
        gdim: Geometric dimension.
        boundaries: The boundary names, in the order of their facet tags (1, 2, ...).
    """

    name: ClassVar[str]
    description: ClassVar[str]
    Settings: ClassVar[type]
    config_keys: ClassVar[tuple[str, ...]]
    config_boundaries: ClassVar[tuple[str, ...]]
    size_key: ClassVar[str] = "resolution"
    boundary_descriptions: ClassVar[dict[str, str]]
    top: ClassVar[str]
    bottom: ClassVar[str]
    refinable: ClassVar[bool] = True
    axis_aligned: ClassVar[bool] = False  # every boundary a plane normal to an axis (normal_axis never None)
    free_surfaces: ClassVar[tuple[str, ...]] = ()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "Settings" in cls.__dict__:
            cls.config_keys = tuple(f.name for f in dataclasses.fields(cls.Settings))

    gdim: int
    boundaries: tuple[str, ...]

    # ------------------------------------------------------------------ config
    @classmethod
    @abstractmethod
    def build(cls, settings: Any, context: DomainContext, /) -> Domain:
        """The domain of a checked ``mesh`` section's keys (a ``Settings``, checked by
        :meth:`check_config`)."""

    @classmethod
    @abstractmethod
    def config_gdim(cls, mesh: MeshSection, /) -> int:
        """The dimension of a ``mesh`` section of this geometry."""

    @classmethod
    def check_config(cls, mesh: MeshSection, /, *, changed_by: str | None) -> None:
        """Refuse a ``mesh`` section this geometry cannot take (ConfigError naming the key); ``changed_by``: the
        key that changes the mesh in the run (``adaptivity.enabled``, ``balance.strategy``), None for a fixed mesh."""

    @classmethod
    def check_boundaries(cls, mesh: MeshSection, boundary: Any, /) -> None:
        """Refuse conditions (``boundary``: a ``BoundarySettings``) this geometry cannot take."""

    @classmethod
    @abstractmethod
    def base_cells_bound(cls, mesh: MeshSection, /) -> float:
        """Cells of the base mesh of a checked ``mesh`` section, estimated for the size check:
        a float, ``inf`` rather than an overflow."""

    @property
    def curved(self) -> bool:
        """Whether the cells are curved (particle generators that need straight cells refuse)."""
        return False

    def expression_constants(self) -> dict[str, float]:
        """Named constants this domain adds to a config's expressions."""
        return {}

    def contains(self, points: npt.ArrayLike, /) -> npt.NDArray[np.bool_] | None:
        """Whether each point (shape=(n, gdim)) lies in the domain (its closure, to a relative
        1e-12), shape=(n,); None: this geometry cannot tell without a mesh (the default)."""
        return None

    def columns(self, across: int, along: int, /) -> Columns | None:
        """Sample points on lines along ``up`` through the whole domain, for integrals along them
        (the height of a material interface): ``across`` lines, ``along`` midpoint samples on each.
        None: this geometry has no such columns (the default)."""
        return None

    @abstractmethod
    def probe_axes(self, level: int, /) -> tuple[list[npt.NDArray[np.float64]], Callable]:
        """The probe grid of :mod:`convection.geometry.probes`: coordinates along each grid axis
        (``level``: the finest adaptivity level) and the map from grid coordinates
        shape=(gdim, n) to points shape=(3, n)."""

    @abstractmethod
    def boundary_axis(self, name: str, /) -> tuple[int, bool]:
        """The probe grid axis on which boundary ``name`` is one end, and whether the upper one."""

    # ------------------------------------------------------------------ shape
    @property
    @abstractmethod
    def gravity(self) -> Gravity:
        """Which way is up (:mod:`convection.geometry.gravity`)."""

    def up(self, x: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
        """Unit up vectors at points ``x`` (shape=(n, gdim) or (n, 3)), shape=(n, gdim)."""
        return self.gravity.up_at(np.asarray(x, dtype=np.float64)[:, : self.gdim])

    def inward(self, x: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
        """Unit directions into the domain from its moving surface at points ``x`` (shape=(n,
        gdim)), shape=(n, gdim): down (:func:`particles.relocation.moving_mesh.pull_in` follows them)."""
        return -self.up(x)

    def check_boundary_names(self, names: Any, /) -> None:
        """Raise ValueError naming the valid names if ``names`` holds one that is not a boundary."""
        unknown = [n for n in names if n not in self.boundaries]
        if unknown:
            raise ValueError(f"Unknown boundary name(s) {unknown} of the {self.name}; valid names: "
                             f"{list(self.boundaries)}")

    # ------------------------------------------------------------------ mesh
    @abstractmethod
    def create_mesh(self, comm: MPI.Comm, /, *, owners: npt.NDArray[np.int32] | None = None,
                    straight: bool = False) -> dolfinx.mesh.Mesh:
        """The base mesh (collective) on a reproducible partition; ``owners``: a partition to
        impose (owner rank per cell by input index, on rank 0); ``straight``: straight-sided cells
        even where the domain is curved (what a mesh hierarchy refines)."""

    def mesh_levels(self, wanted: int = 0, /) -> int:
        """How many nested meshes, coarse to fine and the base mesh the finest, this domain can make
        for geometric multigrid (:meth:`create_mesh_levels`): ``wanted`` if it can, or, with 0, as
        many as it can. 1: no coarser mesh.

        Raises:
            ValueError: ``wanted`` levels cannot be made (one line, saying why)."""
        if wanted > 1:
            raise ValueError(f"the {self.name} domain cannot make meshes coarser than its mesh "
                             "(geometric multigrid: a box whose cells halve)")
        return 1

    def create_mesh_levels(self, comm: MPI.Comm, levels: int, /, *, owners: npt.NDArray[np.int32] | None = None
                           ) -> list[dolfinx.mesh.Mesh]:
        """``levels`` nested meshes, coarse to fine, the finest the base mesh (:meth:`create_mesh`),
        every cell on the rank of the coarser cell it lies in (collective); ``owners``: the finest
        mesh's partition to impose (owner rank per cell by input index, on rank 0).

        Raises:
            ValueError: The domain cannot make them (:meth:`mesh_levels`)."""
        self.mesh_levels(levels)
        return [self.create_mesh(comm, owners=owners)]

    @abstractmethod
    def estimated_cells(self) -> float:
        """Cells of the base mesh (an estimate where a mesh generator decides)."""

    def manifold(self) -> Any:
        """What places the geometry nodes of refined cells (:mod:`fembase.manifold`), or None when
        refined cells stay straight."""
        return None

    def confinement(self, mesh: dolfinx.mesh.Mesh, /, *, free: tuple[str, ...] = ()
                    ) -> Callable[[npt.NDArray[np.float64]], None] | None:
        """``confine(x)`` that moves particles outside the domain back in (points shape=(n, gdim),
        in place; collective to build), or None when straight walls need none; ``free``: free
        surfaces, which move (particles are not held at them)."""
        return None

    # ------------------------------------------------------------------ boundaries
    @abstractmethod
    def locate_facets(self, mesh: dolfinx.mesh.Mesh, name: str, /) -> npt.NDArray[np.int32]:
        """Local indices of the boundary facets of boundary ``name``. Collective."""

    def facet_tags(self, mesh: dolfinx.mesh.Mesh, /) -> dolfinx.mesh.MeshTags:
        """Facet tags of the boundaries: ``boundaries[i]`` gets value ``i + 1``. Collective on the
        first call for a mesh; later calls return the same tags (the measures of one form must
        share them: e.g. Nitsche's free slip inside and a free surface outside)."""
        cached = getattr(mesh, _FACET_TAGS, None)
        if cached is not None and cached[0] == self.boundaries:
            return cached[1]
        tags = self.tag_facets(mesh, self._boundary_facets(mesh))
        setattr(mesh, _FACET_TAGS, (self.boundaries, tags))
        return tags

    def _boundary_facets(self, mesh: dolfinx.mesh.Mesh, /) -> list[npt.NDArray[np.int32]]:
        """The facets of every boundary, in the order of :attr:`boundaries`. Collective."""
        return [self.locate_facets(mesh, name) for name in self.boundaries]

    @staticmethod
    def tag_facets(mesh: dolfinx.mesh.Mesh, facets: list[npt.NDArray[np.int32]], /) -> dolfinx.mesh.MeshTags:
        """Facet tags from the facets of each boundary (``facets[i]`` gets ``i + 1``; a facet on two
        boundaries, e.g. at a box corner, keeps the first)."""
        idx = np.concatenate(facets)
        val = np.concatenate([np.full(f.shape, i + 1, dtype=np.int32) for i, f in enumerate(facets)])
        order = np.argsort(idx, kind="stable")
        idx, val = idx[order], val[order]
        keep = np.ones(idx.shape, dtype=bool)
        keep[1:] = idx[1:] != idx[:-1]
        return dolfinx.mesh.meshtags(mesh, mesh.topology.dim - 1, idx[keep], val[keep])

    def tag(self, name: str, /) -> int:
        """The facet tag value of boundary ``name`` in :meth:`facet_tags`."""
        self.check_boundary_names([name])
        return self.boundaries.index(name) + 1

    def measure(self, mesh: dolfinx.mesh.Mesh, name: str, /, *, tags: dolfinx.mesh.MeshTags | None = None,
                metadata: dict | None = None) -> ufl.Measure:
        """``ds`` restricted to boundary ``name``; ``tags``: :meth:`facet_tags` to share between
        measures of one form (built if omitted; collective then)."""
        tags = self.facet_tags(mesh) if tags is None else tags
        return ufl.Measure("ds", domain=mesh, subdomain_data=tags, metadata=metadata or {})(self.tag(name))

    def locate_dofs(self, V: dolfinx.fem.FunctionSpace, name: str, /) -> npt.NDArray[np.int32]:
        """Local dof indices of ``V`` (a space or sub-space) on boundary ``name``. Collective."""
        return dolfinx.fem.locate_dofs_topological(V, V.mesh.topology.dim - 1, self.locate_facets(V.mesh, name))

    def normal_axis(self, name: str, /) -> int | None:
        """The coordinate axis normal to boundary ``name`` if it is a plane normal to an axis
        (free slip is then a zero Dirichlet condition on that velocity component); None where the
        normal varies or is oblique (free slip is then weak, by Nitsche's method)."""
        return None

    def pressure_pin(self, Q: dolfinx.fem.FunctionSpace, /) -> DirichletBC:
        """Zero Dirichlet condition on one pressure dof, which removes the constant pressure from a
        direct solve: the dof numbered 0 globally (whichever point that is). Collective."""
        owns_first = Q.mesh.comm.rank == 0 and Q.dofmap.index_map.size_local > 0
        dofs = np.arange(1 if owns_first else 0, dtype=np.int32)
        return dolfinx.fem.dirichletbc(PETSc.ScalarType(0.0), dofs, Q)

    def has_rotations(self, free_slip: set[str], /) -> bool:
        """Whether rigid rotations about the origin solve the homogeneous Stokes problem when the
        boundaries ``free_slip`` are free slip and the others have a velocity condition."""
        return False

    # ------------------------------------------------------------------ heat flow
    def opposite(self, name: str, /) -> tuple[str, str]:
        """The pair ``(lower, upper)`` of boundaries across which the heat flow through ``name``
        is measured (``name`` is one of them): bottom and top, left and right, inner and outer."""
        if name in (self.bottom, self.top):
            return self.bottom, self.top
        raise ValueError(f"no Nusselt number through {name!r} of the {self.name}; through {self.bottom!r} or "
                         f"{self.top!r}")

    @abstractmethod
    def nusselt(self, mesh: dolfinx.mesh.Mesh, name: str, heat_flow: float, delta_T: float, area: float, /) -> float:
        """The Nusselt number through boundary ``name``: the heat flow from its ``lower`` to its
        ``upper`` boundary (:meth:`opposite`) over the conductive heat flow of the temperature
        difference ``delta_T`` between their means (``area``: the measure of ``name``). Collective."""


@runtime_checkable
class LevelsByRefinement(Protocol):
    """A domain whose geometric-multigrid levels on a fixed mesh are made by refining a coarser base
    uniformly (a gmsh shell: :class:`convection.geometry.shell.ShellDomain`), not by coarsening its
    base (a box: :meth:`Domain.create_mesh_levels`). With ``L`` levels (:meth:`Domain.mesh_levels`)
    the run's mesh is the base of ``coarsened(L - 1)`` refined uniformly ``L - 1`` times; on an
    adaptive or repartitioned mesh the refinement rounds are the levels instead."""

    def coarsened(self, refinements: int, /) -> Domain:
        """The domain whose base mesh, refined uniformly ``refinements`` times, makes this domain's
        mesh."""
