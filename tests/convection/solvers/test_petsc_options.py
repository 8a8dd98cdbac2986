"""Solvers rebuilt many times (as adaptivity does) must not exhaust PETSc's options database."""

import gc

from mpi4py import MPI
from petsc4py import PETSc

import dolfinx.mesh

from convection.physics.approximation import BoussinesqApproximation
from convection.geometry.boundary import TemperatureBC
from convection.solvers.transport import TransportSolver


def test_options_released_when_solvers_are_dropped():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 2, 2)
    approx = BoussinesqApproximation(Ra=1.0)
    bcs = {"bottom": TemperatureBC("dirichlet", 1.0), "top": TemperatureBC("dirichlet", 0.0)}
    before = len(PETSc.Options().getAll())
    for _ in range(150):  # PETSc allows 512 options; each solver sets 4 or more
        TransportSolver(mesh, approx, bcs=bcs)
        gc.collect()
    assert len(PETSc.Options().getAll()) <= before + 20


def test_linear_solvers_share_the_direct_setup_and_merge_overrides():
    from convection.solvers.petsc_options import HAS_HYPRE, MUMPS_LU, SCALAR_AMG
    from convection.solvers.stokes.solver import STOKES_SOLVERS
    from convection.solvers.transport import TRANSPORT_SOLVERS

    assert sorted(STOKES_SOLVERS) == ["direct", "iterative", "iterative_gamg", "multigrid"]
    assert sorted(TRANSPORT_SOLVERS) == ["direct", "iterative"]
    for registry in (STOKES_SOLVERS, TRANSPORT_SOLVERS):
        assert dict(registry["direct"].options) == dict(MUMPS_LU)
    gmres = TRANSPORT_SOLVERS["iterative"].options_with({"ksp_rtol": 1e-6, "ksp_monitor": None})
    amg = {"pc_type": "hypre", "pc_hypre_type": "boomeramg"} if HAS_HYPRE else dict(SCALAR_AMG)
    assert gmres == {"ksp_type": "gmres", "ksp_rtol": 1e-6, "ksp_atol": 1e-14, "ksp_max_it": 1000, **amg,
                     "ksp_monitor": None}
    assert STOKES_SOLVERS["iterative"].options["ksp_type"] == "fgmres"
    assert "ksp_monitor" not in TRANSPORT_SOLVERS["iterative"].options  # defaults stay unchanged


def test_direct_solves_on_several_ranks_gather_on_one_rank():
    """On several ranks the direct solvers factorise on rank 0 alone (reproducible; a parallel MUMPS
    factorisation is not); one rank keeps the plain MUMPS LU; user options still win."""
    from convection.solvers.petsc_options import MUMPS_LU, reproducible_lu
    from convection.solvers.stokes.solver import STOKES_SOLVERS
    from convection.solvers.transport import TRANSPORT_SOLVERS

    for registry in (STOKES_SOLVERS, TRANSPORT_SOLVERS):
        direct = registry["direct"]
        assert direct.options_with(ranks=1) == dict(MUMPS_LU)
        for ranks in (2, 3):
            options = direct.options_with(ranks=ranks)
            assert options == reproducible_lu(ranks)
            assert options["pc_type"] == "telescope" and options["pc_telescope_reduction_factor"] == ranks
            assert options["telescope_pc_factor_mat_solver_type"] == "mumps"
        assert direct.options_with({"pc_type": "lu"}, ranks=2)["pc_type"] == "lu"
        assert registry["iterative"].options_with(ranks=2) == dict(registry["iterative"].options)
