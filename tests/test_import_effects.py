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
