"""Particles through 20 adaptations (refine and coarsen, rebuilt from the base mesh)."""

import numpy as np

from convection.adapt.hierarchy import MeshHierarchy
from convection.geometry.box import BoxSpec, create_box_mesh
from fembase.geometry import CellGeometry
from particles import Swarm
from particles.relocation.new_mesh import move_to_mesh
from particles.generation import generate

from _helpers import gathered


def _check_adaptations(comm):
    base = create_box_mesh(comm, BoxSpec((6, 6), (0.0, 0.0), (0.9142, 1.0)))
    hierarchy = MeshHierarchy(base)
    swarm = Swarm(base)
    swarm.add_property("tag", 2)
    generate(swarm, "random_uniform", num_particles=3000, seed=7)
    swarm.property("tag")[:] = np.column_stack([swarm.ids, swarm.x[:, 0]])
    ids0, x0, props0 = gathered(swarm)
    rng = np.random.default_rng(3)  # same stream on every rank: wanted levels from a global rule
    mesh = base
    cell_counts = []
    for _ in range(20):
        # Wanted level from a moving band (refine there, coarsen elsewhere), random depth.
        centre, depth = rng.uniform(0.1, 0.9), int(rng.integers(0, 4))
        midpoints = swarm.geometry.push_forward(np.arange(swarm.num_owned_cells, dtype=np.int32),
                                                np.full((swarm.num_owned_cells, 2), 1.0 / 3.0))
        wanted = np.where(np.abs(midpoints[:, 1] - centre) < 0.15, depth, 0).astype(np.int32)
        old, mesh = mesh, hierarchy.rebuild(mesh, wanted)
        candidates = hierarchy.candidates(mesh, old, swarm.cells)
        assert candidates is not None
        # Every particle's cell in the new mesh (bounding-box search) is among its candidates:
        # the new cells refined from the base cell its old cell came from.
        found = CellGeometry(mesh).locate(swarm.x, owned_only=True).cells
        group_of = np.full(mesh.topology.index_map(2).size_local, -1)
        group_of[candidates.cells] = np.repeat(np.arange(candidates.offsets.size - 1), np.diff(candidates.offsets))
        assert np.all(found >= 0) and np.array_equal(group_of[found], candidates.groups)
        # So the move with candidates gives the cells of the move without.
        from_tree = move_to_mesh(swarm, mesh)[0]
        swarm, stats = move_to_mesh(swarm, mesh, candidates=candidates)
        assert np.array_equal(swarm.ids, from_tree.ids) and np.array_equal(swarm.cells, from_tree.cells)
        assert np.array_equal(swarm.xref, from_tree.xref)
        assert stats.lost == 0
        swarm.check_invariants()
        # each particle's cell truly contains it, with a consistent reference position
        assert np.all(swarm.geometry.inside(swarm.xref))
        assert np.allclose(swarm.geometry.push_forward(swarm.cells, swarm.xref), swarm.x, rtol=0, atol=1e-12)
        cell_counts.append(mesh.topology.index_map(2).size_global)
    ids, x, props = gathered(swarm)
    assert np.array_equal(ids, ids0)
    assert np.array_equal(x, x0) and np.array_equal(props, props0)
    assert len(set(cell_counts)) > 3 and min(cell_counts) < max(cell_counts)  # refined and coarsened


def test_twenty_adaptations(world):
    _check_adaptations(world)
