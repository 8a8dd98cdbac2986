"""Matrix-free action of the P2 velocity block against PETSc's assembled one (issue 34, item 3).

The multigrid's finest level applies the velocity block ``A`` (``2 eta eps(u) : eps(v)``, vector P2
on tetrahedra) about six times per outer iteration (Chebyshev smoothing, residual, the outer
operator). Stored, ``A`` is the largest object of a 3D run. This script measures, on one core
(the operation is the same on each rank; a rank adds a ghost exchange, the same for both), one
application ``y = A x`` three ways:

- ``assembled``: PETSc's ``MatMult`` on the matrix DOLFINx assembles (AIJ with block size 3, the
  layout fieldsplit's velocity block has);
- ``on the fly``: a numba kernel that loops over the cells with the stored inverse Jacobian of each
  (affine cells: 9 numbers) and the cell's nodes, forms the physical gradients of the ten P2
  basis functions at the 4 points of the degree-2 rule (exact for a constant viscosity per
  cell), the strain rate, and adds ``sum_q w_q 2 eta |det J| eps(u) : grad(phi_i e_k)`` into y;
- ``stored gradients``: the same with the physical gradients stored per cell and point
  (120 numbers a cell: the "precomputed geometry" variant).

A sum-factorised action, the reason matrix-free pays for ASPECT's hexahedra (Q2: 27 nodes a cell,
tensor-product bases, Kronecker kernels), has no counterpart on simplices.

Every variant is checked against the assembled product (relative difference below 1e-12). Memory is
the matrix's (its allocated nonzeros from PETSc's ``MatGetInfo``: values and column indices, and
the row offsets) against the arrays each kernel reads. Seconds are the best
of ``--repeat`` rounds of ``--applications`` products.

Usage (the machine otherwise idle)::

    python -m benchmarks.scaling.matrix_free --sizes 8 16 24 32 [--out benchmarks/scaling/matrix_free.md]
"""

from __future__ import annotations

import time
from pathlib import Path

import basix
import dolfinx
import dolfinx.fem.petsc
import numba
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from benchmarks.harness import Benchmark, Load
from fembase.dolfinx_compat import cell_dofmap, function_space, geometry_dofmap

HERE = Path(__file__).resolve().parent
BENCHMARK = Benchmark(__doc__, out_option=True)

QUADRATURE_DEGREE = 2
"""grad(P2) . grad(P2) is of degree 2 on an affine cell: the 4-point rule is exact."""


@numba.njit(cache=True)
def _apply_on_the_fly(x: np.ndarray, y: np.ndarray, nodes: np.ndarray, inverse_jacobian: np.ndarray,
                      scale: np.ndarray, dphi: np.ndarray) -> None:  # pragma: no cover - numba
    """y += A x. nodes (cells, 10); inverse_jacobian (cells, 3, 3), K[j, d] = dX_j/dx_d;
    scale (cells, points) = 2 eta w_q |det J|; dphi (points, 10, 3) reference gradients."""
    n_points, n_basis = dphi.shape[0], dphi.shape[1]
    ue = np.empty((n_basis, 3))
    ye = np.empty((n_basis, 3))
    grad = np.empty((n_basis, 3))
    for c in range(nodes.shape[0]):
        _gather(x, nodes[c], ue, ye)
        for q in range(n_points):
            for i in range(n_basis):
                for d in range(3):
                    grad[i, d] = (dphi[q, i, 0] * inverse_jacobian[c, 0, d] + dphi[q, i, 1] * inverse_jacobian[c, 1, d]
                                  + dphi[q, i, 2] * inverse_jacobian[c, 2, d])
            _strain_action(ue, ye, grad, scale[c, q])
        _scatter(y, nodes[c], ye)


@numba.njit(cache=True)
def _apply_stored(x: np.ndarray, y: np.ndarray, nodes: np.ndarray, gradients: np.ndarray,
                  scale: np.ndarray) -> None:  # pragma: no cover - numba
    """y += A x with the physical gradients stored: gradients (cells, points, 10, 3)."""
    n_points, n_basis = gradients.shape[1], gradients.shape[2]
    ue = np.empty((n_basis, 3))
    ye = np.empty((n_basis, 3))
    for c in range(nodes.shape[0]):
        _gather(x, nodes[c], ue, ye)
        for q in range(n_points):
            _strain_action(ue, ye, gradients[c, q], scale[c, q])
        _scatter(y, nodes[c], ye)


@numba.njit(cache=True, inline="always")
def _gather(x: np.ndarray, cell_nodes: np.ndarray, ue: np.ndarray, ye: np.ndarray) -> None:  # pragma: no cover
    """ue[i, k] = x at the cell's node i, component k; ye = 0."""
    for i in range(cell_nodes.shape[0]):
        for k in range(3):
            ue[i, k] = x[3 * cell_nodes[i] + k]
            ye[i, k] = 0.0


@numba.njit(cache=True, inline="always")
def _scatter(y: np.ndarray, cell_nodes: np.ndarray, ye: np.ndarray) -> None:  # pragma: no cover
    """y at the cell's node i, component k += ye[i, k]."""
    for i in range(cell_nodes.shape[0]):
        for k in range(3):
            y[3 * cell_nodes[i] + k] += ye[i, k]


@numba.njit(cache=True, inline="always")
def _strain_action(ue: np.ndarray, ye: np.ndarray, grad: np.ndarray, s: float) -> None:  # pragma: no cover
    """ye[i, k] += s eps(u)[k, d] grad[i, d] at one point (eps(u) symmetric: eps(u) : grad v)."""
    g = np.zeros((3, 3))
    for i in range(ue.shape[0]):
        for k in range(3):
            for d in range(3):
                g[k, d] += ue[i, k] * grad[i, d]
    for k in range(3):
        for d in range(3):
            e = 0.5 * s * (g[k, d] + g[d, k])
            for i in range(ue.shape[0]):
                ye[i, k] += e * grad[i, d]


def _geometry(mesh: dolfinx.mesh.Mesh, eta: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Inverse Jacobians (cells, 3, 3), the weights 2 eta w_q |det J| (cells, points), the reference
    gradients (points, 10, 3) and the physical ones (cells, points, 10, 3) of the affine cells."""
    x = mesh.geometry.x
    vertices = x[geometry_dofmap(mesh)[:, :4]]  # (cells, 4, 3), basix's reference order
    jacobian = np.transpose(vertices[:, 1:] - vertices[:, :1], (0, 2, 1))  # J[a, j] = dx_a/dX_j
    inverse = np.linalg.inv(jacobian)
    points, weights = basix.make_quadrature(basix.CellType.tetrahedron, QUADRATURE_DEGREE)
    element = basix.create_element(basix.ElementFamily.P, basix.CellType.tetrahedron, 2,
                                   basix.LagrangeVariant.equispaced)
    dphi = np.ascontiguousarray(np.transpose(element.tabulate(1, points)[1:4, :, :, 0], (1, 2, 0)))
    scale = 2.0 * eta * np.abs(np.linalg.det(jacobian))[:, None] * weights[None, :]
    gradients = np.ascontiguousarray(np.einsum("qij,cjd->cqid", dphi, inverse))
    return np.ascontiguousarray(inverse), scale, dphi, gradients


def _matrix_bytes(A) -> float:
    """An AIJ matrix's values (8 bytes) and column indices (PETSc's integer) and its row offsets."""
    index = np.dtype(PETSc.IntType).itemsize
    return float(A.getInfo()["nz_allocated"] * (8 + index) + (A.getSize()[0] + 1) * index)


def _best(apply, repeat: int, applications: int) -> float:
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(applications):
            apply()
        best = min(best, (time.perf_counter() - start) / applications)
    return best


def measure(n: int, *, repeat: int, applications: int, eta: float = 1.0) -> list[dict[str, float | str]]:
    """One row per variant at n^3 cubes (6 tetrahedra each) on this process."""
    mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, n, n, n)
    V = function_space(mesh, "Lagrange", 2, shape=(3,))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    a = dolfinx.fem.form(2.0 * eta * ufl.inner(ufl.sym(ufl.grad(u)), ufl.sym(ufl.grad(v))) * ufl.dx)
    A = dolfinx.fem.petsc.assemble_matrix(a)
    A.assemble()
    x, y = A.createVecs()
    x.setArray(np.random.default_rng(1).standard_normal(x.getLocalSize()))
    A.mult(x, y)
    reference = y.getArray().copy()
    inverse, scale, dphi, gradients = _geometry(mesh, eta)
    nodes = np.ascontiguousarray(cell_dofmap(V)).astype(np.int32)
    xa = x.getArray(readonly=True).copy()
    ya = np.zeros_like(xa)
    variants = {
        "assembled": (lambda: A.mult(x, y), _matrix_bytes(A)),
        "on the fly": (lambda: (ya.fill(0.0), _apply_on_the_fly(xa, ya, nodes, inverse, scale, dphi)),
                       float(nodes.nbytes + inverse.nbytes + scale.nbytes)),
        "stored gradients": (lambda: (ya.fill(0.0), _apply_stored(xa, ya, nodes, gradients, scale)),
                             float(nodes.nbytes + gradients.nbytes + scale.nbytes)),
    }
    rows = []
    unknowns = x.getSize()
    for name, (apply, memory) in variants.items():
        apply()
        result = y.getArray() if name == "assembled" else ya
        error = float(np.linalg.norm(result - reference) / np.linalg.norm(reference))
        if error > 1e-12:
            raise AssertionError(f"{name} at {n}^3 differs from the assembled product by {error:.1e}")
        seconds = _best(apply, repeat, applications)
        rows.append({"n": n, "unknowns": unknowns, "variant": name, "seconds": seconds, "memory": memory,
                     "error": error})
    A.destroy()
    return rows


def main(argv: list[str] | None = None) -> str:
    parser = BENCHMARK.parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[8, 16])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--applications", type=int, default=10)
    args = parser.parse_args(argv)
    load = " ".join(f"{value:.2f}" for value in Load.now().averages)
    lines = [
        "# The P2 velocity block's action: assembled (PETSc) against matrix-free (numba), one core",
        "",
        f"Generated by `python benchmarks/scaling/matrix_free.py --sizes {' '.join(map(str, args.sizes))}`; "
        f"best of {args.repeat} rounds of {args.applications} products; load average before: {load}. "
        "Constant viscosity, n³ cubes of 6 tetrahedra, every variant equal to the assembled product "
        "to the error shown.",
        "",
        "| cells per side | unknowns | variant | one product [ms] | against assembled | memory [MB] | "
        "memory [bytes / unknown] | relative difference |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for n in args.sizes:
        rows = measure(n, repeat=args.repeat, applications=args.applications)
        base = rows[0]["seconds"]
        for row in rows:
            lines.append(f"| {row['n']} | {row['unknowns']} | {row['variant']} | {1e3 * row['seconds']:.2f} | "
                         f"{row['seconds'] / base:.2f}x | {row['memory'] / 2**20:.1f} | "
                         f"{row['memory'] / row['unknowns']:.0f} | {row['error']:.1e} |")
        print(lines[-3:], flush=True)
    text = "\n".join(lines) + "\n"
    if args.out is not None:
        args.out.write_text(text)
    print(text)
    return text


if __name__ == "__main__":
    main()
