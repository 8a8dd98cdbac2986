"""Rayleigh-Taylor instability with particles, built from components and stepped in a loop.

This demo builds van Keken et al.'s (1997) isoviscous Rayleigh-Taylor benchmark (case 1a) from
the library's parts, without a YAML file, and advances it in a loop written here. A config file
and ``python -m convection run configs/vankeken_1a.yaml`` do the same; this is the way in for
anyone who wants to change a step, add a diagnostic or couple something else.

Run it with ``python demos/rayleigh_taylor.py`` (``--cells 24 --end 300`` reaches the first vrms
peak in about a minute), or under ``mpirun -n 2``: every piece below is parallel.

The problem
-----------
A box of width ``0.9142`` and height 1 holds a light layer below the interface
``z = 0.2 + 0.02 cos(pi x / 0.9142)`` and a dense layer above it. With the dense material's
fraction ``C`` the nondimensional Stokes equations are

    -div(2 eta eps(u)) + grad p = -Rb C e_z,    div u = 0,

with ``Rb = 1`` and viscosity ``eta = 1`` (no temperature: ``Ra = 0``), no slip on the top and
bottom and free slip on the sides. The material moves with the flow, ``dC/dt + u . grad C = 0``;
here particles carry it, and ``C`` in a cell is the mean of its particles' values (the seed
paper's cell average). The light layer rises at the left wall; vrms peaks at 3.0916e-3 near
t = 209 (van Keken et al. 1997).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from convection.adapt.adaptivity import Adaptivity, AdaptivitySettings  # noqa: E402

from convection.adapt.hierarchy import MeshHierarchy  # noqa: E402
from convection.geometry.boundary import VelocityBC  # noqa: E402
from convection.model.composition import ParticleComposition, particle_properties  # noqa: E402
from convection.physics.materials import Material, Materials  # noqa: E402
from convection.model.model import Model  # noqa: E402
from convection.postprocess.postprocessors import Entrainment, Velocity  # noqa: E402
from convection.solvers.stokes.solver import StokesSolver  # noqa: E402
from fembase.dolfinx_compat import function_space
from particles.generation import RandomUniform  # noqa: E402
from particles.manager import ParticleManager  # noqa: E402
from particles.properties import PropertyContext  # noqa: E402

WIDTH = 0.9142


def interface(x: np.ndarray) -> np.ndarray:
    """The initial interface height at x."""
    return 0.2 + 0.02 * np.cos(np.pi * x / WIDTH)


def build(cells: int, particles_per_cell: int, max_level: int, comm: MPI.Comm) -> Model:
    # The mesh
    # --------
    # A coarse base mesh of triangles; adaptivity refines it up to ``max_level`` times where the
    # composition jumps, and coarsens it again behind the interface. Meshes are always rebuilt
    # from this base (DOLFINx 0.5 cannot coarsen), which the hierarchy keeps.
    base = dolfinx.mesh.create_rectangle(comm, [np.zeros(2), np.array([WIDTH, 1.0])], [cells, cells],
                                         dolfinx.mesh.CellType.triangle,
                                         ghost_mode=dolfinx.mesh.GhostMode.shared_facet)
    hierarchy = MeshHierarchy(base)
    adaptivity = Adaptivity(hierarchy, AdaptivitySettings(every=10, min_level=0, max_level=max_level,
                                                            refine_fraction=0.2, coarsen_fraction=0.5,
                                                            fields=("composition",)))

    # The material
    # ------------
    # One named material, ``dense``, fills the box above the interface; the rest is the
    # background. Its compositional Rayleigh number ``Rb = 1`` gives the buoyancy ``-Rb C e_z``.
    # The initial region is a function of points shape=(3, n), as DOLFINx interpolates.
    dense = Material("dense", lambda x: (x[1] > interface(x[0])).astype(float), Rb=1.0)
    materials = Materials((dense,))

    # Start on a mesh already refined along the interface: adapt to the initial fraction.
    def initial_fraction(mesh):
        space = function_space(mesh, "DG", 0)
        C = dolfinx.fem.Function(space)
        C.interpolate(dense.initial)
        return [C]

    mesh = adaptivity.initial_mesh(initial_fraction)

    # The flow solver
    # ---------------
    # Taylor-Hood P2-P1 with a direct (MUMPS) solve. The approximation holds Ra, the materials'
    # Rb and the viscosity law; the sides not listed would be traction free.
    approximation = materials.approximation(Ra=0.0)
    walls = {"left": VelocityBC("free_slip"), "right": VelocityBC("free_slip"),
             "bottom": VelocityBC("no_slip"), "top": VelocityBC("no_slip")}
    stokes = StokesSolver(mesh, approximation, bcs=walls, degree=2, solver="direct")

    # The particles
    # -------------
    # The manager owns the swarm and everything acting on it. Each particle carries the dense
    # fraction (set from the initial region at its position) and its accumulated strain, which
    # the integrator advances with the positions (RK2).
    num_cells = mesh.topology.index_map(2).size_global
    manager = ParticleManager(
        mesh, generator=RandomUniform(RandomUniform.Settings(num_particles=particles_per_cell * num_cells, seed=1)),
        integrator="rk2",
        properties=[*particle_properties(materials, 2), "integrated_strain"],
        context=PropertyContext(u_new=stokes.u),
    )
    # The composition the flow sees is the per-cell average of the particles' dense fraction.
    composition = ParticleComposition(manager, materials)

    # The model
    # ---------
    # No temperature solver: T = 0. Adaptivity runs on its own schedule inside the step.
    return Model(stokes, composition=composition, particles=manager, adaptivity=adaptivity)


def main(argv: list[str] | None = None) -> dict[str, float]:
    parser = argparse.ArgumentParser(description="van Keken 1a from components")
    parser.add_argument("--cells", type=int, default=24)
    parser.add_argument("--particles-per-cell", type=int, default=20)
    parser.add_argument("--max-level", type=int, default=2)
    parser.add_argument("--end", type=float, default=300.0)
    parser.add_argument("--every", type=int, default=20, help="print every N steps")
    args = parser.parse_args(argv)
    comm = MPI.COMM_WORLD
    model = build(args.cells, args.particles_per_cell, args.max_level, comm)

    # The loop
    # --------
    # Diagnostics are postprocessors: callables of the model returning named values.
    vrms = Velocity()
    light_risen = Entrainment({"entrainment": (0, True)}, height=0.2)  # light material above z = 0.2
    model.start()  # the first flow solve
    history = [(model.time, vrms(model)["vrms"])]
    light_risen(model)  # remembers the light volume at t = 0
    while model.time < args.end * (1 - 1e-12):
        dt = min(model.cfl_dt(1.0), args.end - model.time)
        model.step(dt)
        history.append((model.time, vrms(model)["vrms"]))
        if model.timestep % args.every == 0 and comm.rank == 0:
            print(f"step {model.timestep:4d}  t = {model.time:7.2f}  vrms = {history[-1][1]:.4e}  "
                  f"cells = {model.num_cells}", flush=True)

    t, v = np.array(history).T
    peak = int(np.argmax(v))
    result = {"steps": model.timestep, "time": model.time, "vrms": v[-1], "peak_vrms": v[peak],
              "peak_time": t[peak], "entrainment": light_risen(model)["entrainment"],
              "particles": model.particles.num_particles, "lost": model.particles.lost,
              "strain_max": comm.allreduce(float(model.particles.swarm.property("integrated_strain").max(initial=0.0)),
                                           op=MPI.MAX)}
    model.destroy()
    if comm.rank == 0:
        print(f"largest vrms {result['peak_vrms']:.5e} at t = {result['peak_time']:.2f} "
              f"(the first peak of van Keken et al. 1997: 3.0916e-3 at t = 208.99); light material above z = 0.2: "
              f"{result['entrainment']:.3f}; {result['particles']} particles, {result['lost']} lost")
    return result


if __name__ == "__main__":
    main()
