"""The in-process cache of compiled forms and elements (convection/jit_cache.py)."""

from __future__ import annotations

import dolfinx
import dolfinx.fem
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from fembase import jit_cache
from fembase.dolfinx_compat import function_space
from fembase.dolfinx_compat import form as compat_form


@pytest.fixture
def counted(monkeypatch):
    """Count the calls that reach DOLFINx's own (disk-cached) compiler."""
    calls = []

    def original(comm, ufl_object, *args, **kwargs):
        calls.append(type(ufl_object).__name__)
        return real(comm, ufl_object, *args, **kwargs)

    real = jit_cache._ORIGINAL
    monkeypatch.setattr(jit_cache, "_ORIGINAL", original)
    monkeypatch.setattr(jit_cache, "_CACHE", {})
    jit_cache.install()
    return calls


def _mass(mesh: dolfinx.mesh.Mesh, degree: int) -> float:
    V = function_space(mesh, "Lagrange", degree)
    f = dolfinx.fem.Function(V)
    f.interpolate(lambda x: 1.0 + x[0] ** 2)
    local = dolfinx.fem.assemble_scalar(dolfinx.fem.form(f * ufl.dx))
    return mesh.comm.allreduce(local, op=MPI.SUM)


def test_each_form_and_element_is_compiled_once_per_process(counted):
    """A second mesh reuses the compiled element and form and gets its own, correct values."""
    coarse = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 3, 3)
    fine = dolfinx.mesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], [2.0, 1.0]], [8, 4])
    assert _mass(coarse, 2) == pytest.approx(4.0 / 3.0, rel=1e-13)  # int_0^1 1 + x^2
    first = len(counted)
    assert first >= 1  # the form (and, on DOLFINx 0.5, the element)
    assert _mass(fine, 2) == pytest.approx(2.0 + 8.0 / 3.0, rel=1e-13)  # int_0^2 1 + x^2
    assert len(counted) == first
    _mass(fine, 1)  # another element and form: compiled
    assert len(counted) > first
    assert jit_cache.cached() == len(counted)


def test_options_are_part_of_the_key(counted):
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 2, 2)
    form = dolfinx.fem.Constant(mesh, 1.0) * ufl.dx(domain=mesh)
    dolfinx.fem.form(form)
    compat_form(form, form_compiler_options={"table_rtol": 1e-9})
    dolfinx.fem.form(form)
    assert len(counted) == 2
    assert np.isclose(mesh.comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(form)), op=MPI.SUM), 1.0)


@pytest.mark.mpi
def test_cache_on_several_ranks(counted):
    """Collective: every rank hits or misses together, so DOLFINx's rank-0-first compile does not hang."""
    test_each_form_and_element_is_compiled_once_per_process(counted)
    sizes = MPI.COMM_WORLD.allgather(jit_cache.cached())
    assert len(set(sizes)) == 1


@pytest.mark.mpi
def test_a_form_compiled_on_one_rank_alone_is_no_hit_for_all_ranks(counted):
    """Collective: rank 0 compiles a form on COMM_SELF first; the same form made by every rank
    afterwards still goes through DOLFINx's collective compile on all of them (no hang)."""
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        _mass(dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 2, 2), 3)
    before = len(counted)
    assert _mass(dolfinx.mesh.create_unit_square(comm, 3, 3), 3) == pytest.approx(4.0 / 3.0, rel=1e-13)
    assert len(counted) > before  # compiled for the world group on every rank, rank 0 included
    assert comm.allreduce(1) == comm.size  # the ranks are still in step
