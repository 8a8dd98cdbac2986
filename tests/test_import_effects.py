"""Importing the packages changes nothing outside them: every module of fembase, particles and
convection imported in a fresh interpreter leaves DOLFINx's JIT function and PETSc's options
database as they were (the solvers set what they need when they are made)."""

import sys
from pathlib import Path

from _runs import guarded_run

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = """
import importlib, pathlib, sys
import dolfinx.jit
from petsc4py import PETSc
original = dolfinx.jit.ffcx_jit
before = PETSc.Options().getAll()
modules = []
for package in ("fembase", "particles", "convection"):
    for path in sorted(pathlib.Path(package).rglob("*.py")):
        parts = path.with_suffix("").parts
        if parts[-1] == "__main__":
            continue
        modules.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
for name in modules:
    importlib.import_module(name)
assert dolfinx.jit.ffcx_jit is original, "dolfinx.jit.ffcx_jit replaced at import"
assert PETSc.Options().getAll() == before, (before, PETSc.Options().getAll())
print(len(modules))
"""


def test_imports_have_no_side_effects():
    proc = guarded_run([sys.executable, "-c", SCRIPT], cwd=ROOT, budget=300)
    assert proc.returncode == 0, proc.stderr
    assert int(proc.stdout.split()[-1]) > 100  # every module was imported


def test_a_solver_sets_what_it_needs():
    """Making a solver installs the form cache and the reproducible vector kernels (idempotent)."""
    script = """
import dolfinx.jit, dolfinx.mesh
from mpi4py import MPI
from petsc4py import PETSc
from convection.geometry.boundary import TemperatureBC
from convection.physics.approximation import BoussinesqApproximation
from convection.solvers.transport import TransportSolver
from fembase import jit_cache
mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 2, 2)
TransportSolver(mesh, BoussinesqApproximation(Ra=1.0), bcs={"top": TemperatureBC("dirichlet", 0.0)})
assert dolfinx.jit.ffcx_jit is jit_cache._cached_ffcx_jit
assert PETSc.Options().hasName("vec_mdot_use_gemv")
"""
    proc = guarded_run([sys.executable, "-c", script], cwd=ROOT, budget=300)
    assert proc.returncode == 0, proc.stderr


RUN_SCRIPT = """
import sys
from convection.app.cli import main
code = main(["run", "configs/thick_layer_3d.yaml", "--output", sys.argv[1], "--set", "mesh.cells=[4,4,4]",
             "--set", "stokes.solver=multigrid", "--set", "time.max_steps=2", "--set", "output.fields_every=1",
             "--set", "output.progress=none"])
assert code == 0, code
print(" ".join(sorted(m for m in sys.modules if m.split(".")[0] in ("matplotlib", "pyvista", "vtk", "vtkmodules", "PIL")
                     or m.startswith(("scipy.spatial", "convection.io.pictures")))))
print("done")
"""


def test_a_run_loads_no_pictures_stack(tmp_path):
    """A run of the 3D thick layer with particles, the multigrid, fields and checkpoints written
    imports neither the plotting stack (matplotlib, PyVista/VTK, the pictures) nor scipy.spatial
    (23 MB a process: imported where a k-d tree is used, on a restart or a new mesh)."""
    proc = guarded_run([sys.executable, "-c", RUN_SCRIPT, str(tmp_path / "run")], cwd=ROOT, budget=300)
    assert proc.returncode == 0, proc.stderr
    loaded, done = proc.stdout.splitlines()[-2:]
    assert done == "done" and loaded == "", loaded
    assert (tmp_path / "run" / "fields.xdmf").exists()
