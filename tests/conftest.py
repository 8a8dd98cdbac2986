"""Shared test fixtures.

Collective tests carry ``@pytest.mark.mpi`` and are run by scripts/test.sh under mpirun with 2 and 3
ranks; they must assert on globally reduced values so every rank passes or fails together. A test
that takes the ``world`` fixture runs twice: ``[serial]`` in the plain run and ``[mpi]`` under mpirun.
"""

import os

import pytest
from mpi4py import MPI

os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")


@pytest.fixture(params=["serial", pytest.param("mpi", marks=pytest.mark.mpi)])
def world() -> MPI.Comm:
    """``MPI.COMM_WORLD``, for the same test serial (one rank) and collective (mpi-marked)."""
    return MPI.COMM_WORLD
