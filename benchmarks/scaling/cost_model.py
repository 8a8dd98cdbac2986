"""Cost model on paper: project the seed paper's section 3 scaling tests (3D circular flow, RK2)
from constants measured on this machine (see ``cost_model.md`` for each constant's command) to
12 ... 12 288 ranks.

    python -m benchmarks.scaling.cost_model                  # tables (markdown) + cost_model.png
    python -m benchmarks.scaling.cost_model --alpha 5e-6     # another network latency assumption
    python -m benchmarks.scaling.cost_model --strong-cells 3145728 --ppc 40 --weak-cells 24576
    python -m benchmarks.scaling.cost_model --thick-layer    # the 3D thick layer with the multigrid Stokes solver

Nothing here runs MPI: it evaluates formulas. Two designs are projected side by side:
``today`` (the code as of this commit) and ``fixed`` (the same code with the O(P) paths replaced by
O(neighbours) or tree-collective versions, see cost_model.md). Times are per rank and assume
perfect load balance (imbalance factor 1); measured constants are CPU-time based where the
machine was shared (see the .md).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, field
from pathlib import Path

from benchmarks.harness import Benchmark

BENCHMARK = Benchmark(__doc__)
RANKS = [12, 24, 48, 96, 192, 384, 768, 1536, 3072, 6144, 12288]


@dataclass
class Constants:
    # --- particle work per particle and time step (3D, P2 velocity, RK2: 2 evaluations, 2
    #     relocations, 1 sort per step); measure_constants.py advect3d 12 20 10 rk2, CPU-scaled
    eval_ns: float = 100.0
    reloc_ns: float = 85.0
    sort_ns: float = 27.0
    step_fixed_s: float = 1.0e-3       # per-step Python overhead of Advector.step besides migration
                                       # (performance/log/NOTES.md: ~3 ms/step fixed incl. ~2 ms interpolation)
    # --- migration (per call; RK2 migrates once per stage = 2 calls per step)
    mig_fixed_s: float = 0.6e-3        # CPU, 0 particles sent (measure_constants.py migration)
    mig_per_particle_s: float = 2.2e-6  # CPU per particle received, 3D run incl. neighbour offers
    mig_unlocated_share: float = 0.17  # share of crossing particles that take the offer path (3D)
    crossing_coeff: float = 0.27       # crossing fraction per stage = coeff / m, m = (cells/6)^(1/3)
    # --- O(P) code paths (measure_constants.py loops, fake P on one process), seconds per unit
    decide_loop_per_rank_s: float = 1.2e-6    # Migrator._decide: for r in range(P), every migration
                                              # (real method at fake P: 15 ms at 12 288; the bare
                                              # expression 25-45 ms)
    box_candidates_per_rank_s: float = 36e-9  # Migrator._box_candidates with m = 0 (per rank of P)
    box_candidates_per_pair_s: float = 60e-9  # per (unlocated particle, rank) pair (real method:
                                              # 117 ms at m = 160, P = 12 288)
    rankloads_per_rank_s: float = 0.17e-6     # RankLoads zip over the allgathered P tuples
    quantile_per_value_s: float = 68e-9       # np.quantile over the allgathered indicator
    keyorder_per_pair_s: float = 11e-9        # key_order_offsets: P masks over m keys
    pickle_per_tuple_s: float = 30e-6         # pickled alltoall: per (keys, counts, index) tuple
    # --- communication (alpha: ASSUMED network latency; beta: per-rank bandwidth, measured
    #     intra-node 2.2-3.6 GB/s, used as the network share per rank: an assumption)
    alpha_s: float = 2e-6
    beta_Bps: float = 2e9
    py_allreduce_s: float = 370e-6     # mpi4py pickled allreduce of a 5-int64 numpy array (median of
                                       # the best loops seen on 2 ranks: 88 us ... 1.2 ms)
    py_allreduce_scalar_s: float = 7e-6  # pickled allreduce of one Python int (best seen)
    buffer_allreduce_s: float = 5e-6   # comm.Allreduce of 5 int64 buffers (means 5.4 / 7.4 us, best 2.9-4.0 us)
    msg_post_s: float = 1.4e-6         # Python Irecv+Isend pair posting (26 pairs to self: 37 us)
    neighbours: int = 26               # ASSUMED neighbours of a 3D subdomain (cubic blocks)
    # --- Stokes, 3D iterative (FGMRES + BoomerAMG), measure_constants.py stokes
    stokes_dof_iter_s: float = 1.0e-6  # wall 0.9-1.7 us/dof/iteration under load (assumed 1.0)
    stokes_iterations: int = 30        # measured 27-30 (warm start), assumed flat in h
    dofs_per_cell: float = 4.2         # P2-P1 on tetrahedra (derived; 4.85 measured at 10^3 x 6)
    amg_coarsening: float = 8.0        # ASSUMED coarsening factor per AMG level
    amg_exchanges_per_level: int = 4   # ASSUMED halo exchanges per level and V-cycle
    # --- adaptation (2D convection run, 1 rank, vankeken_1a, adapting every step)
    adapt_per_cell_s: float = 58e-6
    transfer_per_cell_s: float = 83e-6
    mesh_change_per_particle_s: float = 4e-6
    # --- rank-0 serial mesh rebuild (repartition): gather_cell_layout + create_mesh, 3D
    serial_mesh_per_cell_s: float = 35e-6
    bytes_per_cell_gather: int = 104   # 4 corners x 3 doubles + int64 canonical index
    bytes_per_particle_out: int = 52   # id 8 + position 24 + connectivity 8 + rank 4 + 1 property 8


@dataclass
class Scenario:
    name: str
    cells: list[float]
    particles: list[float]
    adapt_every: int = 0       # 0: no adaptation (the seed's circular-flow test has none: ASSUMED)
    repartition_every: int = 0
    output_every: int = 0
    stokes: bool = False
    convection_loop: bool = False
    extra: dict = field(default_factory=dict)


def log2c(p: int) -> int:
    return max(1, math.ceil(math.log2(p)))


def allreduce(c: Constants, p: int, python: float) -> float:
    """Tree allreduce: alpha log2 P + the Python/mpi4py overhead of the call."""
    return c.alpha_s * log2c(p) + python


def neighbour_round(c: Constants, nbytes: float) -> float:
    return c.alpha_s + c.neighbours * c.msg_post_s + nbytes / c.beta_Bps


def allgather(c: Constants, p: int, bytes_per_rank: float) -> float:
    """Allgather of O(P) data: alpha log2 P + P * bytes / beta (every rank receives everything)."""
    return c.alpha_s * log2c(p) + p * bytes_per_rank / c.beta_Bps


def phases(c: Constants, p: int, cells_total: float, particles_total: float, s: Scenario, design: str) -> dict:
    """Seconds per time step per rank, by phase."""
    cells = cells_total / p
    n = particles_total / p
    out: dict[str, float] = {}
    out["advect"] = n * c.eval_ns * 1e-9
    out["relocate"] = n * c.reloc_ns * 1e-9
    out["sort"] = n * c.sort_ns * 1e-9
    out["step overhead"] = c.step_fixed_s
    m_edge = max((cells / 6.0) ** (1.0 / 3.0), 1.0)
    crossing = min(1.0, c.crossing_coeff / m_edge) * n       # particles leaving this rank per stage
    unlocated = c.mig_unlocated_share * crossing
    nb = min(c.neighbours, p - 1)
    row_bytes = 8 * (2 + 3 + 3 + 3 + 1)                        # id, cell, x, xref, stage x0, 1 property
    per_mig_local = c.mig_fixed_s + crossing * c.mig_per_particle_s
    per_mig_comm = 2 * (c.alpha_s + nb * c.msg_post_s) + crossing * row_bytes / c.beta_Bps
    per_mig_comm += allreduce(c, p, c.py_allreduce_s if design == "today" else c.buffer_allreduce_s)
    if design == "today":
        per_mig_op = p * c.decide_loop_per_rank_s + p * c.box_candidates_per_rank_s \
            + unlocated * p * c.box_candidates_per_pair_s
    else:  # candidates from a tree of the P boxes; loops over neighbours only
        per_mig_op = unlocated * log2c(p) * 0.2e-6 + nb * 2e-6
    out["migration (local)"] = 2 * per_mig_local
    out["migration (latency+bw)"] = 2 * per_mig_comm
    out["migration O(P) Python"] = 2 * per_mig_op
    if s.stokes:
        dofs = c.dofs_per_cell * cells
        levels = max(1, math.ceil(math.log(max(c.dofs_per_cell * cells_total / 100.0, 2.0), c.amg_coarsening)))
        per_it = dofs * c.stokes_dof_iter_s
        per_it_comm = 2 * allreduce(c, p, 0.0) + levels * c.amg_exchanges_per_level * (c.alpha_s + nb * 0.2e-6)
        out["stokes"] = c.stokes_iterations * per_it
        out["stokes latency"] = c.stokes_iterations * per_it_comm
    if s.convection_loop:
        # per step: ~10 scalar allreduces (dt, stop, sent, population x3, interpolation x2, postprocessors)
        scalar = 10 * allreduce(c, p, c.py_allreduce_scalar_s)
        loads = allgather(c, p, 24) + p * c.rankloads_per_rank_s if design == "today" else allreduce(c, p, 20e-6)
        out["loop collectives"] = scalar + loads
    if s.adapt_every:
        local = cells * (c.adapt_per_cell_s + c.transfer_per_cell_s) + n * c.mesh_change_per_particle_s
        if design == "today":
            glob = allgather(c, p, 8 * cells) + cells_total * c.quantile_per_value_s + allgather(c, p, 48)
        else:  # distributed selection of the quantile (a few allreduces of histograms)
            glob = 20 * allreduce(c, p, 20e-6)
        out["adaptation (amortised)"] = (local + glob) / s.adapt_every
    if s.repartition_every:
        if design == "today":
            t = cells_total * c.serial_mesh_per_cell_s + cells_total * c.bytes_per_cell_gather / c.beta_Bps
        else:  # parallel graph/RCB partition + distributed redistribution: local work + log P rounds
            t = cells * c.serial_mesh_per_cell_s + 30 * allreduce(c, p, 20e-6)
        out["repartition (amortised)"] = t / s.repartition_every
    if s.output_every:
        nbytes = particles_total * c.bytes_per_particle_out
        if design == "today":  # serial h5py: gather everything to rank 0
            t = nbytes / c.beta_Bps
        else:  # parallel HDF5: every rank writes its slice (file system bandwidth not modelled)
            t = n * c.bytes_per_particle_out / c.beta_Bps + 3 * allreduce(c, p, 10e-6)
        out["particle output (amortised)"] = t / s.output_every
    return out


def project(c: Constants, s: Scenario, design: str) -> list[tuple[int, dict, float]]:
    rows = []
    for p, cells, parts in zip(RANKS, s.cells, s.particles):
        ph = phases(c, p, cells, parts, s, design)
        rows.append((p, ph, sum(ph.values())))
    return rows


def efficiency(rows: list[tuple[int, dict, float]], strong: bool) -> list[float]:
    p0, _, t0 = rows[0]
    if strong:
        return [t0 * p0 / (t * p) for p, _, t in rows]
    return [t0 / t for _, _, t in rows]


def fmt(t: float) -> str:
    if t >= 1.0:
        return f"{t:.2f} s"
    if t >= 1e-3:
        return f"{t * 1e3:.1f} ms"
    return f"{t * 1e6:.0f} µs"


def table(c: Constants, s: Scenario, design: str, strong: bool) -> str:
    rows = project(c, s, design)
    eff = efficiency(rows, strong)
    names = list(rows[0][1].keys())
    head = "| ranks | cells/rank | particles/rank | " + " | ".join(names) + " | total / step | efficiency |"
    sep = "|" + "---|" * (len(names) + 5)
    lines = [head, sep]
    for (p, ph, tot), e, cells, parts in zip(rows, eff, s.cells, s.particles):
        lines.append(f"| {p} | {cells / p:,.0f} | {parts / p:,.0f} | " + " | ".join(fmt(ph[k]) for k in names)
                     + f" | {fmt(tot)} | {e:.2f} |")
    return "\n".join(lines)


def gb(nbytes: float) -> str:
    if nbytes >= 1e9:
        return f"{nbytes / 1e9:.1f} GB"
    if nbytes >= 1e6:
        return f"{nbytes / 1e6:.1f} MB"
    return f"{nbytes / 1e3:.1f} kB"


@dataclass
class ThickLayer:
    """The seed's 3D thick layer (configs/thick_layer_3d.yaml) with ``stokes.solver: multigrid``:
    measured constants on 2 ranks (benchmarks/scaling/aspect_thick_layer*.md: the fifth sitting for
    16^3, the fourth for 32^3, both 2026-12-04; benchmarks/tackley_king for the steps)."""

    seconds_per_step_16: float = 77.0 / 95    # 16^3 to t = 0.002, best of 3, start-up included (fifth sitting)
    seconds_per_step_32: float = 1275.0 / 183  # 32^3 to t = 0.002, one run, start-up included (fourth sitting:
                                               # preconditioner set up every step, so an upper bound)
    rss_per_rank_32_bytes: float = 3082e6     # max RSS per rank at 32^3 on 2 ranks (fourth sitting)
    steps_to_end_n: int = 1422                # steps to t = 0.02 at CFL 1 on n^3 ...
    steps_n: int = 32                         # ... n (benchmarks/tackley_king, 32^3, 2026-12-05)
    end_time: float = 0.02                    # this project's end time (no end time is published with the seed's e)
    efficiency: float = 1.0                   # ASSUMED strong-scaling efficiency of the whole step ...
    min_unknowns_per_rank: int = 20_000       # ... down to this many Stokes unknowns per rank (ASSUMED; below: not projected)


def stokes_unknowns(n: int) -> int:
    """P2/P1 on n^3 cubes of 6 tetrahedra (= Q2/Q1 on n^3 hexahedra)."""
    return 3 * (2 * n + 1) ** 3 + (n + 1) ** 3


def thick_layer_table(t: ThickLayer, sizes: tuple[int, ...] = (32, 64, 128),
                      ranks: tuple[int, ...] = (2, 48, 192, 768, 3072)) -> str:
    """Hours to ``t.end_time`` and memory per rank of the thick layer at ``sizes`` on ``ranks`` ranks.

    Derived: the time per step on 2 ranks grows as unknowns^q with q fitted to 16^3 and 32^3; the
    steps to the end time grow as n (CFL: dt ~ h at the same velocities) from the 32^3 run; the
    time on N ranks is the 2-rank time times 2 / (N efficiency); memory per unknown as at 32^3."""
    u16, u32 = stokes_unknowns(16), stokes_unknowns(32)
    q = math.log(t.seconds_per_step_32 / t.seconds_per_step_16) / math.log(u32 / u16)
    lines = [f"Time per step on 2 ranks ~ unknowns^{q:.2f} (fitted to 16³ and 32³); steps to t = {t.end_time:g} "
             f"~ n ({t.steps_to_end_n} at {t.steps_n}³); parallel efficiency {t.efficiency:g} down to "
             f"{t.min_unknowns_per_rank:,} unknowns per rank (ASSUMED; '-': fewer).\n",
             "| mesh | Stokes unknowns | steps to t_end | s/step on 2 ranks | " + " | ".join(f"{p} ranks [h]" for p in ranks)
             + " | memory per rank on the fewest ranks that fit 4 GB |",
             "|---|---|---|---|" + "---|" * len(ranks) + "---|"]
    for n in sizes:
        u = stokes_unknowns(n)
        per_step = t.seconds_per_step_32 * (u / u32) ** q
        steps = round(t.steps_to_end_n * n / t.steps_n)
        hours = [steps * per_step * 2 / (p * t.efficiency) / 3600 if u / p >= t.min_unknowns_per_rank else None
                 for p in ranks]
        total_bytes = 2 * t.rss_per_rank_32_bytes * u / u32
        fits = next((p for p in ranks if total_bytes / p <= 4e9), None)
        memory = f"{total_bytes / fits / 1e9:.1f} GB on {fits}" if fits else f"{total_bytes / 1e9:.0f} GB in all"
        lines.append(f"| {n}³ | {u:,} | {steps} | {per_step:.1f} | "
                     + " | ".join("-" if h is None else f"{h:.2f}" for h in hours)
                     + f" | {memory} |")
    return "\n".join(lines)


def main() -> None:
    ap = BENCHMARK.parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--thick-layer", action="store_true",
                    help="only the projection of the 3D thick layer with the multigrid Stokes solver")
    ap.add_argument("--strong-cells", type=float, default=3 * 2 ** 20, help="ASSUMED strong-scaling cells")
    ap.add_argument("--weak-cells", type=float, default=24576, help="ASSUMED weak-scaling cells per rank")
    ap.add_argument("--ppc", type=float, default=40, help="ASSUMED particles per cell")
    ap.add_argument("--alpha", type=float, default=2e-6, help="ASSUMED network latency per message hop, s")
    ap.add_argument("--beta", type=float, default=2e9, help="per-rank bandwidth, bytes/s")
    ap.add_argument("--png", type=Path, default=Path(__file__).with_name("cost_model.png"))
    args = ap.parse_args()
    if args.thick_layer:
        print(thick_layer_table(ThickLayer()))
        return
    c = Constants(alpha_s=args.alpha, beta_Bps=args.beta)
    strong = Scenario("strong", [args.strong_cells] * len(RANKS), [args.strong_cells * args.ppc] * len(RANKS))
    weak = Scenario("weak", [args.weak_cells * p for p in RANKS], [args.weak_cells * args.ppc * p for p in RANKS])
    print(f"# Projection (alpha = {args.alpha * 1e6:.1f} µs, beta = {args.beta / 1e9:.1f} GB/s)\n")
    results = {}
    variants = {
        "particles": lambda sc: sc,
        "particles + Stokes": lambda sc: Scenario(sc.name, sc.cells, sc.particles, stokes=True),
        "coupled loop": lambda sc: Scenario(sc.name, sc.cells, sc.particles, stokes=True, adapt_every=10,
                                            repartition_every=10, output_every=50, convection_loop=True),
    }
    for s, is_strong in ((strong, True), (weak, False)):
        for design in ("today", "fixed"):
            print(f"## {s.name} scaling, time per step by phase, coupled loop, design: {design}\n")
            print(table(c, variants["coupled loop"](s), design, is_strong) + "\n")
            for vname, make in variants.items():
                results[(s.name, design, vname)] = efficiency(project(c, make(s), design), is_strong)
    for s in (strong, weak):
        print(f"## {s.name} scaling: parallel efficiency (vs 12 ranks)\n")
        keys = [(d, v) for v in variants for d in ("today", "fixed")]
        print("| ranks | " + " | ".join(f"{v}, {d}" for d, v in keys) + " |")
        print("|---|" + "---|" * len(keys))
        for i, p in enumerate(RANKS):
            print(f"| {p} | " + " | ".join(f"{results[(s.name, d, v)][i]:.2f}" for d, v in keys) + " |")
        print()
    print("## Memory of the O(global) structures today (bytes per rank / on rank 0)\n")
    print("| study | ranks | global cells | global particles | indicator allgather, every rank | "
          "repartition gather, rank 0 | particle output gather, rank 0 | owned boxes, every rank |")
    print("|---|---|---|---|---|---|---|---|")
    for s in (strong, weak):
        for i, p in enumerate(RANKS):
            if p not in (12, 768, 12288):
                continue
            cg, pg = s.cells[i], s.particles[i]
            print(f"| {s.name} | {p} | {cg:,.0f} | {pg:,.0f} | {gb(8 * cg)} | {gb(c.bytes_per_cell_gather * cg)} | "
                  f"{gb(c.bytes_per_particle_out * pg)} | {gb(48 * p)} |")
    print()
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    for ax, name in zip(axes, ("strong", "weak")):
        markers = {"particles": "o", "particles + Stokes": "^", "coupled loop": "s"}
        for (sn, design, kind), eff in results.items():
            if sn != name:
                continue
            style = "-" if design == "today" else "--"
            ax.semilogx(RANKS, eff, style, marker=markers[kind], label=f"{kind}, {design}")
        ax.set_xticks(RANKS)
        ax.set_xticklabels([str(r) for r in RANKS], rotation=60, fontsize=8)
        ax.set_ylim(0, 1.1)
        ax.grid(True, alpha=0.3)
        ax.set_xlabel("ranks")
        ax.set_title(f"{name} scaling (projected)")
    axes[0].set_ylabel("parallel efficiency (vs 12 ranks)")
    axes[1].legend(fontsize=8, loc="lower left")
    fig.suptitle(f"cost model: alpha {args.alpha * 1e6:.0f} µs, beta {args.beta / 1e9:.0f} GB/s; "
                 f"strong {args.strong_cells:,.0f} cells, weak {args.weak_cells:,.0f} cells/rank, {args.ppc:g} particles/cell",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(args.png, dpi=110)
    print(f"wrote {args.png}")


if __name__ == "__main__":
    main()
