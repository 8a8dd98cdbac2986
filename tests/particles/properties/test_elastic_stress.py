"""``elastic_stress``: the Jaumann rotation (exact over the step), the Maxwell update at the particles
(backward Euler's closed form), the Voigt layout, and the step of length 0 that changes nothing."""

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from _helpers import swarm_at
from fembase.dolfinx_compat import function_space
from particles.properties import PROPERTIES, ElasticStress, PropertyBuildContext, PropertyContext, PropertyManager
from particles.properties.elastic_stress import from_voigt, jaumann_rotation, to_voigt

RNG = np.random.default_rng(5)


def _symmetric(n, g):
    a = RNG.normal(size=(n, g, g))
    return 0.5 * (a + np.swapaxes(a, 1, 2))


@pytest.mark.parametrize("gdim", [2, 3])
def test_voigt_round_trip(gdim):
    tau = _symmetric(7, gdim)
    assert to_voigt(tau).shape == (7, 3 if gdim == 2 else 6)
    assert np.allclose(from_voigt(to_voigt(tau), gdim), tau, rtol=0, atol=1e-15)


@pytest.mark.parametrize("gdim", [2, 3])
def test_rotation_keeps_the_invariants_and_solves_the_jaumann_equation(gdim):
    tau, grad = _symmetric(5, gdim), RNG.normal(size=(5, gdim, gdim))
    big = jaumann_rotation(tau, grad, 3.0)  # a large rotation: invariants exact, symmetric
    assert np.allclose(np.swapaxes(big, 1, 2), big, atol=1e-14)
    assert np.allclose(np.einsum("nij,nij->n", big, big), np.einsum("nij,nij->n", tau, tau), rtol=1e-13)
    assert np.allclose(np.trace(big, axis1=1, axis2=2), np.trace(tau, axis1=1, axis2=2), atol=1e-13)
    W = 0.5 * (grad - np.swapaxes(grad, 1, 2))
    rate = W @ tau - tau @ W  # dtau/dt = W tau - tau W: the linearised step agrees to O(dt^2)
    errors = [np.abs(jaumann_rotation(tau, grad, dt) - (tau + dt * rate)).max() for dt in (1e-2, 5e-3)]
    assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.05)


def test_rigid_rotation_turns_the_stress_with_the_material():
    """u = omega (-y, x) turns the frame by omega t counterclockwise: e_x e_x becomes e e with e = (cos, sin)."""
    omega, dt = 0.7, 1.3
    grad = np.array([[[0.0, -omega], [omega, 0.0]]])
    tau = np.array([[[1.0, 0.0], [0.0, 0.0]]])
    e = np.array([np.cos(omega * dt), np.sin(omega * dt)])
    assert np.allclose(jaumann_rotation(tau, grad, dt)[0], np.outer(e, e), atol=1e-14)


def _fields(mesh, eta_ve, chi, rate):
    V = function_space(mesh, "Lagrange", 2, shape=(2,))
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: np.stack([rate * x[0], -rate * x[1]]))
    D = function_space(mesh, "DG", 1)
    out = {}
    for name, value in (("elastic_viscosity", eta_ve), ("elastic_memory", chi)):
        out[name] = dolfinx.fem.Function(D)
        out[name].x.array[:] = value
    return u, out


def test_maxwell_update_is_backward_euler_and_dt_zero_changes_nothing():
    """eta = G = 1, dt_e = dt: tau^{n+1} = 2 eta_ve eps + chi tau^n, tau^n = 2 eps (1 - (1 + dt)^-n)."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 3, 3)
    swarm = swarm_at(mesh, np.array([[0.2, 0.3], [0.7, 0.6], [0.45, 0.9]]))
    manager = PropertyManager(swarm, [ElasticStress()])
    manager.initialise(PropertyContext())
    assert np.array_equal(manager.values("elastic_stress"), np.zeros((3, 3)))
    eps, dt = 0.01, 0.1
    eta_ve, chi = dt / (1 + dt), 1 / (1 + dt)  # eta G dt/(eta + G dt), eta/(eta + G dt)
    u, fields = _fields(mesh, eta_ve, chi, eps)
    manager.update(PropertyContext(dt=0.0, u_new=u, fields=fields))
    assert np.array_equal(manager.values("elastic_stress"), np.zeros((3, 3)))
    for n in range(1, 6):
        manager.update(PropertyContext(time=n * dt, dt=dt, u_new=u, fields=fields))
    expected = 2 * eps * (1 - (1 + dt) ** -5)
    assert np.allclose(manager.values("elastic_stress"), [expected, -expected, 0.0], rtol=1e-12, atol=1e-16)
    with pytest.raises(ValueError, match="elastic_memory"):
        manager.update(PropertyContext(dt=dt, u_new=u, fields={"elastic_viscosity": fields["elastic_viscosity"]}))


def test_initial_values_and_their_checks():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 2, 2)
    swarm = swarm_at(mesh, np.array([[0.2, 0.3], [0.7, 0.6]]))
    settings = PROPERTIES.settings("elastic_stress", initial=(1.0, -1.0, 0.5))
    manager = PropertyManager(swarm, [PROPERTIES.build("elastic_stress", settings, PropertyBuildContext())])
    manager.initialise(PropertyContext())
    assert np.array_equal(manager.values("elastic_stress"), [[1.0, -1.0, 0.5]] * 2)
    assert ElasticStress().size(3) == 6 and ElasticStress.default_new_particles == "interpolate"
    with pytest.raises(ValueError, match="3 .2D. or 6"):
        ElasticStress(ElasticStress.Settings(initial=(1.0, 2.0)))
    with pytest.raises(ValueError, match="needs 3 numbers in 2D"):
        six = ElasticStress(ElasticStress.Settings(initial=(0.0,) * 6))
        too_many = PropertyManager(swarm_at(mesh, np.array([[0.5, 0.5]])), [six])
        too_many.initialise(PropertyContext())


def _flow(x):
    """A flow with spin and strain, not in P2: in 2D (all z = 0) or 3D."""
    if np.all(x[2] == 0.0):
        return np.stack([np.sin(2 * x[1]) + x[0] ** 2, np.cos(3 * x[0]) - x[0] * x[1]])
    return np.stack([np.sin(2 * x[1]) + x[0] * x[2], np.cos(3 * x[2]) - x[0] * x[1],
                     np.sin(x[0] + 2 * x[1]) + x[2] ** 2])


@pytest.mark.parametrize("gdim", [2, 3])
@pytest.mark.parametrize("degree", [0, 1])
def test_compiled_update_gives_the_vectorised_numbers(degree, gdim, monkeypatch):
    """The compiled loop (particles/properties/elastic_kernel.py) against the vectorised path on a
    distorted mesh of triangles or tetrahedra, a P2 flow with spin and strain, eta_ve and chi varying
    in space (DG0 or DG1), a random stress and a large step: equal to round-off."""
    import particles.properties.elastic_stress as module

    if gdim == 2:
        mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 5, 4)
    else:
        mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 3, 3, 2)
    mesh.geometry.x[:, 0] += 0.05 * np.sin(3.0 * mesh.geometry.x[:, 1])  # cells of different shapes
    points = RNG.uniform(0.05, 0.95, size=(200, gdim))
    V = function_space(mesh, "Lagrange", 2, shape=(gdim,))
    u = dolfinx.fem.Function(V)
    u.interpolate(_flow)
    D = function_space(mesh, "DG", degree)
    fields = {name: dolfinx.fem.Function(D) for name in ElasticStress.mesh_fields}
    fields["elastic_viscosity"].interpolate(lambda x: 1.0 + x[0] * x[1])
    fields["elastic_memory"].interpolate(lambda x: 0.3 + 0.5 * x[0])
    results, ran = [], []
    compiled_update = module.fast_update
    monkeypatch.setattr(module, "fast_update", lambda *args: ran.append(compiled_update(*args)) or ran[-1])
    for fast in (True, False):
        swarm = swarm_at(mesh, points)
        manager = PropertyManager(swarm, [ElasticStress()])
        manager.initialise(PropertyContext())
        swarm.properties[:] = RNG.normal(size=swarm.properties.shape) if fast else results[0][1]
        start = swarm.properties.copy()
        if not fast:
            monkeypatch.setattr(module, "fast_update", lambda *args: False)
        manager.update(PropertyContext(time=0.7, dt=0.7, u_new=u, fields=fields))
        results.append((manager.values("elastic_stress").copy(), start))
    (compiled, start), (vectorised, _) = results
    assert ran == [True]  # the first update took the compiled loop
    assert compiled.shape[1] == (3 if gdim == 2 else 6)
    assert np.abs(compiled - start).max() > 0.1  # the update did something
    assert np.allclose(compiled, vectorised, rtol=0.0, atol=1e-13 * np.abs(vectorised).max())
