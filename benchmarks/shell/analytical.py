"""Stokes in an annulus / spherical shell against the analytical solutions of Kramer, Davies & Wilson (2021).

The solutions come from the PyPI package ``assess`` (``pip install assess``). They solve, with
unit viscosity, ``-div(2 eps(u)) + grad p = -g rho' r_hat``, ``div u = 0`` between the radii
``R_m = 1.22`` and ``R_p = 2.22``, with

- ``smooth_*``: ``rho' = (r / R_p)^k cos(n phi)`` (2D) or ``(r / R_p)^k Y_lm(theta, phi)`` (3D);
- ``delta_*``: ``rho' = delta(r - r') cos(n phi)`` (or ``Y_lm``), a force on the surface
  ``r' = 1.72`` (the mesh conforms to it; the pressure jumps there);

and free slip (``*_free_slip``) or zero slip (``*_zero_slip``) on both surfaces. The model's
buoyancy ``Ra T e_up`` with ``e_up = x / |x|`` (radial gravity) and ``Ra = 1`` is this forcing for
``T = -g rho'``; the surface force of the delta cases is added to the right-hand side as an
interior-facet integral. Free slip is the solver's Nitsche condition; its rigid-rotation null
space is removed, as is the pressure mean (the analytical pressures have zero mean).

Errors are relative L2 norms, ``||u_h - u|| / ||u||``, with the analytical fields interpolated into
P(k+2) velocity / P(k+1) pressure spaces on the same (curved) mesh (discontinuous pressure for the
delta cases, each cell taking its side of ``r'``). Level ``i`` meshes with gmsh cell size
``resolution / 2^i``; orders are least-squares slopes of ``log(error)`` against ``log(h)`` with
``h = (|Omega| / cells)^(1/dim)``.

Usage (ranks via mpirun; prints one JSON document on rank 0)::

    python -m benchmarks.shell.analytical --kind smooth_free_slip --dim 2 --n 2 --k 3 --levels 0 1 2 3
    mpirun -n 2 python -m benchmarks.shell.analytical --kind smooth_zero_slip --dim 2 --levels 0 1 2
    python -m benchmarks.shell.analytical --kind smooth_free_slip --dim 3 --n 2 --m 1 --levels 0 1 --resolution 0.5
    python -m benchmarks.shell.analytical --kind smooth_free_slip --adaptive 3 --resolution 0.4

``--adaptive ROUNDS``: the meshes of a :class:`convection.adapt.hierarchy.MeshHierarchy` with the shell
manifold (:mod:`fembase.manifold`; for the delta cases it also keeps the surface ``r'`` the force
acts on): the straight gmsh mesh of cell size ``resolution`` curved, solved, then ``ROUNDS`` times
refined where the Kelly indicator of the velocity is largest (``--refine-fraction`` of the cells up
one level) and solved again; ``levels`` lists the rounds. ``--hierarchy`` instead refines that
base uniformly ``--levels`` times (the adaptive code path's meshes, uniformly refined).
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import ufl
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from benchmarks.harness import Benchmark
from convection.adapt.adaptivity import AdaptivitySettings, kelly_indicator, wanted_levels

from convection.adapt.hierarchy import MeshHierarchy
from convection.physics.approximation import BoussinesqApproximation
from convection.geometry.boundary import VelocityBC
from convection.geometry.shell import ShellSpec, create_shell_mesh, shell_domain
from convection.solvers.stokes.solver import StokesSolver
from fembase.dolfinx_compat import atan2, function_space, interpolate_on_cells
from fembase.manifold import ShellManifold

BENCHMARK = Benchmark(__doc__)
KINDS = ("smooth_free_slip", "smooth_zero_slip", "delta_free_slip", "delta_zero_slip")
R_INNER, R_OUTER, R_DELTA = 1.22, 2.22, 1.72


@dataclass(frozen=True)
class Case:
    """One analytical case.

    Attributes:
        kind: one of :data:`KINDS`.
        dim: 2 (annulus) or 3 (spherical shell).
        n: wave number (2D) or spherical-harmonic degree l (3D).
        m: spherical-harmonic order (3D only).
        k: radial power of the smooth forcing.
    """

    kind: str
    dim: int = 2
    n: int = 2
    m: int = 1
    k: int = 3

    @property
    def smooth(self) -> bool:
        return self.kind.startswith("smooth")

    @property
    def free_slip(self) -> bool:
        return self.kind.endswith("free_slip")

    def solutions(self) -> list:
        """The ``assess`` solution(s): one for smooth forcing; (below r', above r') for delta."""
        import assess

        shape = "Cylindrical" if self.dim == 2 else "Spherical"
        forcing = "Smooth" if self.smooth else "Delta"
        slip = "FreeSlip" if self.free_slip else "ZeroSlip"
        cls = getattr(assess, f"{shape}StokesSolution{forcing}{slip}")
        harmonic = (self.n,) if self.dim == 2 else (self.n, self.m)
        radii = {"Rp": R_OUTER, "Rm": R_INNER}
        if self.smooth:
            return [cls(*harmonic, self.k, **radii)]
        return [cls(*harmonic, sign, rp=R_DELTA, **radii) for sign in (-1, +1)]


def _pointwise(function, components: int):
    """DOLFINx interpolation callable (x shape=(3, N)) from a point function of one point."""
    def evaluate(x: np.ndarray) -> np.ndarray:
        values = np.array([function(x[:, i]) for i in range(x.shape[1])], dtype=np.float64)
        return values.T.reshape(components, -1) if components > 1 else values.reshape(-1)
    return evaluate


def _angular(case: Case, x: ufl.SpatialCoordinate):
    """UFL ``cos(n phi)`` (2D) or the real spherical harmonic ``Y_lm(theta, phi)`` (3D) as assess defines it."""
    if case.dim == 2:
        return ufl.cos(case.n * atan2(x[1], x[0]))
    return None


def _interpolated_density(case: Case, V: dolfinx.fem.FunctionSpace, solution) -> dolfinx.fem.Function:
    """The smooth forcing density ``rho'`` interpolated into ``V`` (3D: Y_lm has no closed UFL form here)."""
    f = dolfinx.fem.Function(V)
    f.interpolate(_pointwise(solution.delta_rho_cartesian, 1))
    return f


def _delta_density(case: Case, V: dolfinx.fem.FunctionSpace) -> dolfinx.fem.Function:
    """The angular factor of the delta forcing, ``cos(n phi)`` or ``Y_lm``, interpolated into ``V``."""
    f = dolfinx.fem.Function(V)
    if case.dim == 2:
        f.interpolate(lambda x: np.cos(case.n * np.arctan2(x[1], x[0])))
    else:
        from assess.spherical import Y_cartesian

        f.interpolate(_pointwise(lambda p: Y_cartesian(case.n, case.m, p), 1))
    return f


@dataclass
class LevelResult:
    """Errors of one mesh level."""

    level: int
    resolution: float
    cells: int
    h: float
    dofs: int
    velocity_error: float
    pressure_error: float
    divergence: float
    solve_seconds: float


def _interface_measure(mesh: dolfinx.mesh.Mesh):
    """``dS`` on the interior facets on the circle/sphere r = r' (vertices within 1e-8 of it)."""
    fdim = mesh.topology.dim - 1
    gdim = mesh.geometry.dim
    facets = dolfinx.mesh.locate_entities(
        mesh, fdim, lambda x: np.abs(np.sqrt(np.sum(x[:gdim] ** 2, axis=0)) - R_DELTA) <= 1e-8 * R_OUTER)
    facets = np.sort(facets).astype(np.int32)
    tags = dolfinx.mesh.meshtags(mesh, fdim, facets, np.ones(facets.shape, dtype=np.int32))
    return ufl.Measure("dS", domain=mesh, subdomain_data=tags)(1)


def run_level(case: Case, level: int, resolution: float, *, comm: MPI.Comm, degree: int = 2,
              geometry_degree: int = 2, solver: str = "direct", nitsche_penalty: float | None = None,
              petsc_options: dict | None = None, mesh_dir: Path | None = None) -> LevelResult:
    """Solve one mesh level and measure the errors (collective). With ``mesh_dir``, the level's
    gmsh mesh is read from there if it was written before, else written there."""
    h_target = resolution / 2**level
    spec = ShellSpec(case.dim, R_INNER, R_OUTER, resolution=h_target, geometry_degree=geometry_degree,
                     interfaces=() if case.smooth else (R_DELTA,))
    msh = None
    if mesh_dir is not None:
        msh = mesh_dir / (f"shell{case.dim}d_{'smooth' if case.smooth else 'delta'}_h{h_target:g}"
                          f"_g{geometry_degree}.msh")
        if comm.rank == 0:
            mesh_dir.mkdir(parents=True, exist_ok=True)
    mesh = create_shell_mesh(comm, spec, msh_file=msh)
    return solve_on(case, mesh, level, h_target, comm=comm, degree=degree, solver=solver,
                    nitsche_penalty=nitsche_penalty, petsc_options=petsc_options)[0]


def solve_on(case: Case, mesh: dolfinx.mesh.Mesh, level: int, h_target: float, *, comm: MPI.Comm, degree: int = 2,
             solver: str = "direct", nitsche_penalty: float | None = None, petsc_options: dict | None = None,
             indicator: bool = False) -> tuple[LevelResult, np.ndarray | None]:
    """Solve on ``mesh`` and measure the errors (collective); with ``indicator``, also the Kelly
    indicator of the velocity per owned cell (:func:`convection.adapt.adaptivity.kelly_indicator`)."""
    solutions = case.solutions()
    kind = "free_slip" if case.free_slip else "no_slip"
    bcs = {"inner": VelocityBC(kind), "outer": VelocityBC(kind)}
    domain = shell_domain(ShellSpec(case.dim, R_INNER, R_OUTER))  # the boundaries are found on the mesh
    approximation = BoussinesqApproximation(Ra=1.0, gravity=domain.gravity)
    stokes = StokesSolver(mesh, approximation, bcs=bcs, domain=domain, degree=degree, solver=solver,
                          nitsche_penalty=nitsche_penalty, petsc_options=petsc_options)
    x = ufl.SpatialCoordinate(mesh)
    if case.smooth:
        # rho' = (r / R_p)^k * angular; interpolated at degree k + 2 to keep the forcing error small.
        Vf = function_space(mesh, "Lagrange", degree + 2)
        T = -_interpolated_density(case, Vf, solutions[0])
    else:
        T = 0.0
    if not case.smooth:
        # Surface force -g Y r_hat on r = r': added to the solver's right-hand side form.
        Vf = function_space(mesh, "Lagrange", degree + 2)
        angular = _delta_density(case, Vf)
        dS = _interface_measure(mesh)
        v = ufl.TestFunction(stokes.V)
        q = ufl.TestFunction(stokes.Q)
        r_hat = x / ufl.sqrt(ufl.dot(x, x))
        forms = stokes.prepare(T, None)
        zero = dolfinx.fem.Constant(mesh, np.zeros(case.dim))
        L0 = ufl.inner(zero, v) * ufl.dx + (-angular("+") * ufl.dot(r_hat("+"), v("+"))) * dS
        stokes.forms = forms._replace(L=dolfinx.fem.form([L0, ufl.inner(dolfinx.fem.Constant(mesh, 0.0), q) * ufl.dx]))
    comm.barrier()
    start = time.perf_counter()
    stokes.solve(T)
    seconds = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)

    # Analytical fields in higher-degree spaces.
    Vh = function_space(mesh, "Lagrange", degree + 2, shape=(mesh.geometry.dim,))
    Qh = function_space(mesh, "Lagrange" if case.smooth else "DG", degree + 1)
    u_exact, p_exact = dolfinx.fem.Function(Vh), dolfinx.fem.Function(Qh)
    if case.smooth:
        u_exact.interpolate(_pointwise(solutions[0].velocity_cartesian, case.dim))
        p_exact.interpolate(_pointwise(solutions[0].pressure_cartesian, 1))
    else:
        tdim = mesh.topology.dim
        num_cells = mesh.topology.index_map(tdim).size_local + mesh.topology.index_map(tdim).num_ghosts
        mid = dolfinx.mesh.compute_midpoints(mesh, tdim, np.arange(num_cells, dtype=np.int32))
        below = np.linalg.norm(mid[:, : case.dim], axis=1) < R_DELTA
        for solution, cells in zip(solutions, (np.flatnonzero(below), np.flatnonzero(~below))):
            cells = cells.astype(np.int32)
            interpolate_on_cells(u_exact, _pointwise(solution.velocity_cartesian, case.dim), cells)
            interpolate_on_cells(p_exact, _pointwise(solution.pressure_cartesian, 1), cells)

    def integral(expr) -> float:
        return comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(expr * ufl.dx)), op=MPI.SUM)

    volume = integral(dolfinx.fem.Constant(mesh, 1.0))
    p_mean = integral(p_exact) / volume
    u_err = np.sqrt(integral(ufl.inner(stokes.u - u_exact, stokes.u - u_exact)) / integral(ufl.inner(u_exact, u_exact)))
    p_err = np.sqrt(integral((stokes.p - (p_exact - p_mean)) ** 2) / integral((p_exact - p_mean) ** 2))
    divergence = np.sqrt(integral(ufl.div(stokes.u) ** 2))
    cells = mesh.topology.index_map(mesh.topology.dim).size_global
    dofs = (stokes.V.dofmap.index_map.size_global * stokes.V.dofmap.index_map_bs
            + stokes.Q.dofmap.index_map.size_global)
    eta = kelly_indicator([stokes.u]) if indicator else None
    stokes.destroy()
    return LevelResult(level, h_target, int(cells), float((volume / cells) ** (1.0 / case.dim)), int(dofs),
                       float(u_err), float(p_err), float(divergence), float(seconds)), eta


def run_hierarchy(case: Case, rounds: int, resolution: float, *, comm: MPI.Comm, adaptive: bool,
                  refine_fraction: float = 0.3, **options) -> list[LevelResult]:
    """The meshes of a hierarchy with the shell manifold (collective; the delta cases' manifold keeps
    the forcing's surface r' as well): ``adaptive``, round i
    refined from round i - 1 by the Kelly indicator of its velocity; otherwise level i uniformly
    refined i times. Returns one result per round / level 0..rounds."""
    interfaces = () if case.smooth else (R_DELTA,)
    base = create_shell_mesh(comm, ShellSpec(case.dim, R_INNER, R_OUTER, resolution=resolution, geometry_degree=1,
                                             interfaces=interfaces))
    hierarchy = MeshHierarchy(base, manifold=ShellManifold(R_INNER, R_OUTER, case.dim, interfaces=interfaces))
    params = AdaptivitySettings(every=1, min_level=0, max_level=rounds, refine_fraction=refine_fraction,
                                  coarsen_fraction=0.0)
    results, mesh = [], hierarchy.uniform(0)
    for i in range(rounds + 1):
        if not adaptive:
            mesh = hierarchy.uniform(i)
        result, eta = solve_on(case, mesh, i, resolution / 2**i, comm=comm, indicator=adaptive, **options)
        results.append(result)
        if adaptive and i < rounds:
            mesh = hierarchy.rebuild(mesh, wanted_levels(eta, hierarchy.levels(mesh), params, comm))
    return results


def fitted_order(h: list[float], errors: list[float]) -> float | None:
    """Least-squares slope of log(error) against log(h) (None for fewer than two levels)."""
    if len(h) < 2:
        return None
    return float(np.polyfit(np.log(h), np.log(errors), 1)[0])


def main(argv: list[str] | None = None) -> dict:
    parser = BENCHMARK.parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--kind", choices=KINDS, default="smooth_free_slip")
    parser.add_argument("--dim", type=int, choices=(2, 3), default=2)
    parser.add_argument("--n", type=int, default=2, help="wave number (2D) or harmonic degree l (3D)")
    parser.add_argument("--m", type=int, default=1, help="harmonic order (3D)")
    parser.add_argument("--k", type=int, default=3, help="radial power of the smooth forcing")
    parser.add_argument("--levels", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--resolution", type=float, default=None,
                        help="gmsh cell size of level 0 (default 0.2 in 2D, 0.5 in 3D)")
    parser.add_argument("--degree", type=int, default=2, help="velocity degree (pressure: degree - 1)")
    parser.add_argument("--geometry-degree", type=int, default=2, choices=(1, 2))
    parser.add_argument("--solver", default="direct")
    parser.add_argument("--nitsche-penalty", type=float, default=None)
    parser.add_argument("--petsc-options", type=json.loads, default=None,
                        help='extra Stokes PETSc options as JSON, e.g. \'{"mat_mumps_icntl_10": -2}\'')
    parser.add_argument("--mesh-dir", type=Path, default=None,
                        help="read each level's gmsh mesh from this folder, or write it there the first time "
                             "(the same meshes for another gmsh version: benchmarks/releases)")
    parser.add_argument("--adaptive", type=int, default=None, metavar="ROUNDS",
                        help="refine ROUNDS times by the Kelly indicator of the velocity")
    parser.add_argument("--refine-fraction", type=float, default=0.3,
                        help="--adaptive: fraction of the cells (largest indicator) refined each round")
    parser.add_argument("--hierarchy", action="store_true",
                        help="refine the adaptive path's base uniformly to the largest of --levels")
    args = parser.parse_args(argv)
    comm = MPI.COMM_WORLD
    case = Case(args.kind, args.dim, args.n, args.m, args.k)
    resolution = args.resolution if args.resolution is not None else (0.2 if args.dim == 2 else 0.5)
    options = dict(degree=args.degree, solver=args.solver, nitsche_penalty=args.nitsche_penalty,
                   petsc_options=args.petsc_options)
    if args.adaptive is not None or args.hierarchy:
        rounds = args.adaptive if args.adaptive is not None else max(args.levels)
        results = run_hierarchy(case, rounds, resolution, comm=comm, adaptive=args.adaptive is not None,
                                refine_fraction=args.refine_fraction, **options)
    else:
        results = [run_level(case, level, resolution, comm=comm, geometry_degree=args.geometry_degree,
                             mesh_dir=args.mesh_dir, **options)
                   for level in args.levels]
    h = [r.h for r in results]
    document = {
        "case": asdict(case), "ranks": comm.size, "degree": args.degree, "geometry_degree": args.geometry_degree,
        "solver": args.solver, "refinement": ("adaptive" if args.adaptive is not None else
                                              "hierarchy" if args.hierarchy else "gmsh"),
        "levels": [asdict(r) for r in results],
        "orders": {"velocity": fitted_order(h, [r.velocity_error for r in results]),
                   "pressure": fitted_order(h, [r.pressure_error for r in results])},
    }
    if comm.rank == 0:
        print(json.dumps(document, indent=1))
    return document


if __name__ == "__main__":
    main()
