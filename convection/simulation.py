"""The time loop of a convection run, built from a resolved configuration.

Per step (Boussinesq, see :mod:`convection.approximation`):

1. dt from the CFL number of the current velocity (:func:`convection.timestep.cfl_timestep`);
2. advance the temperature by dt with the current velocity (:class:`convection.transport.TransportSolver`);
3. solve Stokes with the new temperature and the composition field (:class:`convection.stokes.StokesSolver`);
4. statistics row (time, dt, vrms, Nusselt, T mean/min/max, cells), progress, field output;
5. every ``adaptivity.every`` steps: rebuild the mesh from the base mesh (:mod:`convection.adaptivity`)
   and carry every field to it.

The composition field C enters the buoyancy (Ra T - Rb C) e_z and the viscosity. With
``composition.source: static`` it is set from ``initial.composition`` and kept fixed; with
``field`` it is a continuous P(k) field advected after the temperature with the same SUPG/BDF2
scheme (no diffusion); with
``particles`` it is averaged per step from advected particles
(:class:`convection.particle_composition.ParticleComposition`): after the temperature step the
particles move from t^n to t^{n+1} in the velocity interpolated linearly in time between u^n and
the extrapolation u* = (1 + w) u^n - w u^{n-1} (w = dt_n / dt_{n-1}; u* = u^n on the first step),
then C is re-averaged and Stokes is solved with it.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, NamedTuple

import numpy as np
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh
import ufl

from convection.adaptivity import AdaptivityParameters, MeshHierarchy, kelly_indicator, wanted_levels
from convection.approximation import BoussinesqApproximation, ViscosityLaw
from convection.boundary import TemperatureBC, VelocityBC, side_names
from convection.config import dump_config, expression_constants
from convection.diagnostics import RunDiagnostics
from convection.transport import TransportSolver
from convection.expressions import Expression
from convection.mesh import BoxSpec, create_box_mesh
from convection.output import FieldOutput
from convection.particle_composition import ParticleComposition
from convection.progress import Progress
from convection.statistics import BalanceLog, StatisticsWriter
from convection.stokes import StokesSolver
from convection.timestep import cfl_timestep
from convection.transfer import PointEvaluator, transfer_function

__all__ = ["RunSummary", "Simulation", "STATISTICS_COLUMNS"]

STATISTICS_COLUMNS = (
    "step", "time", "dt", "vrms", "nusselt", "T_mean", "T_min", "T_max", "cells", "stokes_iterations",
    "n_particles", "n_lost", "cell_imbalance", "particle_imbalance", "entrainment", "wall_time",
)


class _Solvers(NamedTuple):
    """The solvers and fields of one mesh (kept while their values move to a new mesh)."""

    stokes: StokesSolver
    energy: TransportSolver
    composition: dolfinx.fem.Function | None
    composition_solver: TransportSolver | None

    def destroy(self) -> None:
        """Free the solvers' PETSc objects (collective)."""
        for solver in (self.stokes, self.energy, self.composition_solver):
            if solver is not None:
                solver.destroy()


@dataclass(frozen=True)
class RankLoads:
    """Per-rank counts, each shape=(num_ranks,): owned cells, particles, load = cells + W particles."""

    cells: np.ndarray
    particles: np.ndarray
    load: np.ndarray

    @staticmethod
    def _ratio(values: np.ndarray) -> float:
        mean = float(np.mean(values))
        return float(np.max(values)) / mean if mean > 0 else 1.0

    @property
    def cell_imbalance(self) -> float:
        return self._ratio(self.cells)

    @property
    def particle_imbalance(self) -> float:
        return self._ratio(self.particles)

    @property
    def load_imbalance(self) -> float:
        return self._ratio(self.load)


@dataclass(frozen=True)
class RunSummary:
    """What a finished (or stopped) run reached."""

    steps: int
    time: float
    vrms: float
    nusselt: float
    cells: int
    wall_time: float
    reason: str

    def as_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def velocity_bcs_from_config(section: dict, gdim: int) -> dict[str, VelocityBC]:
    """Velocity conditions per side of the ``boundary.velocity`` section (null sides: traction free)."""
    result = {}
    for side in side_names(gdim):
        value = section[side]
        if value is None:
            continue
        if isinstance(value, dict):
            result[side] = VelocityBC(value["kind"], tuple(float(v) for v in value.get("value") or ()) or None)
        else:
            result[side] = VelocityBC(value)
    return result


def temperature_bcs_from_config(section: dict, gdim: int) -> dict[str, TemperatureBC]:
    """Temperature conditions per side of the ``boundary.temperature`` section."""
    result = {}
    for side in side_names(gdim):
        value = section[side]
        if value is None or value == "insulating":
            result[side] = TemperatureBC("insulating")
        else:
            result[side] = TemperatureBC("dirichlet", float(value["dirichlet"]))
    return result


class Simulation:
    """A convection run on one communicator (collective construction and run).

    Args:
        config: A resolved configuration (:func:`convection.config.load_config`).
        comm: The communicator.
    """

    def __init__(self, config: dict[str, Any], /, *, comm: MPI.Comm = MPI.COMM_WORLD) -> None:
        self.config = config
        self.comm = comm
        self.output_dir = Path(config["output"]["directory"])
        self.spec = BoxSpec.from_config(config["mesh"])
        gdim = self.spec.gdim
        physics = config["physics"]
        visc = physics["viscosity"]
        law = ViscosityLaw(
            material_viscosities=tuple(visc["material_viscosities"]) if visc["material_viscosities"] else None,
            mixing=visc["mixing"], temperature_law=visc["temperature_law"], gamma=visc["gamma"],
        )
        self.approximation = BoussinesqApproximation(Ra=physics["Ra"], Rb=physics["Rb"], H=physics["H"], viscosity=law)
        self.velocity_bcs = velocity_bcs_from_config(config["boundary"]["velocity"], gdim)
        self.temperature_bcs = temperature_bcs_from_config(config["boundary"]["temperature"], gdim)
        constants = expression_constants(config)
        self.initial_temperature = Expression(config["initial"]["temperature"], constants=constants, gdim=gdim)
        text = config["initial"]["composition"]
        self.initial_composition = Expression(text, constants=constants, gdim=gdim) if text is not None else None

        self.adaptivity = AdaptivityParameters.from_config(config["adaptivity"]) if config["adaptivity"]["enabled"] else None
        base = create_box_mesh(comm, self.spec)
        balancing = config["balance"]["strategy"] != "none"
        self.hierarchy = MeshHierarchy(base) if self.adaptivity or balancing else None
        mesh = self.hierarchy.uniform(self.adaptivity.min_level) if self.adaptivity else base
        self._build(mesh)
        self._set_initial_fields()
        if self.adaptivity:
            rounds = config["adaptivity"]["initial_steps"]
            if rounds is None:
                rounds = self.adaptivity.max_level - self.adaptivity.min_level
            for _ in range(rounds):
                self.adapt(initial=True)
        self.particles: ParticleComposition | None = None
        if config["composition"]["source"] == "particles":
            assert self.initial_composition is not None  # load_config checks it
            pcfg = config["particles"]
            self.particles = ParticleComposition(
                self.mesh, self.initial_composition, generator=pcfg["generator"], integrator=pcfg["integrator"],
                interpolator=pcfg["interpolator"], degree=config["composition"]["degree"],
            )
            self.composition = self.particles.field
        self._u_previous: dolfinx.fem.Function | None = None
        self._entrainment_form: tuple | None = None
        self._initial_material_volume: float | None = None
        self.t = 0.0
        self.step = 0
        self._last_dt = 0.0

    # ------------------------------------------------------------------ setup
    def _build(self, mesh: dolfinx.mesh.Mesh) -> None:
        cfg = self.config
        self.mesh = mesh
        self.stokes = StokesSolver(
            mesh, self.approximation, bcs=self.velocity_bcs, degree=cfg["stokes"]["degree"],
            solver=cfg["stokes"]["solver"], petsc_options=cfg["stokes"]["petsc_options"],
        )
        self.energy = TransportSolver(
            mesh, self.approximation, bcs=self.temperature_bcs, degree=cfg["energy"]["degree"],
            stabilisation=cfg["energy"]["stabilisation"],
        )
        self.diagnostics = RunDiagnostics(self.stokes.u, self.energy, side="top",
                                          nusselt=cfg["energy"]["enabled"])
        self.composition: dolfinx.fem.Function | None = None
        self.composition_solver: TransportSolver | None = None
        if self.initial_composition is not None:
            degree = cfg["composition"]["degree"]
            if cfg["composition"]["source"] == "field":  # advected like T, without diffusion or heating
                self.composition_solver = TransportSolver(
                    mesh, self.approximation, bcs={}, degree=degree, stabilisation=cfg["energy"]["stabilisation"],
                    diffusivity=0.0, heating=False, name="composition",
                )
                self.composition = self.composition_solver.T
            else:
                space = dolfinx.fem.FunctionSpace(mesh, ("DG", 0) if degree == 0 else ("Lagrange", degree))
                self.composition = dolfinx.fem.Function(space, name="composition")

    def _set_initial_fields(self) -> None:
        self.energy.set_initial(self.initial_temperature)
        if self.composition_solver is not None:
            self.composition_solver.set_initial(self.initial_composition)
        elif self.composition is not None and self.initial_composition is not None:
            self.composition.interpolate(self.initial_composition)
            self.composition.x.scatter_forward()

    @property
    def num_cells(self) -> int:
        return int(self.mesh.topology.index_map(self.mesh.topology.dim).size_global)

    # ------------------------------------------------------------------ adaptivity
    def adapt(self, *, initial: bool = False) -> tuple[int, int]:
        """Refine/coarsen once and carry the fields to the new mesh. Returns (cells before, after).

        With ``initial=True`` the fields on the new mesh are set from the initial conditions
        instead of being transferred (used to resolve the initial state). Collective.
        """
        assert self.hierarchy is not None and self.adaptivity is not None
        fields = []
        if "temperature" in self.config["adaptivity"]["fields"]:
            fields.append(self.energy.T)
        if "composition" in self.config["adaptivity"]["fields"] and self.composition is not None:
            fields.append(self.composition)
        before = self.num_cells
        indicator = kelly_indicator(fields or [self.energy.T])
        wanted = wanted_levels(indicator, self.hierarchy.levels(self.mesh), self.adaptivity, self.comm)
        new_mesh = self.hierarchy.rebuild(self.mesh, wanted)
        old = self._solvers()
        self._build(new_mesh)
        if initial:
            self._set_initial_fields()
        else:
            self._carry_fields(old)
        old.destroy()
        return before, self.num_cells

    def _solvers(self) -> _Solvers:
        return _Solvers(self.stokes, self.energy, self.composition, self.composition_solver)

    def _carry_fields(self, old: _Solvers) -> None:
        """Carry velocity, pressure, temperature (with history), composition and particles from the
        solvers of the previous mesh to the current one (collective)."""
        evaluator = PointEvaluator(old.stokes.mesh)

        def transfer(src: dolfinx.fem.Function, dst: dolfinx.fem.Function) -> None:
            transfer_function(src, dst, evaluator=evaluator)

        self.stokes.transfer_from(old.stokes, transfer)
        self.energy.transfer_from(old.energy, transfer)
        if self._u_previous is not None:
            u_previous = dolfinx.fem.Function(self.stokes.u.function_space)
            transfer(self._u_previous, u_previous)
            self._u_previous = u_previous
        if getattr(self, "particles", None) is not None:
            self.particles.move_to_mesh(self.mesh)
            self.composition = self.particles.field
        elif self.composition_solver is not None and old.composition_solver is not None:
            self.composition_solver.transfer_from(old.composition_solver, transfer)
        elif old.composition is not None and self.composition is not None:
            transfer(old.composition, self.composition)

    # ------------------------------------------------------------------ load balancing
    def _rank_loads(self) -> RankLoads:
        """Owned cells, particles and load 1 + W n_particles summed per rank (collective)."""
        owned = self.mesh.topology.index_map(self.mesh.topology.dim).size_local
        particles = self.particles.swarm.num_particles if self.particles else 0
        load = owned + self.config["balance"]["particle_weight"] * particles
        gathered = self.comm.allgather((owned, particles, load))
        return RankLoads(*(np.array(column) for column in zip(*gathered)))

    def _balance_due(self) -> bool:
        bcfg = self.config["balance"]
        if bcfg["strategy"] == "none" or self.comm.size == 1 or self.step % bcfg["every"] != 0:
            return False
        if bcfg["strategy"] == "every":
            return True
        return self._rank_loads().load_imbalance > bcfg["threshold"]

    def rebalance(self) -> tuple[RankLoads, RankLoads]:
        """Repartition the mesh with cell loads 1 + W n_particles(K) and move cells, fields and
        particles with it (collective). The mesh itself does not change: the base mesh and the
        current mesh are redistributed together
        (:meth:`convection.adaptivity.MeshHierarchy.repartition`). Returns the loads before and after.
        """
        assert self.hierarchy is not None
        before = self._rank_loads()
        bcfg = self.config["balance"]
        if self.particles is not None:
            particles = self.particles.swarm.particles_per_cell().astype(np.float64)
        else:
            particles = np.zeros(int(before.cells[self.comm.rank]))
        new_mesh = self.hierarchy.repartition(self.mesh, particles, particle_weight=bcfg["particle_weight"],
                                              method=bcfg["method"])
        old = self._solvers()
        self._build(new_mesh)
        self._carry_fields(old)
        old.destroy()
        return before, self._rank_loads()

    # ------------------------------------------------------------------ time loop
    def _diagnostics(self) -> dict[str, float]:
        d = self.diagnostics.compute()
        return {"vrms": d.vrms, "nusselt": d.nusselt, "T_mean": d.temperature.mean,
                "T_min": d.temperature.min, "T_max": d.temperature.max}

    def _timestep(self) -> float:
        tcfg = self.config["time"]
        dt = cfl_timestep(self.stokes.u, tcfg["cfl"], dt_max=tcfg["dt_max"])
        if not np.isfinite(dt) or dt <= 0.0:
            dt = tcfg["dt_initial"] or tcfg["dt_max"] or 0.0
            if dt <= 0.0:
                raise RuntimeError("the velocity is zero and neither time.dt_initial nor time.dt_max is set")
        return min(dt, tcfg["end"] - self.t)

    def _material_volume_above(self, height: float | None) -> float:
        """Volume of the configured material above ``height`` (everywhere for None; collective)."""
        C = self.composition
        assert C is not None
        z = ufl.SpatialCoordinate(self.mesh)[self.mesh.geometry.dim - 1]
        amount = C if self.config["diagnostics"]["entrainment_material"] == "dense" else 1.0 - C
        key = (id(C), height)
        if self._entrainment_form is None or self._entrainment_form[0] != key:
            integrand = amount if height is None else ufl.conditional(ufl.gt(z, height), amount, 0.0)
            form = dolfinx.fem.form(integrand * ufl.dx)
            self._entrainment_form = (key, form, C)
        return self.comm.allreduce(dolfinx.fem.assemble_scalar(self._entrainment_form[1]), op=MPI.SUM)

    def _entrainment(self) -> float:
        """Fraction of the configured material's initial volume that lies above the entrainment
        height, from the composition field (NaN when not configured)."""
        dcfg = self.config["diagnostics"]
        if dcfg["entrainment_material"] is None or self.composition is None:
            return float("nan")
        if self._initial_material_volume is None:
            self._initial_material_volume = self._material_volume_above(None)
        return self._material_volume_above(dcfg["entrainment_height"]) / self._initial_material_volume

    def _imbalance(self) -> dict[str, float]:
        """Load imbalance max/mean over ranks of owned cells and of particles (1 = balanced)."""
        loads = self._rank_loads()
        return {"cell_imbalance": loads.cell_imbalance, "particle_imbalance": loads.particle_imbalance}

    def _velocity_at_step_end(self, dt: float) -> dolfinx.fem.Function:
        """u* = (1 + w) u^n - w u^{n-1} (w = dt / previous dt), or u^n on the first step; then
        remembers u^n as the previous velocity."""
        u = self.stokes.u
        if self._u_previous is None or self._last_dt <= 0.0:
            u_end = u
        else:
            w = dt / self._last_dt
            u_end = dolfinx.fem.Function(u.function_space)
            u_end.x.array[:] = (1.0 + w) * u.x.array - w * self._u_previous.x.array
        if self._u_previous is None or self._u_previous.function_space is not u.function_space:
            self._u_previous = dolfinx.fem.Function(u.function_space)
        self._u_previous.x.array[:] = u.x.array
        return u_end

    def _fields(self) -> dict[str, dolfinx.fem.Function]:
        out = {"temperature": self.energy.T, "velocity": self.stokes.u, "pressure": self.stokes.p}
        if self.composition is not None:
            out["composition"] = self.composition
        return out

    def run(self, *, should_stop: Callable[[], bool] = lambda: False) -> RunSummary:
        """Run to ``time.end`` (or max_steps, steady state, or a stop request). Collective.

        Args:
            should_stop: Polled every step on every rank (e.g. a signal flag); the run stops when it
                is True on any rank, with the statistics flushed.
        """
        cfg = self.config
        tcfg, ocfg = cfg["time"], cfg["output"]
        rank0 = self.comm.rank == 0
        if rank0:
            self.output_dir.mkdir(parents=True, exist_ok=True)
            (self.output_dir / "config.yaml").write_text(dump_config(cfg))
        self.comm.barrier()
        writer = StatisticsWriter(self.output_dir / "statistics.csv", STATISTICS_COLUMNS, comm=self.comm)
        fields = FieldOutput(self.output_dir)
        progress = Progress(tcfg["end"], mode=ocfg["progress"], every=ocfg["progress_every"], enabled=rank0)
        start = time.monotonic()
        history: list[tuple[float, float]] = []
        reason = "end time"
        balance_log = BalanceLog(self.output_dir / "balance.csv", comm=self.comm)
        if self._balance_due():
            self._log_rebalance(balance_log, progress)
        result = self.stokes.solve(self.energy.T, self.composition)
        row: dict[str, Any] = {}
        written_step = -1
        try:
            while True:
                diag = self._diagnostics()
                row = {"step": self.step, "time": self.t, "dt": 0.0 if self.step == 0 else self._last_dt,
                       "cells": self.num_cells, "stokes_iterations": result.iterations,
                       "n_particles": self.particles.num_particles if self.particles else 0,
                       "n_lost": self.particles.lost if self.particles else 0,
                       **self._imbalance(), "entrainment": self._entrainment(),
                       "wall_time": time.monotonic() - start, **diag}
                writer.write(row)
                progress.update(self.step, self.t, row["dt"], diag["vrms"], extra=f"Nu={diag['nusselt']:.5g}")
                if ocfg["fields_every"] and self.step % ocfg["fields_every"] == 0:
                    fields.write(self._fields(), self.t)
                    written_step = self.step
                history.append((diag["vrms"], diag["nusselt"]))
                if self.t >= tcfg["end"] * (1.0 - 1e-12):
                    break
                if tcfg["max_steps"] is not None and self.step >= tcfg["max_steps"]:
                    reason = "max steps"
                    break
                if self._steady(history):
                    reason = "steady state"
                    break
                if self.comm.allreduce(bool(should_stop()), op=MPI.LOR):
                    reason = "stopped by signal"
                    break
                dt = self._timestep()
                if self.config["energy"]["enabled"]:
                    self.energy.step(self.stokes.u, dt)
                if self.composition_solver is not None:
                    self.composition_solver.step(self.stokes.u, dt)
                if self.particles is not None:
                    self.particles.advect(self.stokes.u, self._velocity_at_step_end(dt), dt)
                self.t += dt
                self.step += 1
                self._last_dt = dt
                if self.adaptivity and self.step % self.adaptivity.every == 0:
                    before, after = self.adapt()
                    progress.message(f"adapted mesh at step {self.step}: {before} -> {after} cells")
                if self._balance_due():
                    self._log_rebalance(balance_log, progress)
                result = self.stokes.solve(self.energy.T, self.composition)
        finally:
            writer.close()
            balance_log.close()
            progress.close()
            # The solvers are done; free them now, on every rank together, not in the garbage collector.
            self._solvers().destroy()
        if written_step != self.step:
            fields.write(self._fields(), self.t)
        fields.close()
        summary = RunSummary(self.step, self.t, float(row.get("vrms", np.nan)), float(row.get("nusselt", np.nan)),
                             self.num_cells, time.monotonic() - start, reason)
        if rank0:
            (self.output_dir / "summary.json").write_text(json.dumps(summary.as_dict(), indent=2) + "\n")
            progress.message(f"finished ({reason}): step {summary.steps}, t={summary.time:.6g}, "
                             f"vrms={summary.vrms:.6g}, Nu={summary.nusselt:.6g}, {summary.cells} cells, "
                             f"{summary.wall_time:.1f} s")
        return summary


    def _log_rebalance(self, log: BalanceLog, progress: Progress) -> None:
        before, after = self.rebalance()
        log.write(self.step, before, after)
        progress.message(
            f"rebalanced at step {self.step}: cells per rank {before.cells.tolist()} -> {after.cells.tolist()}, "
            f"particles per rank {before.particles.tolist()} -> {after.particles.tolist()} "
            f"(imbalance cells {before.cell_imbalance:.3f} -> {after.cell_imbalance:.3f}, "
            f"particles {before.particle_imbalance:.3f} -> {after.particle_imbalance:.3f})"
        )

    def _steady(self, history: list[tuple[float, float]]) -> bool:
        tol = self.config["time"]["steady_state_tolerance"]
        window = self.config["time"]["steady_state_window"]
        if tol is None or len(history) <= window:
            return False
        recent = np.array(history[-window - 1:])
        scale = np.maximum(np.abs(recent[-1]), 1e-300)
        change = np.max(np.abs(recent - recent[-1]), axis=0) / scale
        return bool(np.all(change < tol))
