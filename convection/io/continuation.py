"""Start a run from another run's temperature: ``initial.from_run`` (``run --initial-from PATH``).

The source is a run folder (its newest checkpoint; every run writes one at its end) or one
checkpoint folder of it. Its temperature ``T^n`` becomes the new run's initial temperature, on the
new run's mesh, element degree and rank count:

- where every node of the new temperature space is a saved node (the same mesh, the same degree,
  any partition), the saved values are copied: the continued run starts from the source's
  temperature exactly;
- otherwise the source's mesh is made again on the new run's ranks from the saved cells (each rank
  an equal block of them, as a resume on another rank count does,
  :func:`convection.io.checkpoint.restore_mesh`), its temperature filled from the saved values by
  dof coordinates, and interpolated into the new space
  (:func:`convection.adapt.transfer.transfer_function`, which finds the points another rank
  holds): T_new = I_new(T_source), the same on any rank count to round-off.

The Dirichlet values of the new run are imposed on the result. Only the temperature is taken:
the new run's first Stokes solve makes the velocity from it (the shipped laws make Stokes linear in
the velocity for a given temperature, so a first guess would not save a factorisation), and
materials and particles start from the new run's own initial condition. The time starts at 0.

The source must be a domain meshed with straight cells (a box) of the same ``mesh.geometry``,
extent, dimension and cell type, with a temperature; a run
that adapts its mesh to its initial condition (``adaptivity.enabled``) cannot continue one (it
adapts to ``initial.temperature``). :func:`convection.config.continuation.check_source` says what
is wrong in one line naming the key.
"""

from __future__ import annotations

import os
from pathlib import Path

import dolfinx.fem
import dolfinx.mesh
import h5py
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from convection.adapt.transfer import PointEvaluator, transfer_function
from convection.io.checkpoint import (CheckpointError, block, fill_functions, latest_checkpoint,
                                      read_checkpoint)
from fembase.distribute import MeshPiece, create_mesh_from_piece
from fembase.dolfinx_compat import coordinate_element_from, function_space, mesh_domain

__all__ = ["KEY", "initial_temperature", "source_checkpoint"]

KEY = "initial.from_run"
"""The config key naming the source."""

def source_checkpoint(path: str | os.PathLike[str], /) -> Path | None:
    """The checkpoint folder ``path`` names: the newest of a run folder, or ``path`` itself when it
    is a checkpoint folder (holds a state.h5); None if neither."""
    folder = Path(path)
    if (folder / "state.h5").is_file():
        return folder
    return latest_checkpoint(folder) if folder.is_dir() else None


def _saved_temperature(path: Path) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Every rank's saved dof coordinates and values of the temperature (every rank reads all)."""
    with h5py.File(path / "state.h5", "r") as f:
        group = f["functions/temperature/T"]
        return group["coords"][...], group["values"][...].reshape(-1)


def _copy_if_same_nodes(target: dolfinx.fem.Function, coords: npt.NDArray[np.float64],
                        values: npt.NDArray[np.float64]) -> bool:
    """Copy the saved values into ``target`` if every owned node of it is a saved node, on every
    rank (collective); returns whether it did."""
    V = target.function_space
    n = V.dofmap.index_map.size_local
    local = V.tabulate_dof_coordinates()[:n]
    from scipy.spatial import cKDTree  # here, not at import: scipy.spatial is 23 MB a process
    distance, index = cKDTree(coords).query(local) if n else (np.zeros(0), np.zeros(0, dtype=int))
    scale = max(1.0, float(np.abs(coords).max(initial=0.0)))
    same = bool(np.all(distance <= 1e-12 * scale))
    if not V.mesh.comm.allreduce(same, op=MPI.LAND):
        return False
    target.x.array[:n] = values[index]
    target.x.scatter_forward()
    return True


def _source_mesh(path: Path, comm: MPI.Comm, like: dolfinx.mesh.Mesh) -> dolfinx.mesh.Mesh:
    """The source's mesh made again on ``comm`` from its saved cells: each rank takes an equal block
    of the saved cells and nodes and keeps its cells (collective). ``like``: a mesh of the new run
    (its cell type and dimension; the saved geometry is affine)."""
    with h5py.File(path / "state.h5", "r") as f:
        cells, x = block(f, "mesh/cells", comm), block(f, "mesh/x", comm)
    owners = np.full(cells.shape[0], comm.rank, dtype=np.int32)
    domain = mesh_domain(coordinate_element_from((like.topology.cell_name(), 1, like.geometry.dim)))
    return create_mesh_from_piece(comm, MeshPiece(cells.astype(np.int64), x, owners), domain).mesh


def initial_temperature(source: str | os.PathLike[str], target: dolfinx.fem.Function, /) -> bool:
    """Set the Function ``target`` (the new run's temperature space) to the source run's
    temperature (module docstring). Collective.

    Returns:
        True when the values were copied (the same nodes), False when interpolated.

    Raises:
        CheckpointError: On every rank: the source has no readable checkpoint or no temperature.
    """
    mesh = target.function_space.mesh
    comm = mesh.comm
    path = source_checkpoint(source)
    if path is None:
        raise CheckpointError(f"{KEY}: '{source}' holds no checkpoint")
    saved = read_checkpoint(path, comm)
    coords, values = _saved_temperature(saved.path)
    if _copy_if_same_nodes(target, coords, values):
        return True
    other = _source_mesh(saved.path, comm, mesh)
    T = dolfinx.fem.Function(function_space(other, "Lagrange", int(saved.config["energy"]["degree"])))
    fill_functions(saved, {"temperature/T": T}, exact=False)
    transfer_function(T, target, evaluator=PointEvaluator(other, snap=True))
    return False
