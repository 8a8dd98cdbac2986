"""The 2D cylindrical sector (``mesh.geometry: sector``), added as one domain class: its mesh and
boundaries, and Taylor-Hood Stokes on it converging at the orders of curved P2-P1 against Kramer et
al.'s annulus solution (``assess``) restricted to the sector.

The annulus solution with forcing ``rho' = (r / R_p)^k cos(n phi)`` is mirror-symmetric about every
ray ``phi = j pi / n``: there its angular velocity and its shear stress vanish. A sector bounded by
two such rays therefore has the annulus solution as its own with free slip on all four sides (here
``n = 4``, ``k = 2`` on 45-135 degrees: sides oblique to the axes, free slip weak by Nitsche everywhere); on any
other sector the exact velocity is prescribed on the radial sides (here ``n = 2``, ``k = 3`` on 10-100 degrees).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import ufl
from mpi4py import MPI

import dolfinx.fem

pytest.importorskip("gmsh")
assess = pytest.importorskip("assess")

from convection.geometry import Sector, SectorSpec, VelocityBC  # noqa: E402
from convection.physics.approximation import BoussinesqApproximation  # noqa: E402
from convection.solvers.stokes.solver import StokesSolver  # noqa: E402
from fembase.dolfinx_compat import function_space  # noqa: E402

R_INNER, R_OUTER = 1.22, 2.22


def _integral(mesh, expr) -> float:
    return mesh.comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(expr)), op=MPI.SUM)


def _pointwise(function, components: int):
    def evaluate(x: np.ndarray) -> np.ndarray:
        values = np.array([function(x[:, i]) for i in range(x.shape[1])], dtype=np.float64)
        return values.T.reshape(components, -1) if components > 1 else values.reshape(-1)
    return evaluate


def test_sector_mesh_and_boundaries(world):
    spec = SectorSpec(R_INNER, R_OUTER, (45.0, 135.0), resolution=0.2)
    domain = Sector(spec)
    mesh = domain.create_mesh(world)
    assert abs(_integral(mesh, dolfinx.fem.Constant(mesh, 1.0) * ufl.dx) / spec.volume - 1.0) < 1e-6
    tags = domain.facet_tags(mesh)
    lengths = {name: _integral(mesh, dolfinx.fem.Constant(mesh, 1.0) * domain.measure(mesh, name, tags=tags))
               for name in domain.boundaries}
    assert lengths["inner"] == pytest.approx(0.5 * math.pi * R_INNER, rel=1e-5)
    assert lengths["outer"] == pytest.approx(0.5 * math.pi * R_OUTER, rel=1e-5)
    assert lengths["west"] == pytest.approx(1.0, rel=1e-12) and lengths["east"] == pytest.approx(1.0, rel=1e-12)
    # every boundary facet is on exactly one boundary
    fdim = mesh.topology.dim - 1
    mesh.topology.create_connectivity(fdim, mesh.topology.dim)
    boundary = dolfinx.mesh.exterior_facet_indices(mesh.topology)
    assert np.array_equal(np.sort(tags.indices), np.sort(boundary))


def _solve(spec: SectorSpec, n: int, k: int, prescribed_sides: bool, comm: MPI.Comm) -> tuple[float, float, float]:
    """Relative L2 errors of velocity and pressure, and the mesh size, on one sector mesh."""
    solution = assess.CylindricalStokesSolutionSmoothFreeSlip(n, k, Rp=R_OUTER, Rm=R_INNER)
    domain = Sector(spec)
    mesh = domain.create_mesh(comm)
    exact_velocity = _pointwise(solution.velocity_cartesian, 2)
    side = VelocityBC("prescribed", exact_velocity) if prescribed_sides else VelocityBC("free_slip")
    bcs = {"inner": VelocityBC("free_slip"), "outer": VelocityBC("free_slip"), "west": side, "east": side}
    stokes = StokesSolver(mesh, BoussinesqApproximation(Ra=1.0, gravity=domain.gravity), bcs=bcs, domain=domain)
    assert stokes.has_pressure_null_space and not stokes.has_rotation_null_space
    density = dolfinx.fem.Function(function_space(mesh, "Lagrange", 4))
    density.interpolate(_pointwise(solution.delta_rho_cartesian, 1))
    stokes.solve(-density)
    u_exact = dolfinx.fem.Function(function_space(mesh, "Lagrange", 4, shape=(2,)))
    u_exact.interpolate(exact_velocity)
    p_exact = dolfinx.fem.Function(function_space(mesh, "Lagrange", 3))
    p_exact.interpolate(_pointwise(solution.pressure_cartesian, 1))
    volume = _integral(mesh, dolfinx.fem.Constant(mesh, 1.0) * ufl.dx)
    p_exact.x.array[:] -= _integral(mesh, p_exact * ufl.dx) / volume  # the solver's pressure has zero mean
    du, dp = stokes.u - u_exact, stokes.p - p_exact
    u_error = math.sqrt(_integral(mesh, ufl.inner(du, du) * ufl.dx)
                        / _integral(mesh, ufl.inner(u_exact, u_exact) * ufl.dx))
    p_error = math.sqrt(_integral(mesh, dp * dp * ufl.dx) / _integral(mesh, p_exact * p_exact * ufl.dx))
    cells = mesh.topology.index_map(2).size_global
    stokes.destroy()
    return u_error, p_error, math.sqrt(volume / cells)


@pytest.mark.parametrize("n, k, angles, prescribed_sides", [(4, 2, (45.0, 135.0), False), (2, 3, (10.0, 100.0), True)])
def test_stokes_orders_in_the_sector(n, k, angles, prescribed_sides):
    """P2-P1 on curved cells: velocity O(h^3), pressure O(h^2) in L2, with free slip on the oblique
    sides (weak) as with the exact velocity prescribed on them (strong)."""
    results = [_solve(SectorSpec(R_INNER, R_OUTER, angles, resolution=0.3 / 2**level), n, k, prescribed_sides,
                      MPI.COMM_WORLD) for level in range(3)]
    u_errors, p_errors, h = (np.array(column) for column in zip(*results))
    u_order = np.polyfit(np.log(h), np.log(u_errors), 1)[0]
    p_order = np.polyfit(np.log(h), np.log(p_errors), 1)[0]
    assert u_order > 2.7 and p_order > 1.7, (u_errors, p_errors, h)
    assert u_errors[-1] < 1e-3 and p_errors[-1] < 2e-2, (u_errors, p_errors)


def test_conduction_through_a_sector_from_a_config(tmp_path):
    """A sector run from YAML keys: the conductive profile ``ln(r / r_o) / ln(r_i / r_o)`` at Ra = 0
    has the Nusselt number 1 through both arcs (the sector's conductive reference, to P2's
    interpolation error of the logarithm)."""
    from convection.app.factory import run_config
    from convection.config.loader import load_config
    from convection.io.statistics import read_table

    document = {"mesh": {"geometry": "sector", "angles": [20.0, 110.0], "resolution": 0.15},
                "physics": {"Ra": 0.0},
                "boundary": {"temperature": {"inner": {"dirichlet": 1.0}, "outer": {"dirichlet": 0.0}}},
                "initial": {"temperature": "log(r / r_outer) / log(r_inner / r_outer)"},
                "time": {"end": 1.0, "max_steps": 2, "dt_initial": 1e-3},
                "output": {"directory": str(tmp_path / "run"), "progress": "none", "checkpoint": {"at_end": False}}}
    config = load_config(None, document=document)
    assert config["boundary"]["velocity"] == dict.fromkeys(("inner", "outer", "west", "east"), "free_slip")
    run_config(config)
    table = read_table(tmp_path / "run" / "statistics.csv")
    column = {name: [float(row[i]) for row in table.rows] for i, name in enumerate(table.columns)}
    assert max(column["vrms"]) == 0.0
    assert np.allclose(column["nusselt"], 1.0, atol=2e-4) and np.allclose(column["nusselt_bottom"], 1.0, atol=5e-4)
