"""Point evaluation at particles: exact reproduction of polynomials, gradients, locate()."""

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from fembase.dolfinx_compat import function_space
from fembase.evaluation import Evaluator, evaluate, evaluate_gradient, locate
from fembase.geometry import Candidates, CellGeometry


def _poly(degree, x, shift=0.0):
    """A full polynomial of ``degree`` in gdim variables; x shape=(gdim, n)."""
    gdim = x.shape[0]
    val = np.full(x.shape[1], 0.3 + shift)
    grad = np.zeros((gdim, x.shape[1]))
    for d in range(gdim):
        for k in range(1, degree + 1):
            a = (1.0 + d + k + shift) / (k + 1)
            val = val + a * x[d] ** k
            grad[d] += a * k * x[d] ** (k - 1)
    if degree >= 2 and gdim >= 2:
        c = 0.7 + shift
        tail = x[0] ** (degree - 1) * x[1]
        val = val + c * tail
        grad[0] += c * (degree - 1) * x[0] ** (degree - 2) * x[1] if degree >= 2 else 0.0
        grad[1] += c * x[0] ** (degree - 1)
    return val, grad


def _mesh(kind, comm=MPI.COMM_SELF):
    if kind == "triangle":
        return dolfinx.mesh.create_unit_square(comm, 5, 4, diagonal=dolfinx.mesh.DiagonalType.crossed)
    if kind == "quadrilateral":
        return dolfinx.mesh.create_unit_square(comm, 4, 5, cell_type=dolfinx.mesh.CellType.quadrilateral)
    if kind == "tetrahedron":
        return dolfinx.mesh.create_unit_cube(comm, 3, 2, 3)
    return dolfinx.mesh.create_unit_cube(comm, 2, 3, 2, cell_type=dolfinx.mesh.CellType.hexahedron)


def _perturb(mesh, rng):
    """Move interior geometry nodes a little so the cells are not all alike."""
    x = mesh.geometry.x
    interior = np.all((x[:, : mesh.geometry.dim] > 1e-10) & (x[:, : mesh.geometry.dim] < 1 - 1e-10), axis=1)
    x[interior, : mesh.geometry.dim] += 0.05 * (rng.random((interior.sum(), mesh.geometry.dim)) - 0.5)


@pytest.mark.parametrize("kind", ["triangle", "tetrahedron", "quadrilateral", "hexahedron"])
@pytest.mark.parametrize("degree", [1, 2, 3])
def test_polynomials_reproduced_exactly(kind, degree):
    rng = np.random.default_rng(degree)
    mesh = _mesh(kind)
    if kind in ("triangle", "tetrahedron"):
        _perturb(mesh, rng)
    gdim = mesh.geometry.dim
    points = rng.random((300, gdim))
    found = locate(mesh, points)
    assert np.all(found.cells >= 0)
    geom = CellGeometry(mesh)
    assert np.allclose(geom.push_forward(found.cells, found.xref), points, atol=1e-12)

    V = function_space(mesh, "Lagrange", degree)
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: _poly(degree, x[:gdim])[0])
    W = function_space(mesh, "Lagrange", degree, shape=(mesh.geometry.dim,))
    w = dolfinx.fem.Function(W)
    w.interpolate(lambda x: np.stack([_poly(degree, x[:gdim], shift=s)[0] for s in range(gdim)]))

    exact, exact_grad = _poly(degree, points.T)
    values = evaluate(u, found.cells, found.xref)
    assert values.shape == (300, 1)
    assert np.allclose(values[:, 0], exact, atol=1e-11)
    grads = evaluate_gradient(u, found.cells, found.xref)
    assert grads.shape == (300, 1, gdim)
    assert np.allclose(grads[:, 0, :], exact_grad.T, atol=1e-9)

    wv = evaluate(w, found.cells, found.xref)
    wg = evaluate_gradient(w, found.cells, found.xref)
    assert wv.shape == (300, gdim) and wg.shape == (300, gdim, gdim)
    for s in range(gdim):
        ev, eg = _poly(degree, points.T, shift=s)
        assert np.allclose(wv[:, s], ev, atol=1e-11)
        assert np.allclose(wg[:, s, :], eg.T, atol=1e-9)

    p3 = np.zeros((300, 3))
    p3[:, :gdim] = points
    assert np.allclose(w.eval(p3, found.cells), wv, atol=1e-11)


@pytest.mark.parametrize("kind", ["triangle", "tetrahedron"])
@pytest.mark.parametrize("degree", [1, 2])
def test_fast_path_matches_basix_path(kind, degree):
    rng = np.random.default_rng(7)
    mesh = _mesh(kind)
    gdim = mesh.geometry.dim
    W = function_space(mesh, "Lagrange", degree, shape=(mesh.geometry.dim,))
    w = dolfinx.fem.Function(W)
    w.x.array[:] = rng.random(w.x.array.shape)
    ev = Evaluator(W)
    assert ev.fast
    cells = rng.integers(0, ev.geometry.num_local_cells, 500).astype(np.int32)
    bary = rng.dirichlet(np.ones(gdim + 1), 500)
    xref = bary[:, 1:]
    fast = ev.values(w, cells, xref)
    ev.fast = False
    slow = ev.values(w, cells, xref)
    assert np.allclose(fast, slow, atol=1e-13)
    p3 = np.zeros((500, 3))
    p3[:, :gdim] = ev.geometry.push_forward(cells, xref)
    assert np.allclose(w.eval(p3, cells), fast, atol=1e-12)
    # accumulation out = beta * out + alpha * u (used for the in-place Euler push), both paths
    for use_fast in (True, False):
        ev.fast = use_fast
        acc = np.ones((500, gdim))
        ev.values(w, cells, xref, out=acc, alpha=0.5, beta=2.0)
        assert np.allclose(acc, 2.0 + 0.5 * slow, atol=1e-13)


def test_locate_outside_and_function_space_check():
    mesh = _mesh("triangle")
    found = locate(mesh, np.array([[0.5, 0.5], [1.5, 0.2], [-0.1, 0.3]]))
    assert found.cells[0] >= 0 and np.all(found.cells[1:] == -1)
    other = dolfinx.fem.Function(function_space(mesh, "Lagrange", 1))
    ev = Evaluator(function_space(mesh, "Lagrange", 2))
    with pytest.raises(ValueError, match="function space"):
        ev.values(other, found.cells[:1], found.xref[:1])


@pytest.mark.mpi
def test_evaluation_distributed():
    comm = MPI.COMM_WORLD
    mesh = dolfinx.mesh.create_unit_cube(comm, 4, 4, 4)
    V = function_space(mesh, "Lagrange", 3, shape=(mesh.geometry.dim,))
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: np.stack([_poly(3, x, shift=s)[0] for s in range(3)]))
    points = np.random.default_rng(3).random((400, 3))
    found = locate(mesh, points)
    ok = found.cells >= 0
    vals = evaluate(u, found.cells[ok], found.xref[ok])
    err = max(np.abs(vals[:, s] - _poly(3, points[ok].T, shift=s)[0]).max(initial=0.0) for s in range(3))
    # every point is found by some rank (owned or ghost cell)
    hits = np.zeros(400, dtype=np.int32)
    hits[ok] = 1
    comm.Allreduce(MPI.IN_PLACE, hits, op=MPI.MAX)
    assert comm.allreduce(err, op=MPI.MAX) < 1e-10
    assert int(hits.sum()) == 400


@pytest.mark.parametrize("gdim", [2, 3])
def test_compiled_locate_and_max_match_the_vectorised_path(gdim):
    """The compiled candidate tests of affine cells (locate, max_over_containing) give the cells,
    values and flags of the general vectorised path, points on shared facets and vertices included."""
    comm = MPI.COMM_WORLD
    mesh = (dolfinx.mesh.create_unit_square(comm, 9, 7) if gdim == 2 else dolfinx.mesh.create_unit_cube(comm, 4, 3, 5))
    rng = np.random.default_rng(5)
    points = np.vstack([rng.uniform(-0.1, 1.1, (3000, gdim)), mesh.geometry.x[:, :gdim]])
    fast = CellGeometry(mesh)
    general = CellGeometry(mesh)
    general.affine = False  # Newton pull-back and numpy reductions
    values = rng.integers(0, 9, fast.num_local_cells).astype(np.int32)
    a, b = fast.locate(points), general.locate(points)
    assert np.array_equal(a.cells, b.cells) and np.any(a.cells >= 0) and np.any(a.cells < 0)
    assert np.allclose(a.xref, b.xref, atol=1e-12)
    for x, y in zip(fast.max_over_containing(points, values, default=-3),
                    general.max_over_containing(points, values, default=-3)):
        assert np.array_equal(x, y)


def test_locate_with_candidates_falls_back_to_the_tree():
    """Candidates are tried first; points they miss (wrong or empty groups) are found by the tree,
    so the result is the tree's whenever the candidates hold each point's only containing cell."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 8, 6)
    geometry = CellGeometry(mesh)
    rng = np.random.default_rng(2)
    points = rng.uniform(0.0, 1.0, (500, 2))
    tree = geometry.locate(points)
    n = geometry.num_local_cells
    # group 0: every point's true cell alone (via groups = point index); then wrong cells, then none
    exact = Candidates(np.arange(500), np.arange(501), tree.cells.copy())
    wrong = Candidates(np.zeros(500, dtype=np.int64), np.array([0, 3]), np.array([n - 1, n - 2, n - 3], dtype=np.int32))
    empty = Candidates(np.zeros(500, dtype=np.int64), np.array([0, 0]), np.zeros(0, dtype=np.int32))
    for candidates in (exact, wrong, empty):
        got = geometry.locate(points, candidates=candidates)
        assert np.array_equal(got.cells, tree.cells)
        assert np.allclose(got.xref, tree.xref, atol=1e-14)
