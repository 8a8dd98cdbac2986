"""The collective test run itself works: every rank sees the same world and can reduce."""

import pytest
from mpi4py import MPI


@pytest.mark.mpi
def test_world_allreduce():
    comm = MPI.COMM_WORLD
    assert comm.size >= 2
    assert comm.allreduce(1) == comm.size
