"""Whole-run checkpoints: everything a run needs to go on as if it had never stopped.

A checkpoint is a folder ``RUN_DIR/checkpoints/checkpoint_NNNNNN`` (NNNNNN = the step) holding

- ``state.h5``: format and version attributes, the resolved config (YAML text), the run state
  (JSON: the scalars of every stateful component of the model by its name —
  :meth:`convection.model.Model.components`, each a :class:`fembase.state.Stateful`: the model's
  time stepping, the flow, the temperature's and the advected fractions' time history, the particle
  manager's counters — and the run loop's state with its postprocessors'), how the mesh was made —
  the owner rank of every cell of the base mesh the domain made
  (:meth:`convection.geometry.domain.Domain.create_mesh`; ``mesh/created_owners``, while the run
  still stands on it) and
  :class:`convection.adapt.hierarchy.MeshRecipe` (the refinement rounds since, or every rank's pieces
  handed to ``create_mesh`` at the latest repartition) — every rank's fingerprint of the base and of
  the current mesh (:func:`fembase.distribute.mesh_fingerprint`), the mesh's cells (global vertex
  indices, the owned vertex coordinates and the base cell, for a restart on another rank count), and
  the fields of every component (``functions/<component>/<name>``: ``u``, ``p``, ``T^n``,
  ``T^{n-1}``, ``T^{n-2}``, ``u^{n-1}``, advected or static material fractions): owned dof values
  with the owned dof coordinates;
- ``particles.h5``: the particles with their properties (:func:`particles.io.swarm_checkpoint.save_checkpoint`);
  with several particle systems one file per system, ``particles_<name>.h5``
  (:func:`particles.systems.file_stem`).

The folder is written under a hidden temporary name and renamed when complete, so a run killed at
any moment leaves only complete checkpoints under ``checkpoint_*`` names (at worst a stray hidden
temporary folder, removed by the next checkpoint). Only the newest ``keep`` are kept.

Restoring on the rank count it was written on makes the mesh as the run made it, with the saved
owners imposed instead of a partitioner run again, checks every rank's fingerprint, and copies the
dof values: the continuation is bit for bit the uninterrupted run (every part of a run is
deterministic on a fixed rank count: the mesh partition, see
:func:`fembase.distribute.create_reproducible_mesh`, and the direct solver, see
:func:`convection.solvers.petsc_options.reproducible_lu`). If the mesh does not come back exactly (a
fingerprint differs, or the checkpoint has none), and on another rank count, the mesh is rebuilt
from its cells and partitioned afresh (each rank reads an equal block of the saved cells and
vertices and hands them to ``create_mesh``; no rank reads all of them), the fields are matched dof
by dof through their coordinates, and the particles are located and migrated: the same run to
round-off (on the same rank count the run says so in one line).
"""

from __future__ import annotations

import contextlib

import json
import os
import re
import shutil
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Callable, Mapping
from typing import Any

import h5py
import numpy as np
import numpy.typing as npt
import yaml
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from convection.adapt.hierarchy import MeshHierarchy, MeshRecipe
from fembase.manifold import ShellManifold
from convection.model.model import Model
from convection.schema import param
from fembase.state import State
from fembase.distribute import MeshPiece, create_mesh_from_piece, mesh_piece
from fembase.distribute import cell_owners_by_input, mesh_fingerprint
from fembase.files import H5Sink
from particles.io.swarm_checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from particles.manager import ParticleManager
from particles.systems import file_stem
from particles.properties import PropertyContext

__all__ = ["CONFIG_VERSION", "CheckpointError", "CheckpointSettings", "Checkpointer", "SavedRun", "latest_checkpoint",
           "block", "fill_functions", "inspect_checkpoint", "list_checkpoints", "saved_values", "read_checkpoint",
           "restore_mesh", "restore_particles", "restore_state", "write_checkpoint"]

FORMAT = "convection-checkpoint"
VERSION = 4  # 4: the scalars of each component (state "components"); 3: created owners and mesh fingerprints;
# 2: the recipe and the mesh's cells as distributed pieces
READABLE_VERSIONS = (2, 3, 4)  # 2 is continued by coordinates (no fingerprints to prove an exact replay)
CONFIG_VERSION = 1
"""Version of the config schema a checkpoint's config was written with; raise it when a change of
the schema would change the meaning of an old config."""

_NAME = "checkpoint_"
_CHECKPOINT_NAME = re.compile(rf"{_NAME}[0-9]+")
"""The names the writer gives checkpoint folders (ASCII digits only)."""


@dataclass(frozen=True)
class CheckpointSettings:
    """When checkpoints are written: the ``output.checkpoint`` config section.

    Attributes:
        every_steps: Every this many steps (None: not by steps).
        every_wall_seconds: When this much wall time passed since the last one (None: not by time).
        keep: How many of the newest checkpoints are kept.
        at_end: Also at the end of the run and when it is stopped by a signal.
    """

    every_steps: int | None = param(None, minimum=1, help="write a checkpoint every N steps")
    every_wall_seconds: float | None = param(3600.0, exclusive_minimum=0.0,
                                             help="write a checkpoint when this much wall time passed since the last")
    keep: int = param(2, minimum=1, help="how many of the newest checkpoints are kept")
    at_end: bool = param(True, help="also write one at the end and when stopped by a signal")


@dataclass
class SavedRun:
    """A checkpoint read back (the same on every rank; arrays are read per rank on restore).

    Attributes:
        path: The checkpoint folder.
        config: The resolved config it was written with.
        state: The run state (JSON-able dict, see the module docstring).
        num_ranks: The rank count it was written on.
    """

    path: Path
    config: dict[str, Any]
    state: dict[str, Any]
    num_ranks: int

    @property
    def components(self) -> dict[str, Any]:
        """The saved scalars of each component by name (:meth:`convection.model.Model.components`);
        a checkpoint of format 2 or 3 kept them in one ``model`` dict, read here the same way."""
        if "components" in self.state:
            return self.state["components"]
        old = self.state["model"]
        out = {"model": {key: old[key] for key in ("time", "timestep", "dt_previous", "has_u_previous", "flow",
                                                   "timers")},
               "stokes": {}, "composition": {"solvers": old["composition"]}}
        if old["temperature"] is not None:
            out["temperature"] = old["temperature"]
        if old["particles"] is not None:
            out["particles"] = old["particles"]
        return out


# ---------------------------------------------------------------------- listing
def list_checkpoints(run_dir: str | os.PathLike[str], /) -> list[Path]:
    """The complete checkpoints of a run folder, oldest first: the folders named as the writer
    names them (``checkpoint_`` and the step's digits) that hold a ``state.h5``. Anything else in
    ``checkpoints/`` (a copy such as ``checkpoint_000010.bak``, a temporary folder) is ignored."""
    folder = Path(run_dir) / "checkpoints"
    if not folder.is_dir():
        return []
    found = [p for p in folder.iterdir() if _CHECKPOINT_NAME.fullmatch(p.name) and p.is_dir()
             and (p / "state.h5").is_file()]
    return sorted(found, key=lambda p: (int(p.name[len(_NAME):]), p.name))


def latest_checkpoint(run_dir: str | os.PathLike[str], /) -> Path | None:
    """The newest complete checkpoint of a run folder, or None."""
    found = list_checkpoints(run_dir)
    return found[-1] if found else None


# ---------------------------------------------------------------------- what is saved
def component_states(model: Model) -> dict[str, State]:
    """What every stateful component of ``model`` keeps (:meth:`convection.model.Model.components`)."""
    return {name: component.state() for name, component in model.components().items()}


# ---------------------------------------------------------------------- write
def _owned(f: dolfinx.fem.Function) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Owned dof values shape=(n_nodes, bs) and their coordinates shape=(n_nodes, 3)."""
    V = f.function_space
    n = V.dofmap.index_map.size_local
    bs = V.dofmap.index_map_bs
    return f.x.array[: n * bs].reshape(n, bs), V.tabulate_dof_coordinates()[:n]


def _write_piece(sink: H5Sink, name: str, piece: MeshPiece | None) -> None:
    """Every rank's piece (:class:`fembase.distribute.MeshPiece`), concatenated in rank order, with
    the row counts per rank (the cells' global vertex indices stay valid: the vertex blocks are
    concatenated in the same order)."""
    flag = sink.comm.allreduce(int(piece is not None), op=MPI.MAX)
    if not flag:
        return
    comm = sink.comm
    sink.distributed(f"{name}/cells", piece.cells)
    sink.distributed(f"{name}/x", piece.x)
    sink.distributed(f"{name}/owners", piece.owners)
    canonical = piece.canonical
    has_canonical = comm.allreduce(int(canonical is not None), op=MPI.MAX)
    if has_canonical:
        sink.distributed(f"{name}/canonical", canonical)
    sink.replicated(f"{name}/cell_counts", np.asarray(comm.allgather(piece.cells.shape[0]), dtype=np.int64))
    sink.replicated(f"{name}/x_counts", np.asarray(comm.allgather(piece.x.shape[0]), dtype=np.int64))


def _write_recipe(sink: H5Sink, recipe: MeshRecipe) -> list[str]:
    _write_piece(sink, "recipe/base", recipe.base)
    _write_piece(sink, "recipe/mesh", recipe.mesh)
    for i, piece in enumerate(recipe.levels):
        _write_piece(sink, f"recipe/level_{i}", piece)
    rounds = []
    for i, marked in enumerate(recipe.rounds):
        kind = "uniform" if marked is None else "marked"
        if marked is not None:
            sink.distributed(f"recipe/round_{i}", np.asarray(marked, dtype=np.int32))
            sink.replicated(f"recipe/round_{i}_counts",
                            np.asarray(sink.comm.allgather(int(marked.size)), dtype=np.int64))
        rounds.append(kind)
    return rounds


def _write_partition(sink: H5Sink, mesh: dolfinx.mesh.Mesh, hierarchy: MeshHierarchy | None) -> None:
    """What a restore on the same ranks needs to rebuild the mesh exactly and to prove it did: the
    owner of every cell of the mesh ``create_mesh`` made (by input index, when the run still stands
    on it: no repartition since), and every rank's fingerprint of the base and of the current mesh."""
    comm = sink.comm
    created = mesh if hierarchy is None else hierarchy.base
    if hierarchy is None or hierarchy.recipe.base is None:
        owners = cell_owners_by_input(created)
        sink.distributed("mesh/created_owners", owners if owners is not None else np.zeros(0, dtype=np.int32))
    for name, which in (("base", created), ("mesh", mesh)):
        digests = comm.allgather(np.frombuffer(mesh_fingerprint(which), dtype=np.uint8))
        sink.replicated(f"mesh/fingerprints/{name}", np.stack(digests))


def write_checkpoint(model: Model, run_dir: str | os.PathLike[str], /, *, config: dict[str, Any],
                     run_state: dict[str, Any], keep: int = 2) -> Path:
    """Write a checkpoint of ``model`` at its current step into ``run_dir/checkpoints`` (collective,
    atomic); keeps the newest ``keep``. ``run_state`` is the run loop's JSON-able state."""
    comm = model.comm
    folder = Path(run_dir) / "checkpoints"
    final = folder / f"{_NAME}{model.timestep:06d}"
    token = comm.bcast(uuid.uuid4().hex if comm.rank == 0 else None, root=0)  # in every part: they belong together
    tmp = folder / f".{final.name}.{token[:8]}.tmp"
    if comm.rank == 0:
        for stray in folder.glob(".checkpoint_*.tmp"):
            shutil.rmtree(stray, ignore_errors=True)
        tmp.mkdir(parents=True)
    comm.Barrier()
    hierarchy = model.hierarchy if model.hierarchy is not None else (
        model.adaptivity.hierarchy if model.adaptivity else (model.balancer.hierarchy if model.balancer else None))
    states = component_states(model)
    state = {"components": {name: s.scalars for name, s in states.items()}, "run": run_state, "num_ranks": comm.size,
             "recipe_rounds": None, "hierarchy": hierarchy is not None}
    with H5Sink(tmp / "state.h5", comm) as sink:
        if hierarchy is not None:
            state["recipe_rounds"] = _write_recipe(sink, hierarchy.recipe)
        mesh = model.mesh
        n = mesh.topology.index_map(mesh.topology.dim).size_local
        # A free surface's mesh is made again undeformed, then takes the saved coordinates.
        with model.free_surface.undeformed() if model.free_surface is not None else contextlib.nullcontext():
            cells = mesh_piece(mesh, np.zeros(n, dtype=np.int32))  # the owners are chosen on restore
            sink.distributed("mesh/cells", cells.cells)
            sink.distributed("mesh/x", cells.x)
            sink.distributed("mesh/base_cells", hierarchy.base_cells(mesh) if hierarchy is not None
                             else np.zeros(n, dtype=np.int64))
            _write_partition(sink, mesh, hierarchy)
        functions = {f"{component}/{name}": f for component, s in states.items() for name, f in s.fields.items()}
        for name, f in functions.items():
            values, coords = _owned(f)
            sink.distributed(f"functions/{name}/values", values)
            sink.distributed(f"functions/{name}/coords", coords)
            sink.replicated(f"functions/{name}/counts", np.asarray(comm.allgather(values.shape[0]), dtype=np.int64))
        sink.replicated("config", np.frombuffer(yaml.safe_dump(config, sort_keys=False).encode(), dtype=np.uint8))
        sink.replicated("state", np.frombuffer(json.dumps(state).encode(), dtype=np.uint8))
        sink.attrs(format=FORMAT, version=VERSION, config_version=CONFIG_VERSION, num_ranks=comm.size,
                   step=model.timestep, time=model.time, token=token)
    for name, manager in model.particles.items() if model.particles is not None else ():
        save_checkpoint(tmp / f"{file_stem(name)}.h5", manager.swarm, step=model.timestep, time=model.time, token=token)
    comm.Barrier()
    if comm.rank == 0:
        if final.exists():
            shutil.rmtree(final)
        os.rename(tmp, final)
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        for old in list_checkpoints(run_dir)[:-keep] if keep > 0 else []:
            shutil.rmtree(old, ignore_errors=True)
    comm.Barrier()
    return final


# ---------------------------------------------------------------------- read
def inspect_checkpoint(path: str | os.PathLike[str], /) -> SavedRun | str:
    """A checkpoint folder read back, or what is wrong with it in a few words (not collective)."""
    return _inspect(Path(path))


def _inspect(path: Path) -> SavedRun | str:
    """Check a checkpoint folder alone (rank 0); returns it read back, or what is wrong.

    Its parts must belong together: ``write_checkpoint`` puts one random ``token`` attribute into
    state.h5 and particles.h5, so a particles.h5 copied in from another run or checkpoint is
    refused (checkpoints written before the token: the ``step`` attributes must agree)."""
    if not path.is_dir():
        return "missing (no such checkpoint folder)"
    state_file = path / "state.h5"
    try:
        if not h5py.is_hdf5(state_file):
            return "state.h5 is not an HDF5 file"
        with h5py.File(state_file, "r") as f:
            if f.attrs.get("format") != FORMAT:
                return f"not a run checkpoint (format attribute {f.attrs.get('format')!r})"
            if int(f.attrs.get("version", -1)) not in READABLE_VERSIONS:
                return (f"checkpoint format version {int(f.attrs.get('version', -1))}, this code reads "
                        f"{' and '.join(map(str, READABLE_VERSIONS))}")
            if int(f.attrs.get("config_version", -1)) != CONFIG_VERSION:
                return (f"written with config version {int(f.attrs.get('config_version', -1))}, this code reads "
                        f"config version {CONFIG_VERSION}")
            config = yaml.safe_load(f["config"][...].tobytes().decode())
            state = json.loads(f["state"][...].tobytes().decode())
            num_ranks = int(f.attrs["num_ranks"])
            identity = _identity(f)
    except (OSError, ValueError, KeyError, TypeError, yaml.YAMLError) as err:
        return f"damaged ({' '.join(str(err).split())})"
    saved = SavedRun(path, config, state, num_ranks)
    try:
        parts = [name for name in saved.components if name == "particles" or name.startswith("particles_")]
    except (KeyError, TypeError, AttributeError) as err:
        return f"damaged (its state lacks {err})"
    for part in parts:  # one swarm per particle system
        problem = _other_part(path / f"{part}.h5", identity)
        if problem is not None:
            return problem
    return saved


def _identity(f: h5py.File) -> tuple[str | None, int]:
    """What proves a part belongs to this checkpoint: the token ``write_checkpoint`` put into every
    part (None in checkpoints written before it did) and the step."""
    token = f.attrs.get("token")
    return (None if token is None else str(token)), int(f.attrs.get("step", -1))


def _other_part(part: Path, identity: tuple[str | None, int]) -> str | None:
    """What is wrong with a part of a checkpoint (rank 0): missing, damaged, or written by another
    checkpoint (its token or step differs from state.h5's); None if it belongs."""
    if not part.is_file():
        return f"{part.name} is missing"
    try:
        if not h5py.is_hdf5(part):
            return f"{part.name} is not an HDF5 file"
        with h5py.File(part, "r") as f:
            token, step = _identity(f)
    except (OSError, ValueError, TypeError) as err:
        return f"{part.name} is damaged ({' '.join(str(err).split())})"
    expected_token, expected_step = identity
    if expected_token is not None and token != expected_token:
        return (f"{part.name} does not belong to this checkpoint (its token differs from state.h5's: copied from "
                "another run or checkpoint?)")
    if step != expected_step:
        return f"{part.name} is of step {step}, state.h5 of step {expected_step} (copied from another checkpoint?)"
    return None


def read_checkpoint(path: str | os.PathLike[str], comm: MPI.Comm, /) -> SavedRun:
    """Read and check a checkpoint folder (collective).

    Raises:
        CheckpointError: On every rank, one line naming the folder: missing, damaged, or written
            by another format or config version.
    """
    path = Path(comm.bcast(str(path) if comm.rank == 0 else None, root=0))
    saved = _inspect(path) if comm.rank == 0 else None
    saved = comm.bcast(saved, root=0)
    if isinstance(saved, str):
        raise CheckpointError(f"checkpoint {path}: {saved}")
    return saved


def _slice(f: h5py.File, name: str, counts: npt.NDArray[np.int64], rank: int) -> npt.NDArray:
    start = int(counts[:rank].sum())
    return f[name][start: start + int(counts[rank])]


def _read_piece(f: h5py.File, name: str, comm: MPI.Comm) -> MeshPiece:
    """This rank's piece as it was written (the same rank count)."""
    cell_counts, x_counts = f[f"{name}/cell_counts"][...], f[f"{name}/x_counts"][...]
    canonical = _slice(f, f"{name}/canonical", cell_counts, comm.rank) if f"{name}/canonical" in f else None
    return MeshPiece(_slice(f, f"{name}/cells", cell_counts, comm.rank), _slice(f, f"{name}/x", x_counts, comm.rank),
                     _slice(f, f"{name}/owners", cell_counts, comm.rank).astype(np.int32), canonical)


def block(f: h5py.File, name: str, comm: MPI.Comm) -> npt.NDArray:
    """This rank's equal block of rows of a dataset (another rank count than it was written on)."""
    total = int(f[name].shape[0])
    return f[name][total * comm.rank // comm.size: total * (comm.rank + 1) // comm.size]


@dataclass
class RestoredMesh:
    """The mesh a checkpoint's run stood on, made again (:func:`restore_mesh`).

    Attributes:
        mesh: The mesh.
        hierarchy: Its base mesh and levels (None: the run had no adaptivity or balancing).
        exact: True when the mesh, its partition and numbering are the saved ones (then the saved
            dof values are copied and the run continues bit for bit); False when it was rebuilt
            from the saved cells (the fields are matched by coordinates).
        note: Why an exact restore was not possible on the rank count it was written on (one
            line), or None.
    """

    mesh: dolfinx.mesh.Mesh
    hierarchy: MeshHierarchy | None
    exact: bool
    note: str | None = None


def restore_mesh(saved: SavedRun, comm: MPI.Comm,
                 make_base: Callable[[npt.NDArray[np.int32] | None], dolfinx.mesh.Mesh], /, *, hierarchical: bool,
                 manifold: ShellManifold | None = None) -> RestoredMesh:
    """The checkpoint's mesh (collective).

    On the rank count it was written on the mesh is made as the run made it: the base mesh with the
    saved owner of every cell imposed (``make_base(owners)``, owners by input index on rank 0), or
    the saved base pieces of the latest repartition, then the saved refinement rounds or pieces
    (:class:`convection.adapt.hierarchy.MeshRecipe`). The result must have the saved fingerprint on every
    rank (:func:`fembase.distribute.mesh_fingerprint`); otherwise, and on another rank count, the mesh
    is rebuilt from the saved cells and partitioned afresh (each rank reads an equal block of the
    saved cells and vertices; no rank reads all; the base cells go to ranks in equal blocks of
    canonical index and every cell to the rank of its base cell), and the result says why in
    ``note``.

    Args:
        saved: The checkpoint.
        comm: The run's communicator.
        make_base: Makes the config's base mesh, on the given partition (None: its own choice).
        hierarchical: Whether the run has a :class:`convection.adapt.hierarchy.MeshHierarchy`
            (adaptivity or balancing).
        manifold: The hierarchy's manifold (curved shells; ``make_base`` then makes the straight base).
    """
    note = None
    if saved.num_ranks == comm.size:
        restored = _replay(saved, comm, make_base, hierarchical, manifold)
        if isinstance(restored, RestoredMesh):
            return restored
        note = (f"checkpoint {saved.path}: {restored}, so the continuation is the same run to round-off, "
                f"not bit for bit (fields matched by coordinates, particles located again)")
    else:
        note = (f"checkpoint {saved.path}: written on {saved.num_ranks} ranks, resumed on {comm.size}: the "
                f"continuation is the same run to round-off, not bit for bit (fields matched by coordinates, "
                f"particles located again)")
    base = make_base(None)
    hierarchy = MeshHierarchy(base, manifold=manifold) if hierarchical else None
    if hierarchy is None:
        return RestoredMesh(base, None, False, note)  # the base mesh, made the same way on any rank count
    with h5py.File(saved.path / "state.h5", "r") as f:
        if "recipe/base" in f:
            # The saved base pieces, read in equal blocks: the global vertex numbering of the
            # concatenated pieces holds on any rank count.
            canonical = block(f, "recipe/base/canonical", comm).astype(np.int64)
            owners = (canonical * comm.size // max(hierarchy.num_base_cells, 1)).astype(np.int32)
            hierarchy.replay(MeshRecipe(MeshPiece(block(f, "recipe/base/cells", comm),
                                                  block(f, "recipe/base/x", comm), owners, canonical), []))
        cells, x = block(f, "mesh/cells", comm), block(f, "mesh/x", comm)
        base_cells = block(f, "mesh/base_cells", comm)
    # The saved cells, each sent to the rank that owns its base cell, so the mesh and its base
    # stay together (load balancing needs that).
    owners = _base_owners(hierarchy)[base_cells]
    mesh = create_mesh_from_piece(comm, MeshPiece(cells, x, owners), hierarchy.mesh_domain()).mesh
    return RestoredMesh(mesh, hierarchy, False, note)


def _replay(saved: SavedRun, comm: MPI.Comm, make_base: Callable[[npt.NDArray[np.int32] | None], dolfinx.mesh.Mesh],
            hierarchical: bool, manifold: ShellManifold | None = None) -> RestoredMesh | str:
    """The saved mesh made again on the same ranks, checked against the saved fingerprints; or why
    not (collective; the same answer on every rank)."""
    with h5py.File(saved.path / "state.h5", "r") as f:
        if "mesh/fingerprints/mesh" not in f:
            return "it holds no mesh fingerprints (written by an older version)"
        expected = {name: f[f"mesh/fingerprints/{name}"][comm.rank].tobytes() for name in ("base", "mesh")}
        owners = None
        if comm.rank == 0 and "mesh/created_owners" in f:
            owners = f["mesh/created_owners"][...].astype(np.int32)
        pieces = {name: _read_piece(f, f"recipe/{name}", comm) if f"recipe/{name}" in f else None
                  for name in ("base", "mesh")}
        levels = []  # the meshes between the base and the mesh a repartition moved (multigrid levels)
        while f"recipe/level_{len(levels)}" in f:
            levels.append(_read_piece(f, f"recipe/level_{len(levels)}", comm))
        rounds = []
        for i, kind in enumerate(saved.state["recipe_rounds"] or []):
            counts = f[f"recipe/round_{i}_counts"][...] if kind == "marked" else None
            rounds.append(None if kind == "uniform"
                          else _slice(f, f"recipe/round_{i}", counts, comm.rank).astype(np.int32))
    # A checkpoint after a repartition rebuilds its base from the saved pieces, not from the config.
    base = make_base(owners if pieces["base"] is None else None)
    hierarchy = MeshHierarchy(base, manifold=manifold) if hierarchical else None
    if hierarchy is not None and pieces["base"] is not None:
        hierarchy.replay(MeshRecipe(pieces["base"], []))  # the base only
    created = base if hierarchy is None else hierarchy.base
    if not comm.allreduce(mesh_fingerprint(created) == expected["base"], op=MPI.LAND):
        return f"its base mesh could not be made again on {comm.size} ranks as it was saved"
    mesh = base if hierarchy is None else hierarchy.replay(MeshRecipe(pieces["base"], rounds, pieces["mesh"], levels),
                                                           base=False)
    if not comm.allreduce(mesh_fingerprint(mesh) == expected["mesh"], op=MPI.LAND):
        return f"its mesh could not be made again on {comm.size} ranks as it was saved"
    return RestoredMesh(mesh, hierarchy, True)


def _base_owners(hierarchy: MeshHierarchy) -> npt.NDArray[np.int32]:
    """Owner rank of every canonical base cell (collective; every rank gets all: O(base cells))."""
    base = hierarchy.base
    n = base.topology.index_map(hierarchy.tdim).size_local
    owners = np.full(hierarchy.num_base_cells, -1, dtype=np.int32)
    owners[hierarchy.base_canonical[:n]] = base.comm.rank
    total = np.empty_like(owners)
    base.comm.Allreduce(owners, total, op=MPI.MAX)
    return total


def restore_state(model: Model, saved: SavedRun, /, *, exact: bool) -> None:
    """Give every stateful component of ``model`` (built on the restored mesh from the checkpoint's
    config) its saved scalars, then fill the Functions it hands back with the saved values: copied
    when ``exact`` (the same mesh, partition and numbering), else matched by coordinates; then
    call the ``restored()`` of the components that have one. The particle swarm is restored
    before (:func:`restore_particles`). Collective."""
    saved_scalars = saved.components
    functions: dict[str, dolfinx.fem.Function] = {}
    for component, stateful in model.components().items():
        if component not in saved_scalars:
            raise CheckpointError(f"checkpoint {saved.path}: no saved state of the {component}")
        for name, target in stateful.restore(saved_scalars[component]).items():
            functions[f"{component}/{name}"] = target
    fill_functions(saved, functions, exact=exact)
    for stateful in model.components().values():
        stateful.restored()


def fill_functions(saved: SavedRun, functions: Mapping[str, dolfinx.fem.Function], /, *, exact: bool) -> None:
    """Fill each Function from the checkpoint's saved values of the same name
    (``<component>/<name>``): copied when ``exact``, else matched by coordinates. Collective."""
    if not functions:
        return
    comm = next(iter(functions.values())).function_space.mesh.comm
    with h5py.File(saved.path / "state.h5", "r") as f:
        nested: dict[str, h5py.Group] = {}
        _collect(f["functions"], "", nested)
        missing = sorted(set(functions) - set(nested))
        if missing:
            raise CheckpointError(f"checkpoint {saved.path}: no saved values for {missing}")
        for name, target in functions.items():
            group = f[f"functions/{name}"]
            if exact:
                counts = group["counts"][...]
                values = _slice(f, f"functions/{name}/values", counts, comm.rank)
                bs = target.function_space.dofmap.index_map_bs
                target.x.array[: values.size] = values.reshape(-1)
                if values.size != target.function_space.dofmap.index_map.size_local * bs:
                    raise CheckpointError(f"checkpoint {saved.path}: {name} does not fit the replayed mesh")
            else:
                _match_by_coordinates(target, group["coords"][...], group["values"][...])
            target.x.scatter_forward()


def saved_values(saved: SavedRun, name: str, /) -> npt.NDArray[np.float64]:
    """Every rank's saved values of the Function ``name`` (``<component>/<name>``), concatenated
    in rank order, shape=(n, block size). Every rank reads the whole dataset."""
    with h5py.File(saved.path / "state.h5", "r") as f:
        if f"functions/{name}/values" not in f:
            raise CheckpointError(f"checkpoint {saved.path}: no saved values for {name}")
        return f[f"functions/{name}/values"][...]


def restore_particles(saved: SavedRun, manager: ParticleManager, context: PropertyContext, /, *,
                      part: str = "particles") -> bool:
    """Give ``manager`` the checkpoint's particle swarm ``<part>.h5`` (collective; its scalars come
    back with the other components', :func:`restore_state`). Returns whether the particles came back
    exactly (same ranks, same order)."""
    restored = load_checkpoint(saved.path / f"{part}.h5", manager.mesh)
    manager.adopt(restored.swarm, context=context)
    return restored.exact


def _collect(group: h5py.Group, prefix: str, out: dict) -> None:
    """Names of the saved functions (groups holding a ``values`` dataset)."""
    for key, item in group.items():
        if isinstance(item, h5py.Group):
            if "values" in item:
                out[f"{prefix}{key}"] = item
            else:
                _collect(item, f"{prefix}{key}/", out)


def _match_by_coordinates(target: dolfinx.fem.Function, coords: npt.NDArray, values: npt.NDArray) -> None:
    """Set every local dof of ``target`` from the saved dof at the same coordinates."""
    V = target.function_space
    bs = V.dofmap.index_map_bs
    local = V.tabulate_dof_coordinates()
    from scipy.spatial import cKDTree  # here, not at import: scipy.spatial is 23 MB a process
    distance, index = cKDTree(coords).query(local)
    scale = max(1.0, float(np.abs(coords).max(initial=0.0)))
    if local.shape[0] and distance.max() > 1e-9 * scale:
        raise CheckpointError(f"a saved field ({target.name}) does not match the mesh: a dof {distance.max():.3g} "
                              "away from every saved one")
    target.x.array[: local.shape[0] * bs] = values[index].reshape(-1)


class Checkpointer:
    """Writes the checkpoints of a run when they are due (collective decisions).

    Args:
        settings: When to write.
        run_dir: The run's output folder.
        config: The resolved config (stored in every checkpoint).
        resumed_at: The step of the checkpoint a resumed run started from (not written again).
    """

    def __init__(self, settings: CheckpointSettings, run_dir: str | os.PathLike[str], config: dict[str, Any], /, *,
                 resumed_at: int | None = None) -> None:
        self.settings = settings
        self.run_dir = Path(run_dir)
        self.config = config
        self._last_step = resumed_at
        self._last_wall = time.monotonic()
        self.written: list[Path] = []

    def due(self, model: Model, /) -> bool:
        """Whether a checkpoint is due after the current step (the same answer on every rank)."""
        if model.timestep == self._last_step:
            return False
        every = self.settings.every_steps
        if every is not None and model.timestep > 0 and model.timestep % every == 0:
            return True
        if self.settings.every_wall_seconds is None:
            return False
        late = time.monotonic() - self._last_wall >= self.settings.every_wall_seconds
        return bool(model.comm.bcast(late, root=0))

    def write(self, model: Model, run_state: dict[str, Any], /, *, only_if_new: bool = False) -> Path | None:
        """Write a checkpoint now (unless ``only_if_new`` and this step has one)."""
        if only_if_new and model.timestep == self._last_step:
            return None
        with model.timers("checkpoint"):
            path = write_checkpoint(model, self.run_dir, config=self.config, run_state=run_state,
                                    keep=self.settings.keep)
        self._last_step = model.timestep
        self._last_wall = time.monotonic()
        self.written.append(path)
        return path

