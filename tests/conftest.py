"""Shared test fixtures.

Collective tests carry ``@pytest.mark.mpi`` and are run by scripts/test.sh under mpirun with 2 and 3
ranks; they must assert on globally reduced values so every rank passes or fails together. A test
that takes the ``world`` fixture runs twice: ``[serial]`` in the plain run and ``[mpi]`` under mpirun.

The serial tests run in pytest-xdist's workers (scripts/test.sh). This file is also loaded by
xdist's controller, which must not initialise MPI: Open MPI's singleton start writes its PMIx
contact variables into the process's environment, the workers inherit them, and every ``mpirun``
a test starts from a worker then exits with code 1 and no message. So ``mpi4py.MPI`` is imported
here only inside the fixture.
"""

import os

import pytest

os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")


@pytest.fixture(params=["serial", pytest.param("mpi", marks=pytest.mark.mpi)])
def world():
    """``MPI.COMM_WORLD``, for the same test serial (one rank) and collective (mpi-marked)."""
    from mpi4py import MPI

    return MPI.COMM_WORLD
