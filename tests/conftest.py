"""Shared test fixtures.

Collective tests carry ``@pytest.mark.mpi`` and are run by scripts/test.sh under mpirun with 2 and 3
ranks; they must assert on globally reduced values so every rank passes or fails together.
"""

import os

os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
