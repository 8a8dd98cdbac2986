"""Tiny run folders the picture tests draw: fields at a few times (2D or 3D), particles, statistics."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from convection.io.fields import FieldOutput
from fembase.dolfinx_compat import function_space, refine_keeping_partition
from particles import Swarm
from particles.generation import generate
from particles.io.output import ParticleWriter

TIMES = (0.0, 1.0, 2.0)


def field_functions(mesh: dolfinx.mesh.Mesh, temperature: str) -> dict[str, dolfinx.fem.Function]:
    """material = [z > 1/2] (DG0), temperature = z or 0 (P2), velocity, pressure = x (P1).

    z is the vertical coordinate: y in 2D, z in 3D.
    """
    up = mesh.geometry.dim - 1
    material = dolfinx.fem.Function(function_space(mesh, "DG", 0))
    material.interpolate(lambda x: (x[up] > 0.5).astype(np.float64))
    T = dolfinx.fem.Function(function_space(mesh, "Lagrange", 2))
    T.interpolate(lambda x: x[up] if temperature == "z" else 0.0 * x[up])
    u = dolfinx.fem.Function(function_space(mesh, "Lagrange", 2, shape=(mesh.geometry.dim,)))
    u.interpolate(lambda x: np.stack([x[1] - 0.5, 0.5 - x[0], 0 * x[0]][: mesh.geometry.dim]))
    p = dolfinx.fem.Function(function_space(mesh, "Lagrange", 1))
    p.interpolate(lambda x: x[0])
    return {"temperature": T, "velocity": u, "pressure": p, "material": material}


def run_directory(path: Path, *, temperature: str = "z", dim: int = 2, particles: bool = True) -> Path:
    """A tiny run: fields at TIMES (the mesh refined before the last), particles, statistics.csv."""
    comm = MPI.COMM_SELF
    if dim == 2:
        mesh = dolfinx.mesh.create_unit_square(comm, 6, 6)
    else:
        mesh = dolfinx.mesh.create_unit_cube(comm, 3, 3, 3)
    mesh.topology.create_entities(1)
    out = FieldOutput(path)
    for t in TIMES:
        if t == TIMES[-1]:
            mesh = refine_keeping_partition(mesh)
        out.write(field_functions(mesh, temperature), t)
    out.close()
    if particles:
        swarm = Swarm(mesh)
        swarm.add_property("material")
        generate(swarm, "random_uniform", num_particles=400, seed=2)
        writer = ParticleWriter(path)
        for step, t in enumerate(TIMES):
            swarm.property("material")[:, 0] = swarm.x[:, 0] + t
            writer.write(swarm, t, step)
    lines = ["step,time,vrms,nusselt,cells"] + [f"{k},{t},{1 + t},{2 + t},{100}" for k, t in enumerate(TIMES)]
    (path / "statistics.csv").write_text("\n".join(lines) + "\n")
    return path
