"""A free surface through adaptation and repartitioning (convection/model/mesh_changes.py): the mesh
changes in the reference configuration and the new mesh takes the carried deformed positions. Refined
cells keep the deformed surface exactly (the old surface nodes stay, the new ones lie on its
chords; the deformed domain's area is unchanged); coarsened cells keep their nodes where they
were; no particle is lost. Collective checks (serial and under mpirun)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from mpi4py import MPI

from _runs import CONFIGS

from convection.app.factory import build_model
from convection.config.loader import load_config
from convection.geometry.mesh import cell_volumes
from fembase.distribute import duplicate_cells


def _model(world, tmp_path, *extra: str, step: bool = True):
    directory = world.bcast(str(tmp_path), root=0)
    config = load_config(CONFIGS / "crameri_case1_free_surface.yaml", [
        "mesh.cells=[16,4]", "adaptivity.enabled=true", "adaptivity.initial_steps=0", "adaptivity.max_level=2",
        "adaptivity.fields=[composition]", "particles.generator.particles_per_cell=8",
        "particles.population.min_per_cell=4", "particles.population.max_per_cell=16", "output.fields_every=0",
        f"output.directory={directory}", *extra])
    model = build_model(config, comm=world)
    model.start()
    model.config_dt_max = config["time"]["dt_max"]
    if step:
        model.step(model.cfl_dt(0.5, dt_max=model.config_dt_max))  # the surface moves off its initial shape
    return model


def _surface(model) -> np.ndarray:
    """The surface nodes of every rank, (x, height) sorted by x, shape=(n, 2)."""
    x, h = model.free_surface.heights()
    nodes = np.concatenate(model.comm.allgather(np.column_stack([x[:, 0], h])))
    return nodes[np.argsort(nodes[:, 0])]


def _area(model) -> float:
    mesh = model.mesh
    owned = mesh.topology.index_map(mesh.topology.dim).size_local
    return model.comm.allreduce(float(cell_volumes(mesh)[:owned].sum()), op=MPI.SUM)


def _adapt(model, **fractions: float) -> None:
    model.adaptivity.params = dataclasses.replace(model.adaptivity.params, **fractions)
    model.adapt()


def test_refinement_keeps_the_deformed_surface(world, tmp_path):
    model = _model(world, tmp_path)
    before, area, cells = _surface(model), _area(model), model.num_cells
    particles, moves = model.particles.swarm.global_num_particles(), model.free_surface.moves
    assert np.abs(before[:, 1]).max() > 1e-3  # deformed (7 km / 700 km)
    _adapt(model, refine_fraction=0.5, coarsen_fraction=0.0)
    after = _surface(model)
    assert model.num_cells > cells and after.shape[0] > before.shape[0]
    # the old nodes are kept, at their heights; the new ones lie on the old surface's chords
    kept = np.searchsorted(after[:, 0], before[:, 0] - 1e-12)
    assert np.allclose(after[kept], before, rtol=0.0, atol=1e-13)
    assert np.allclose(after[:, 1], np.interp(after[:, 0], before[:, 0], before[:, 1]), rtol=0.0, atol=1e-13)
    assert _area(model) == pytest.approx(area, rel=1e-13)
    assert model.particles.lost == 0 and model.particles.swarm.global_num_particles() >= particles
    assert model.free_surface.moves == moves and model.free_surface.quality_min > 0.0


def test_coarsening_keeps_the_remaining_nodes(world, tmp_path):
    model = _model(world, tmp_path)
    _adapt(model, refine_fraction=1.0, coarsen_fraction=0.0)
    model.step(model.cfl_dt(0.5, dt_max=1e-3))  # the refined surface moves on
    before, cells = _surface(model), model.num_cells
    _adapt(model, refine_fraction=0.0, coarsen_fraction=1.0)
    after = _surface(model)
    assert model.num_cells < cells and after.shape[0] < before.shape[0]
    at = np.searchsorted(before[:, 0], after[:, 0] - 1e-12)
    assert np.allclose(before[at], after, rtol=0.0, atol=1e-13)  # each remaining node where it was
    assert model.particles.lost == 0
    # the run goes on: the flow is solved on the coarsened, deformed mesh
    model.step(model.cfl_dt(0.5, dt_max=1e-3))
    assert model.particles.lost == 0 and model.free_surface.quality_min > 0.0


def test_adapted_meshes_have_a_sound_ghost_layer(world, tmp_path):
    """Every facet of an adapted mesh has at most two cells on every rank (DOLFINx 0.5's refinement
    repeated ghost cells, here on 2 ranks: 11 after the first adaptation, before
    :func:`fembase.distribute.refine_on_ranks` checked for them on 2 ranks too), so the refinement
    indicator sees every interior facet and the mesh does not depend on the partition."""
    model = _model(world, tmp_path, "mesh.cells=[28,7]", "adaptivity.initial_steps=2", "balance.strategy=every",
                   "balance.every=1000", step=False)
    for _ in range(2):
        model.step(model.config_dt_max)
    model.adapt()
    for mesh in (model.mesh, model.adaptivity.hierarchy.base):
        assert world.allreduce(duplicate_cells(mesh), op=MPI.SUM) == 0
        mesh.topology.create_connectivity(1, 2)
        assert world.allreduce(int(np.diff(mesh.topology.connectivity(1, 2).offsets).max(initial=1)), op=MPI.MAX) <= 2
