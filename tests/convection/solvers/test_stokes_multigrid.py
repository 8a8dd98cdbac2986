"""The geometric-multigrid Stokes solver (``stokes.solver: multigrid``): the solution of MUMPS to
the solver tolerance (smooth and sharp 1e3 viscosity contrasts, 2D and 3D, 1/2/3 ranks),
iterations that do not grow with the mesh (also with a 1e4 contrast), the operator and the
multigrid hierarchy set up once while the viscosity is constant, and the config's rules."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fembase.dolfinx_compat import repartitioned_manifolds_nest
import ufl
import dolfinx
from mpi4py import MPI
from petsc4py import PETSc

from convection.config.loader import ConfigError, load_config
from convection.geometry.boundary import VelocityBC
from convection.geometry.box import SIDES_2D, SIDES_3D, BoxDomain, BoxSpec
from convection.physics.approximation import BoussinesqApproximation, ViscosityLaw
from convection.solvers.stokes.multigrid import GALERKIN_PRODUCT, galerkin_products
from convection.solvers.stokes.solver import StokesSolver
from fembase.dolfinx_compat import function_space

from benchmarks.performance import stokes3d  # the 3D problem of the iterative solvers' tests

ROOT = Path(__file__).resolve().parents[3]
FREE_SLIP_3D = {side: VelocityBC("free_slip") for side in SIDES_3D}
FREE_SLIP_2D = {side: VelocityBC("free_slip") for side in SIDES_2D}


def _norm(comm, f) -> float:
    return float(np.sqrt(comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(ufl.inner(f, f) * ufl.dx)),
                                        op=MPI.SUM)))


def _cube(comm, n: int, levels: int, viscosity: str):
    """The unit cube of n^3 cubes and the meshes nested in it; stokes3d's fields and viscosity."""
    meshes = BoxDomain.from_spec(BoxSpec((n, n, n), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0))).create_mesh_levels(comm, levels)
    T, C, approximation = stokes3d.problem(meshes[-1], viscosity)
    return meshes, T, C, approximation


def _square(comm, n: int, contrast: float):
    """The unit square of n x n squares (3 levels more coarsely), Ra = 1e5, T = 1 - y + 0.1 cos(pi x) sin(pi y),
    eta = contrast^(-T) (Frank-Kamenetskii; 1: constant)."""
    domain = BoxDomain.from_spec(BoxSpec((n, n), (0.0, 0.0), (1.0, 1.0)))
    meshes = domain.create_mesh_levels(comm, domain.mesh_levels())
    T = dolfinx.fem.Function(function_space(meshes[-1], "Lagrange", 2))
    T.interpolate(lambda x: 1.0 - x[1] + 0.1 * np.cos(np.pi * x[0]) * np.sin(np.pi * x[1]))
    law = (ViscosityLaw(temperature_law="frank_kamenetskii", gamma=np.log(contrast)) if contrast != 1.0
           else ViscosityLaw())
    return meshes, T, BoussinesqApproximation(Ra=1e5, viscosity=law)


def _check_matches(comm, meshes, T, C, approximation, bcs, rtol: float, factor: float) -> int:
    """Multigrid at ``rtol`` against MUMPS (serial) or iterative_gamg at 1e-11 (parallel, where
    MUMPS without iterative refinement is only 4e-6 to 6e-5 accurate); returns the iterations."""
    reference = "direct" if comm.size == 1 else "iterative_gamg"
    options = {"ksp_rtol": 1e-11} if reference != "direct" else None
    exact = StokesSolver(meshes[-1], approximation, bcs=bcs, solver=reference, petsc_options=options)
    exact.solve(T, C)
    stokes = StokesSolver(meshes[-1], approximation, bcs=bcs, solver="multigrid", coarse_meshes=meshes[:-1],
                          petsc_options={"ksp_rtol": rtol})
    result = stokes.solve(T, C)
    assert _norm(comm, stokes.u - exact.u) < factor * rtol * _norm(comm, exact.u)
    assert _norm(comm, stokes.p - exact.p) < factor * rtol * _norm(comm, exact.p)
    for solver in (exact, stokes):
        solver.destroy()
    return result.iterations


@pytest.mark.parametrize("rtol", [1e-5, 1e-9])
@pytest.mark.parametrize("viscosity", ["temperature", "layer"])
def test_matches_the_exact_solution_to_the_solver_tolerance_3d(world, viscosity, rtol):
    """Collective: 4^3 cubes over 2^3; the sharp layer's contrast makes the residual a looser bound
    on the error (as for the AMG solvers, test_stokes_iterative.py)."""
    meshes, T, C, approximation = _cube(world, 4, 2, viscosity)
    iterations = _check_matches(world, meshes, T, C, approximation, FREE_SLIP_3D, rtol,
                                300 if viscosity == "layer" else 30)
    assert iterations < 100


def test_matches_the_exact_solution_2d(world):
    """Collective: a 1e4 contrast on 32 x 32 squares over 4 x 4."""
    meshes, T, approximation = _square(world, 32, 1e4)
    _check_matches(world, meshes, T, None, approximation, FREE_SLIP_2D, 1e-8, 100)


def _iterations(solver: StokesSolver, T, C=None) -> int:
    iterations = solver.solve(T, C).iterations
    solver.destroy()
    return iterations


def test_iterations_do_not_grow_with_the_mesh_2d(world):
    """Collective: 16^2 to 128^2 squares (coarsest 2 x 2), constant viscosity and a 1e4 contrast: the
    count stays within a few iterations (measured on 2 ranks: 12 12 12 13 and 25 25 25 25; the
    contrast's count is the Schur complement's, approximated by the pressure mass matrix / eta;
    18-19 and 39 while the preconditioning matrix lacked the coupling blocks)."""
    for contrast, bound in ((1.0, 16), (1e4, 32)):
        counts = []
        for n in (16, 32, 64, 128):
            meshes, T, approximation = _square(world, n, contrast)
            counts.append(_iterations(StokesSolver(meshes[-1], approximation, bcs=FREE_SLIP_2D, solver="multigrid",
                                                   coarse_meshes=meshes[:-1]), T))
        assert max(counts) <= bound and max(counts) - min(counts) <= 4, (contrast, counts)


def test_iterations_do_not_grow_with_the_mesh_3d(world):
    """Collective: 4^3, 8^3 and 16^3 cubes, each down to 2^3, constant viscosity (measured on 2 ranks:
    13 13 13; 19 20 20 while the preconditioning matrix lacked the coupling blocks)."""
    counts = []
    for n, levels in ((4, 2), (8, 3), (16, 4)):
        meshes, T, C, approximation = _cube(world, n, levels, "constant")
        counts.append(_iterations(StokesSolver(meshes[-1], approximation, bcs=FREE_SLIP_3D, solver="multigrid",
                                               coarse_meshes=meshes[:-1]), T, C))
    assert max(counts) <= 16 and max(counts) - min(counts) <= 3, counts


def test_a_sharp_contrast_converges_alike_on_any_rank_count(world):
    """Collective: a 1e3 layer (stokes3d's ``layer``) at 8^3 over 2^3. With a variable viscosity the Chebyshev
    bound comes from 10 GMRES steps (convection/solvers/stokes/multigrid.py): 52 iterations on 1, 2 and 3
    ranks; with the 4 steps of a constant viscosity 65, 70 and 136 (the sharp contrast's stiff modes are
    local, and a short estimate misses them)."""
    meshes, T, C, approximation = _cube(world, 8, 3, "layer")
    stokes = StokesSolver(meshes[-1], approximation, bcs=FREE_SLIP_3D, solver="multigrid", coarse_meshes=meshes[:-1])
    iterations = _iterations(stokes, T, C)
    assert iterations <= 60, iterations


def test_preconditioning_matrix_holds_the_coupling_blocks(world):
    """Collective: PETSc's fieldsplit takes the Schur factorisation's ``B`` and ``B^T`` from the
    preconditioning matrix, so ``P`` holds the operator's: without them the upper block-triangular
    preconditioner is block diagonal (20 iterations instead of 13 at 16^3)."""
    meshes, T, C, approximation = _cube(world, 4, 2, "constant")
    stokes = StokesSolver(meshes[-1], approximation, bcs=FREE_SLIP_3D, solver="multigrid", coarse_meshes=meshes[:-1])
    stokes.solve(T, C)
    system = stokes.linear_system
    is_u, is_p = system.index_sets()
    for rows, columns in ((is_u, is_p), (is_p, is_u)):
        operator, preconditioning = (M.createSubMatrix(rows, columns) for M in (system.A, system.P))
        size = preconditioning.norm()
        assert size > 0.0
        operator.axpy(-1.0, preconditioning)
        assert operator.norm() <= 1e-14 * size  # equal but for the order of off-rank sums (several ranks)
    stokes.destroy()


def _layer_problem(comm):
    """8^3 cubes over 2^3, constant viscosity, a dense layer (Rb = Ra = 1e6) under z = 0.4 + 0.05
    cos(pi x) cos(pi y) (stokes3d's), its buoyancy predicted over the step (buoyancy_theta 1)."""
    meshes, T, C, _ = _cube(comm, 8, 3, "layer")
    return meshes, T, C, BoussinesqApproximation(Ra=1e6, Rb=1e6)


def test_semi_implicit_term_is_in_the_multigrid_preconditioner(world):
    """Collective: the predicted buoyancy adds ``c u_z v_z`` to the velocity block; the multigrid's
    preconditioning matrix gets it too (the hierarchy is set up again each solve), so a step of
    about the thick layer's CFL size needs a few iterations more than ``dt = 0`` (measured serial:
    13 and 16; 14 and 24 at dt 5e-5, 23 and 68 at 5e-4), not twice as many as without the term in
    the preconditioner (13 and 32), and the solution is the reference's to the tolerance (MUMPS
    serial, iterative_gamg at 1e-11 in parallel, as _check_matches)."""
    meshes, T, C, approximation = _layer_problem(world)
    dt = 1e-4

    def solver(name, in_preconditioner=True, **options):
        stokes = StokesSolver(meshes[-1], approximation, bcs=FREE_SLIP_3D, solver=name, buoyancy_theta=1.0,
                              coarse_meshes=meshes[:-1] if name == "multigrid" else None, petsc_options=options or None)
        stokes.linear_system.term_in_preconditioner = in_preconditioner
        return stokes

    counts = {}
    for in_preconditioner in (True, False):
        stokes = solver("multigrid", in_preconditioner)
        counts[in_preconditioner] = [stokes.solve(T, C, dt=step).iterations for step in (0.0, dt)]
        stokes.destroy()
    with_term, without = counts[True], counts[False]
    assert with_term[1] <= with_term[0] + 5 and without[1] >= with_term[1] + 10, counts

    reference = "direct" if world.size == 1 else "iterative_gamg"
    exact = solver(reference, **({} if reference == "direct" else {"ksp_rtol": 1e-11}))
    exact.solve(T, C, dt=dt)
    stokes = solver("multigrid", ksp_rtol=1e-9)
    stokes.u.x.array[:] = 0.0  # a cold start: the same problem as the reference's
    stokes.solve(T, C, dt=dt)
    assert _norm(world, stokes.u - exact.u) < 30 * 1e-9 * _norm(world, exact.u)
    for s in (exact, stokes):
        s.destroy()


def test_constant_viscosity_sets_up_once(world):
    """Collective: three solves with moving buoyancy and a constant viscosity assemble the operator
    once and set the preconditioner up once (PETSc's log counts no set-up in the later solves)."""
    meshes, T, C, approximation = _cube(world, 4, 2, "constant")
    stokes = StokesSolver(meshes[-1], approximation, bcs=FREE_SLIP_3D, solver="multigrid", coarse_meshes=meshes[:-1])
    PETSc.Log.begin()  # PETSc counts the preconditioner set-ups that do work (a no-op set-up is not logged)
    setups = PETSc.Log.Event("PCSetUp")
    results, counts = [], []
    for shift in (0.0, 0.01, 0.02):
        T.interpolate(stokes3d.temperature("constant", shift))
        before = setups.getPerfInfo()["count"]
        results.append(stokes.solve(T, C))
        counts.append(setups.getPerfInfo()["count"] - before)
    assert [r.assemblies for r in results] == [1, 0, 0]
    assert counts[0] > 0 and counts[1:] == [0, 0], counts
    velocity_pc = stokes.ksp.getPC().getFieldSplitSubKSP()[0].getPC()
    assert velocity_pc.getType() == "mg" and velocity_pc.getMGLevels() == 2
    stokes.destroy()


def test_coarse_operators_are_the_galerkin_products(world):
    """Collective: every coarser level's operator is ``P^T A P`` of the next finer one, to round-off,
    although on several ranks the set-up forms it by PETSc's all-at-once product
    (:data:`GALERKIN_PRODUCT`) and the reference here by PETSc's default; the option leaves the
    database with the set-up."""
    meshes, T, C, approximation = _cube(world, 8, 3, "temperature")
    stokes = StokesSolver(meshes[-1], approximation, bcs=FREE_SLIP_3D, solver="multigrid", coarse_meshes=meshes[:-1])
    stokes.solve(T, C)
    assert not PETSc.Options().hasName("matptap_via")
    pc = stokes.ksp.getPC().getFieldSplitSubKSP()[0].getPC()
    levels = pc.getMGLevels()
    assert levels == 3
    for level in range(levels - 1, 0, -1):
        fine = pc.getMGSmoother(level).getOperators()[0]
        coarse = pc.getMGSmoother(level - 1).getOperators()[0]
        reference = fine.ptap(pc.getMGInterpolation(level))
        reference.axpy(-1.0, coarse)
        assert reference.norm() < 1e-12 * coarse.norm(), level
        reference.destroy()
    stokes.destroy()


@pytest.mark.parametrize("preset", [None, "scalable"])
def test_galerkin_products_option_is_scoped(world, preset):
    """Collective: on several ranks the all-at-once product is asked for inside the scope only, and a
    ``matptap_via`` the user set stays as it is; on one rank nothing is set."""
    options = PETSc.Options()

    def value() -> str | None:
        return options.getString("matptap_via") if options.hasName("matptap_via") else None

    if preset is not None:
        options["matptap_via"] = preset
    try:
        with galerkin_products(world):
            inside = value()
        after = value()
    finally:
        if preset is not None:
            options.delValue("matptap_via")
    expected = preset if preset is not None else (GALERKIN_PRODUCT if world.size > 1 else None)
    assert (inside, after) == (expected, preset)


def test_multigrid_needs_the_coarse_meshes():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 4, 4)
    with pytest.raises(ValueError, match="coarser meshes"):
        StokesSolver(mesh, BoussinesqApproximation(Ra=1.0), bcs=FREE_SLIP_2D, solver="multigrid")


def test_an_adaptive_mesh_without_levels_is_solved_with_the_amg():
    """A mesh whose levels (a callable: an adaptive run's) are none, as after a repartition of an
    unrefined mesh: the AMG block preconditioner for this mesh; on_mesh asks for levels again."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 4, 4)
    stokes = StokesSolver(mesh, BoussinesqApproximation(Ra=1.0), bcs=FREE_SLIP_2D, solver="multigrid",
                          coarse_meshes=lambda m: ())
    assert stokes.solver in ("iterative", "iterative_gamg") and stokes.settings()["solver"] == "multigrid"
    assert stokes.linear_system.multigrid is None
    stokes.destroy()


def test_balanced_adaptive_and_shell_multigrid_are_accepted():
    config = load_config(ROOT / "configs" / "thick_layer_3d.yaml",
                         ["stokes.solver=multigrid", "balance.strategy=every", "adaptivity.enabled=true",
                          "adaptivity.max_level=1"])
    assert config["balance"]["strategy"] == "every"
    if repartitioned_manifolds_nest():
        shell = load_config(ROOT / "configs" / "shell_adaptive.yaml", ["stokes.solver=multigrid"])  # curved levels
    else:
        with pytest.raises(ConfigError, match="repartitioned curved mesh needs DOLFINx 0.5"):
            load_config(ROOT / "configs" / "shell_adaptive.yaml", ["stokes.solver=multigrid"])
        shell = load_config(ROOT / "configs" / "shell_adaptive.yaml",
                            ["stokes.solver=multigrid", "balance.strategy=none"])
    assert shell["stokes"]["solver"] == "multigrid"


@pytest.mark.parametrize("sets, message", [
    (["stokes.solver=iterative", "stokes.multigrid.levels=3"],
     "'stokes.multigrid.levels': only with stokes.solver: multigrid"),
    (["stokes.multigrid.levels=4"], "'stokes.multigrid.levels': 4 mesh levels need mesh.cells divisible by 2\\^3"),
    (["stokes.solver=multigrid", "mesh.cells=[25,25,25]"], "'stokes.solver': multigrid needs coarser meshes"),
    (["stokes.solver=multigrid", "stokes.multigrid.levels=4", "mesh.cells=[20,20,20]"],
     "'stokes.multigrid.levels': 4 mesh levels need mesh.cells divisible by 2\\^3"),
    (["stokes.solver=multigrid", "balance.strategy=every"],
     "'balance.strategy': stokes.solver multigrid repartitions adaptive meshes only"),
    (["stokes.solver=direct", "stokes.schur=wbfbt"], "'stokes.schur': wbfbt only with an iterative stokes.solver"),
])
def test_config_rules(sets, message):
    with pytest.raises(ConfigError, match=message):
        load_config(ROOT / "configs" / "thick_layer_3d.yaml", sets)


def test_config_rules_shell():
    """A fixed shell's levels refine a coarser gmsh shell (cells at most half the thickness); an
    adaptive shell's are its refinement rounds; ``auto`` takes the multigrid on a fixed shell of
    three levels or more (gmsh size at most an eighth of the thickness), free slip on both surfaces
    too, and keeps the AMG below that and on adaptive shells."""
    from convection.config.loader import multigrid_levels

    plates = ROOT / "configs" / "shell_plates.yaml"  # mesh.resolution 0.3, thickness 1
    with pytest.raises(ConfigError, match="multigrid on a fixed mesh.geometry spherical_shell refines a coarser gmsh "
                                          "mesh for its levels, and here cannot: mesh.resolution is too coarse"):
        load_config(plates, ["stokes.solver=multigrid"])
    assert multigrid_levels(load_config(plates, ["stokes.solver=multigrid", "mesh.resolution=0.25"])) == 2
    assert multigrid_levels(load_config(plates, ["stokes.solver=multigrid", "mesh.resolution=0.1"])) == 3
    assert multigrid_levels(load_config(plates, ["mesh.resolution=0.1"])) == 3  # auto
    assert multigrid_levels(load_config(plates, ["mesh.resolution=0.125", "boundary.velocity.outer=free_slip"])) == 3
    assert multigrid_levels(load_config(plates, ["mesh.resolution=0.25"])) == 1  # two levels: too few for auto
    assert multigrid_levels(load_config(plates, ["mesh.resolution=0.1", "stokes.solver=iterative"])) == 1
    assert multigrid_levels(load_config(ROOT / "configs" / "shell_adaptive.yaml", ["mesh.resolution=0.12"])) == 1
    with pytest.raises(ConfigError, match="'stokes.multigrid.levels': 3 levels need a coarsest mesh"):
        load_config(plates, ["stokes.solver=multigrid", "mesh.resolution=0.25", "stokes.multigrid.levels=3"])
    with pytest.raises(ConfigError, match="'stokes.multigrid.levels': an adaptive or repartitioned spherical_shell "
                                          "takes its refinement rounds as the levels"):
        load_config(ROOT / "configs" / "shell_adaptive.yaml",
                    ["stokes.solver=multigrid", "balance.strategy=none", "stokes.multigrid.levels=2"])


@pytest.mark.parametrize("sets, levels", [
    ([], 3),  # 20^3 -> 10^3 -> 5^3
    (["mesh.cells=[16,16,16]"], 4),
    (["mesh.cells=[12,12,12]"], 3),
    (["mesh.cells=[10,10,10]"], 1),  # 10 -> 5: two levels, too few for auto
    (["mesh.cells=[9,9,9]"], 1),
    (["stokes.solver=iterative"], 1),
    (["stokes.solver=multigrid", "mesh.cells=[10,10,10]"], 2),
    (["adaptivity.enabled=true", "adaptivity.max_level=1"], 1),
])
def test_auto_picks_the_multigrid_on_fixed_boxes_that_nest(sets, levels):
    """``auto`` on the 3D thick layer: the multigrid where the box nests in three levels or more and
    the mesh is fixed."""
    from convection.config.loader import multigrid_levels

    assert multigrid_levels(load_config(ROOT / "configs" / "thick_layer_3d.yaml", sets)) == levels


def test_auto_leaves_no_rank_without_a_coarsest_cell():
    """16^3 nests down to 2^3 cubes (48 tetrahedra): auto keeps the AMG solver on more ranks."""
    from convection.config.loader import multigrid_levels

    config = load_config(ROOT / "configs" / "thick_layer_3d.yaml", ["mesh.cells=[16,16,16]"])
    assert multigrid_levels(config, ranks=48) == 4
    assert multigrid_levels(config, ranks=49) == 1


def test_a_run_of_auto_uses_the_multigrid(tmp_path):
    from convection.app.factory import build_model

    config = load_config(ROOT / "configs" / "thick_layer_3d.yaml",
                         ["mesh.cells=[8,8,8]", "particles.generator.particles_per_cell=1",
                          f"output.directory={tmp_path}"])
    model = build_model(config, comm=MPI.COMM_SELF)
    assert model.stokes.solver == "multigrid"
    assert model.stokes.linear_system.multigrid.levels == 3
    assert model.stokes.description == "multigrid (3 levels)"  # the run's closing line names it
    model.stokes.destroy()
