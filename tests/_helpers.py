"""Helpers shared by several test modules (``from _helpers import ...``; pytest puts tests/ on the path)."""

import numpy as np
import numpy.typing as npt
import pytest
from mpi4py import MPI

import dolfinx.mesh

from convection.solvers.petsc_options import HAS_HYPRE
from fembase.evaluation import locate
from particles import Swarm

needs_hypre = pytest.mark.skipif(not HAS_HYPRE, reason="this PETSc has no hypre (BoomerAMG), as PyPI's DOLFINx wheel")
"""For tests of the BoomerAMG solvers (the Stokes solver "iterative")."""

ITERATIVE = pytest.param("iterative", marks=needs_hypre)
"""The Stokes solver "iterative" as a test parameter, skipped without hypre."""


def swarm_at(mesh: dolfinx.mesh.Mesh, points: npt.ArrayLike) -> Swarm:
    """Swarm with particle ``i`` at ``points[i]`` (collective; the same points on every rank).

    Args:
        mesh: The mesh.
        points: shape=(m, gdim). A point in no owned cell of any rank is left out; a point on a
            partition boundary goes to the lowest rank that owns a cell containing it.
    """
    swarm = Swarm(mesh)
    pts = np.asarray(points, dtype=np.float64)
    found = locate(mesh, pts, geometry=swarm.geometry)
    mine = (found.cells >= 0) & (found.cells < swarm.num_owned_cells)
    if mesh.comm.size > 1:
        owner = np.where(mine, mesh.comm.rank, mesh.comm.size).astype(np.int32)
        lowest = np.empty_like(owner)
        mesh.comm.Allreduce(owner, lowest, op=MPI.MIN)
        mine &= lowest == mesh.comm.rank
    swarm.add(np.flatnonzero(mine), pts[mine], found.xref[mine], found.cells[mine])
    return swarm


def gathered(swarm: Swarm) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Ids, positions and property table of every particle on every rank, sorted by id (collective)."""
    comm = swarm.comm
    ids = np.concatenate(comm.allgather(swarm.ids))
    x = np.concatenate(comm.allgather(swarm.x))
    props = np.concatenate(comm.allgather(swarm.properties))
    order = np.argsort(ids)
    return ids[order], x[order], props[order]



def plugin(cls, *args, **parameters):
    """The particle plugin ``cls`` made of ``cls.Settings(*args, **parameters)`` (a generator,
    interpolator or property needing nothing of a build context)."""
    return cls(cls.Settings(*args, **parameters))
