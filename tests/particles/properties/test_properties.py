"""Particle properties: registry, manager policies, path-integrated ODEs (shear closed forms, damage
order), field sampling, new-particle initialisation, and rank independence under MPI."""

import math

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from _helpers import plugin, swarm_at
from fembase.dolfinx_compat import function_space, geometry_dofmap
from fembase.evaluation import locate
from particles import Swarm
from particles.advection import Advector, ParticleODE
from particles.generation import RandomUniform, generate
from particles.properties import (
    PROPERTIES,
    Damage,
    DeformationGradient,
    Displacement,
    FunctionProperty,
    InitialComposition,
    InitialPosition,
    IntegratedStrain,
    Pressure,
    PropertyBuildContext,
    PropertyContext,
    PropertyManager,
    Rank,
    StrainRate,
    Temperature,
    TimeSinceCreation,
    Velocity,
)

GAMMA = 0.8


def _build(name, make=None, **parameters):
    """The property ``name`` made through the registry, as a config makes it."""
    return PROPERTIES.build(name, PROPERTIES.settings(name, **parameters), PropertyBuildContext(make))


def _vector_function(mesh, degree, f):
    V = function_space(mesh, "Lagrange", degree, shape=(mesh.geometry.dim,))
    u = dolfinx.fem.Function(V)
    u.interpolate(f)
    return u


def _scalar_function(mesh, degree, f):
    V = function_space(mesh, "Lagrange", degree)
    u = dolfinx.fem.Function(V)
    u.interpolate(f)
    return u


def _shear(mesh, degree=1, gamma=GAMMA):
    return _vector_function(mesh, degree, lambda x: np.stack([gamma * x[1], np.zeros_like(x[0])]))


def _cellular_flow(x):
    sx, cx = np.sin(np.pi * x[0]), np.cos(np.pi * x[0])
    sy, cy = np.sin(np.pi * x[1]), np.cos(np.pi * x[1])
    return np.stack([2.0 * sx * sx * sy * cy, -2.0 * sx * cx * sy * sy])


def _lattice():
    xs, ys = np.meshgrid([0.13, 0.27, 0.36], [0.21, 0.43, 0.58, 0.79])
    return np.stack([xs.ravel(), ys.ravel()], axis=1)


def _run(swarm, manager, integrator, u, dt, steps):
    adv = Advector(swarm, integrator=integrator, odes=manager.odes())
    for i in range(steps):
        adv.step(u, u, dt)
        manager.update(PropertyContext(time=(i + 1) * dt, dt=dt, u_old=u, u_new=u))


# ----------------------------------------------------------------------------- registry
def test_registry_lists_names_and_rejects_bad_policies():
    assert set(PROPERTIES) == {
        "initial_position", "initial_composition", "function", "velocity", "temperature", "pressure",
        "strain_rate", "integrated_strain", "deformation_gradient", "damage", "time_since_creation", "rank",
        "displacement", "plastic_strain", "elastic_stress", "elastic_stress_invariant", "elastic_strain_rate",
        "viscous_strain_rate", "elastic_share",
    }
    assert all(cls.description for cls in PROPERTIES.values())
    with pytest.raises(ValueError, match="damage.*deformation_gradient.*velocity"):
        _build("strain")
    with pytest.raises(ValueError, match="every_step"):
        _build("velocity", update="sometimes")
    with pytest.raises(ValueError, match="interpolate"):
        _build("rank", new_particles="copy")
    with pytest.raises(ValueError, match="^particle property 'rank' has no parameter 'label'"):
        _build("rank", label="r")
    with pytest.raises(ValueError, match="every_step"):
        plugin(DeformationGradient, update="never")
    with pytest.raises(ValueError, match="alpha"):
        plugin(Damage, alpha=-1.0)
    assert _build("damage", alpha=2.0, beta=0.5) == plugin(Damage, alpha=2.0, beta=0.5)
    text = _build("function", function="x", label="f", make=lambda text: (lambda x: np.full(x.shape[0], 3.0)))
    assert callable(text.source) and text.column == "f" and text.size(2) == 1
    with pytest.raises(ValueError, match="^function: 'function' is text but no expression parser was given$"):
        _build("function", function="x")
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 2, 2)
    swarm = Swarm(mesh)
    with pytest.raises(ValueError, match="distinct labels"):
        PropertyManager(swarm, [plugin(FunctionProperty, function=np.sin), plugin(FunctionProperty, function=np.cos)])
    manager = PropertyManager(swarm, ["deformation_gradient", "velocity", "rank", "initial_position"])
    assert [manager.layout(n).size for n in manager.names] == [4, 2, 1, 2]
    assert swarm.property_names == manager.names
    assert [ode.name for ode in manager.odes()] == ["deformation_gradient"]
    assert [manager[n].update_policy for n in manager.names] == ["every_step", "every_step", "output_only", "never"]
    with pytest.raises(KeyError, match="known"):
        manager["damage"]


# ----------------------------------------------------------------------------- simple shear
@pytest.mark.parametrize("integrator, degree", [("euler", 1), ("rk2", 1), ("rk2", 2), ("rk4", 1)])
def test_simple_shear_closed_forms(integrator, degree):
    """u = (g y, 0): F = [[1, g t], [0, 1]], s = g t / 2, eps = [[0, g/2], [g/2, 0]] for every scheme
    (grad u is constant and nilpotent), initial positions kept, age = steps * dt."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 8, 8)
    u = _shear(mesh, degree)
    x0 = _lattice()
    swarm = swarm_at(mesh, x0)
    manager = PropertyManager(swarm, [InitialPosition(), DeformationGradient(), IntegratedStrain(),
                                      TimeSinceCreation(), StrainRate(), Velocity()])
    manager.initialise(PropertyContext(u_new=u))
    dt, steps = 0.05, 10
    t = dt * steps
    _run(swarm, manager, integrator, u, dt, steps)

    assert swarm.num_particles == x0.shape[0]
    start = x0[swarm.ids]
    np.testing.assert_allclose(swarm.x[:, 0], start[:, 0] + GAMMA * start[:, 1] * t, atol=1e-12)
    np.testing.assert_allclose(swarm.x[:, 1], start[:, 1], atol=1e-12)
    F = manager.values("deformation_gradient").reshape(-1, 2, 2)
    np.testing.assert_allclose(F, np.broadcast_to([[1.0, GAMMA * t], [0.0, 1.0]], F.shape), rtol=0, atol=1e-12)
    np.testing.assert_allclose(manager.values("integrated_strain")[:, 0], GAMMA * t / 2, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(manager.values("initial_position"), start)
    np.testing.assert_allclose(manager.values("time_since_creation")[:, 0], t, rtol=0, atol=1e-14)
    eps = manager.values("strain_rate").reshape(-1, 2, 2)
    np.testing.assert_allclose(eps, np.broadcast_to([[0.0, GAMMA / 2], [GAMMA / 2, 0.0]], eps.shape), atol=1e-12)
    vel = manager.values("velocity")
    np.testing.assert_allclose(vel[:, 0], GAMMA * swarm.x[:, 1], atol=1e-12)
    np.testing.assert_allclose(vel[:, 1], 0.0, atol=1e-12)
    assert swarm.property_names == manager.names  # stage columns removed


def test_displacement_is_distance_from_initial_position_in_shear_and_rotation():
    """Simple shear u = (g y, 0): |x - x0| = g y0 t for every scheme. Rigid rotation by pi: the
    displacement is the diameter of each particle's circle, 2 |x0 - c| (the straight distance, not
    the path). Listed before initial_position, it is still computed after it."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 8, 8)
    x0 = _lattice()
    swarm = swarm_at(mesh, x0)
    manager = PropertyManager(swarm, ["displacement", "initial_position"])
    assert manager.names == ["initial_position", "displacement"]
    manager.initialise(PropertyContext(u_new=_shear(mesh)))
    np.testing.assert_array_equal(manager.values("displacement"), 0.0)
    dt, steps = 0.05, 10
    _run(swarm, manager, "rk2", _shear(mesh), dt, steps)
    start = x0[swarm.ids]
    np.testing.assert_allclose(manager.values("displacement")[:, 0], GAMMA * start[:, 1] * dt * steps, atol=1e-12)

    centre = np.array([0.5, 0.5])
    rotation = _vector_function(mesh, 2, lambda x: np.stack([-(x[1] - 0.5), x[0] - 0.5]))
    points = centre + np.array([[0.1, 0.0], [0.0, -0.2], [0.15, 0.15]])
    swarm = swarm_at(mesh, points)
    manager = PropertyManager(swarm, [InitialPosition(), Displacement()])
    manager.initialise(PropertyContext(u_new=rotation))
    _run(swarm, manager, "rk4", rotation, np.pi / 200, 200)
    expected = 2.0 * np.linalg.norm(points[swarm.ids] - centre, axis=1)
    np.testing.assert_allclose(manager.values("displacement")[:, 0], expected, rtol=1e-6)


def test_displacement_needs_initial_position():
    swarm = Swarm(dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 2, 2))
    with pytest.raises(ValueError, match="'displacement' needs the property 'initial_position'"):
        PropertyManager(swarm, ["displacement", "velocity"])
    with pytest.raises(ValueError, match="initial_position"):
        Displacement().initialise(swarm, np.arange(0), PropertyContext())


def _damage(integrator, steps, alpha=1.5, beta=2.0, t_end=1.0):
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 4, 4)
    u = _shear(mesh)
    swarm = swarm_at(mesh, [[0.2, 0.3], [0.1, 0.6]])
    manager = PropertyManager(swarm, [plugin(Damage, alpha=alpha, beta=beta)])
    manager.initialise()
    _run(swarm, manager, integrator, u, t_end / steps, steps)
    d = manager.values("damage")[:, 0]
    source = alpha * GAMMA / 2  # alpha |eps|, |eps| = sqrt(eps:eps / 2) = gamma / 2
    exact = source / beta * (1.0 - np.exp(-beta * t_end))
    # An explicit RK method maps z = d - source/beta to R(-beta dt) z, R its stability polynomial.
    order = {"euler": 1, "rk2": 2, "rk4": 4}[integrator]
    z = -beta * t_end / steps
    R = sum(z**k / math.factorial(k) for k in range(order + 1))
    discrete = source / beta * (1.0 - R**steps)
    return np.max(np.abs(d - exact)), np.max(np.abs(d - discrete))


@pytest.mark.parametrize("integrator, order, steps", [("euler", 1, [16, 32, 64, 128]), ("rk2", 2, [8, 16, 32, 64]),
                                                      ("rk4", 4, [8, 16, 32, 64])])
def test_damage_converges_with_the_scheme_order(integrator, order, steps):
    """d(t) = (alpha |eps| / beta)(1 - exp(-beta t)); the discrete solution is known exactly too."""
    results = np.array([_damage(integrator, n) for n in steps])
    errors = results[:, 0]
    slope = -np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert abs(slope - order) < 0.15, (slope, errors)
    assert np.max(results[:, 1]) < 1e-14


def test_rotation_gives_rotation_matrix_and_no_strain():
    """Rigid rotation: eps = 0 so s stays 0; F converges to R(omega t) with the scheme's order."""
    mesh = dolfinx.mesh.create_rectangle(MPI.COMM_SELF, [np.array([-1.0, -1.0]), np.array([1.0, 1.0])], [6, 6])
    omega = np.pi
    u = _vector_function(mesh, 1, lambda x: np.stack([-omega * x[1], omega * x[0]]))
    errors = []
    for steps in (10, 20):
        swarm = swarm_at(mesh, [[0.3, 0.1], [-0.2, 0.4]])
        manager = PropertyManager(swarm, ["deformation_gradient", "integrated_strain"])
        manager.initialise()
        _run(swarm, manager, "rk2", u, 0.5 / steps, steps)
        assert np.max(np.abs(manager.values("integrated_strain"))) < 1e-12
        c, s = np.cos(omega * 0.5), np.sin(omega * 0.5)
        errors.append(np.max(np.abs(manager.values("deformation_gradient") - [c, -s, s, c])))
    assert 3.5 < errors[0] / errors[1] < 4.5, errors


def test_deformation_gradient_is_the_derivative_of_the_discrete_flow_map():
    """RK applied to dF/dt = grad(u) F is the derivative of the RK position map: compare with
    central differences of particles started at x0 +- delta e_j (nonlinear P2 cellular flow)."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 10, 10)
    u = _vector_function(mesh, 2, _cellular_flow)
    x0 = np.array([[0.31, 0.27], [0.62, 0.45], [0.4, 0.71]])
    delta = 1e-6
    shifts = np.array([[0, 0], [delta, 0], [-delta, 0], [0, delta], [0, -delta]])
    swarm = swarm_at(mesh, (x0[:, None, :] + shifts[None]).reshape(-1, 2))
    manager = PropertyManager(swarm, [DeformationGradient()])
    manager.initialise()
    _run(swarm, manager, "rk2", u, 0.04, 20)
    order = np.argsort(swarm.ids)
    x = swarm.x[order].reshape(3, 5, 2)
    F = manager.values("deformation_gradient")[order].reshape(3, 5, 2, 2)[:, 0]
    finite = np.stack([(x[:, 1] - x[:, 2]) / (2 * delta), (x[:, 3] - x[:, 4]) / (2 * delta)], axis=2)
    assert np.max(np.abs(F - np.eye(2))) > 0.3
    np.testing.assert_allclose(F, finite, rtol=0, atol=1e-5)  # a different scheme would differ by O(dt^2)


def test_ode_hook_with_callable_velocity():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 4, 4)
    swarm = swarm_at(mesh, [[0.2, 0.3]])
    swarm.add_property("y", 1, value=1.0)
    adv = Advector(swarm, integrator="rk4", odes=[ParticleODE("y", lambda s, c, y, g: -g[:, 0, 0:1] * y)])
    with pytest.raises(ValueError, match="velocity_gradient"):
        adv.step_callable(lambda x, t: np.zeros_like(x), 0.0, 0.1)
    # u = 0, grad u = [[k, 0], [0, 0]] with k = 1 + t: y = exp(-(t + t^2/2)); RK4 with the exact
    # time dependence keeps fourth order
    errors = []
    for steps in (10, 20):
        swarm.property("y")[:] = 1.0
        dt = 1.0 / steps
        for i in range(steps):
            adv.step_callable(lambda x, t: np.zeros_like(x), i * dt, dt,
                              velocity_gradient=lambda x, t: np.broadcast_to([[1.0 + t, 0.0], [0.0, 0.0]],
                                                                             (x.shape[0], 2, 2)))
        errors.append(abs(swarm.property("y")[0, 0] - np.exp(-1.5)))
    assert errors[0] < 1e-4 and 14 < errors[0] / errors[1] < 18, errors


# ----------------------------------------------------------------------------- sampled fields
def test_field_properties_equal_functions_at_particles():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 6, 6)
    u = _vector_function(mesh, 2, lambda x: np.stack([np.sin(3 * x[1]), np.cos(2 * x[0]) * x[1]]) * 0.1)
    T = _scalar_function(mesh, 2, lambda x: np.exp(x[0]) * np.sin(4 * x[1]))
    p = _scalar_function(mesh, 1, lambda x: x[0] * x[1] + np.cos(x[0]))
    swarm = Swarm(mesh)
    generate(swarm, plugin(RandomUniform, 60, seed=3))
    manager = PropertyManager(swarm, [Velocity(), Temperature(), Pressure()])
    with pytest.raises(ValueError, match="temperature"):
        manager.initialise(PropertyContext(u_new=u))
    ctx = PropertyContext(u_new=u, temperature=T, pressure=p)
    manager.initialise(ctx)
    for round_ in range(2):
        pts = np.zeros((swarm.num_particles, 3))
        pts[:, :2] = swarm.x
        np.testing.assert_allclose(manager.values("velocity"), u.eval(pts, swarm.cells), atol=1e-13)
        np.testing.assert_allclose(manager.values("temperature"), T.eval(pts, swarm.cells), atol=1e-13)
        np.testing.assert_allclose(manager.values("pressure"), p.eval(pts, swarm.cells), atol=1e-13)
        if round_ == 0:
            Advector(swarm, integrator="rk2").step(u, u, 0.5)
            manager.update(PropertyContext(time=0.5, dt=0.5, u_new=u, temperature=T, pressure=p))


def test_strain_rate_of_linear_field_is_exact():
    a, b, c = 0.7, -1.3, 0.4
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 5, 5)
    u = _vector_function(mesh, 1, lambda x: np.stack([a * x[0] + b * x[1], c * x[0] - a * x[1]]))
    swarm = Swarm(mesh)
    generate(swarm, plugin(RandomUniform, 40, seed=8))
    manager = PropertyManager(swarm, ["strain_rate"])
    manager.initialise(PropertyContext(u_new=u))
    eps = manager.values("strain_rate").reshape(-1, 2, 2)
    exact = np.array([[a, (b + c) / 2], [(b + c) / 2, -a]])
    np.testing.assert_allclose(eps, np.broadcast_to(exact, eps.shape), atol=1e-12)


def test_initial_composition_from_callable_and_function():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 4, 4)
    phi = _scalar_function(mesh, 1, lambda x: 2.0 * x[0] - x[1])  # linear: exact in P1
    swarm = Swarm(mesh)
    generate(swarm, plugin(RandomUniform, 30, seed=2))
    manager = PropertyManager(swarm, [
        plugin(InitialComposition, source=lambda x: (x[:, 0] > 0.5).astype(float), label="basalt"),
        plugin(InitialComposition, source=phi, label="harzburgite"),
        plugin(FunctionProperty, function=lambda x: np.stack([x[:, 0] ** 2, x[:, 1]], axis=1), label="f", components=2),
        Rank(),
    ])
    manager.initialise()
    x = swarm.x.copy()
    np.testing.assert_array_equal(manager.values("basalt")[:, 0], (x[:, 0] > 0.5).astype(float))
    np.testing.assert_allclose(manager.values("harzburgite")[:, 0], 2 * x[:, 0] - x[:, 1], atol=1e-13)
    np.testing.assert_array_equal(manager.values("f"), np.stack([x[:, 0] ** 2, x[:, 1]], axis=1))
    assert np.all(manager.values("rank") == 0)
    other = Swarm(mesh)
    generate(other, plugin(RandomUniform, 3, seed=2))
    with pytest.raises(ValueError, match="callable returned"):
        PropertyManager(other, [plugin(FunctionProperty, function=lambda x: x, label="g")]).initialise()


# ----------------------------------------------------------------------------- new particles
def _centroids(mesh):
    dofs = geometry_dofmap(mesh)
    return mesh.geometry.x[dofs][:, :, :2]


def test_initialise_new_interpolates_cell_mean_and_reinitialises():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 4, 4)
    vertices = _centroids(mesh)
    centroid = vertices.mean(axis=1)
    occupied = np.arange(10)
    old_pts = (0.6 * centroid[occupied, None, :] + 0.4 * vertices[occupied]).reshape(-1, 2)
    swarm = swarm_at(mesh, old_pts)
    assert swarm.num_particles == 30
    u = _vector_function(mesh, 1, lambda x: np.stack([x[1], -x[0]]))
    f = lambda x: x[:, 0] + 2.0 * x[:, 1] ** 2  # noqa: E731
    manager = PropertyManager(swarm, [
        plugin(FunctionProperty, function=f, label="f"),                                      # reinitialise
        plugin(InitialComposition, source=lambda x: np.ones(x.shape[0]), label="comp"),     # interpolate
        plugin(InitialComposition, source=lambda x: 5.0 + 0 * x[:, 0], label="reset", new_particles="reinitialise"),
        TimeSinceCreation(), InitialPosition(), Velocity(),
    ])
    manager.initialise(PropertyContext(u_new=u))
    manager.update(PropertyContext(time=0.3, dt=0.3, u_new=u))
    rng = np.random.default_rng(4)
    manager.values("comp")[:] = rng.random((swarm.num_particles, 1))
    manager.values("reset")[:] = -1.0
    old = {int(i): (int(c), swarm.properties[r].copy(), swarm.x[r].copy())
           for r, (i, c) in enumerate(zip(swarm.ids, swarm.cells))}

    full, empty = 3, 20  # a cell with three old particles, and one without any
    new_pts = centroid[[full, empty]]
    found = locate(mesh, new_pts, geometry=swarm.geometry)
    assert list(found.cells) == [full, empty]
    swarm.add([100, 101], new_pts, found.xref, found.cells)
    rows = np.flatnonzero(swarm.ids >= 100)
    manager.initialise_new(swarm, rows)

    comp, ipos = manager.layout("comp").start, manager.layout("initial_position").columns
    in_full = [v for c, v, _ in old.values() if c == full]
    assert len(in_full) == 3
    old_x = np.array([x for _, _, x in old.values()])
    nearest = list(old.values())[int(np.argmin(np.linalg.norm(old_x - centroid[empty], axis=1)))][1]
    for row, expected in zip(rows, [np.mean(in_full, axis=0), nearest]):
        vals = swarm.properties[row]
        assert vals[comp] == pytest.approx(expected[comp], abs=1e-15)
        np.testing.assert_allclose(vals[ipos], expected[ipos], atol=1e-15)
    r_full, r_empty = rows
    assert abs(swarm.properties[r_full, comp] - swarm.properties[r_empty, comp]) > 0  # different rules used
    np.testing.assert_allclose(manager.values("f")[rows, 0], f(new_pts), atol=1e-15)
    np.testing.assert_array_equal(manager.values("reset")[rows, 0], 5.0)
    np.testing.assert_array_equal(manager.values("time_since_creation")[rows, 0], 0.0)
    np.testing.assert_allclose(manager.values("velocity")[rows], np.stack([new_pts[:, 1], -new_pts[:, 0]], 1),
                               atol=1e-14)
    for r in np.flatnonzero(swarm.ids < 100):  # old particles untouched
        np.testing.assert_array_equal(swarm.properties[r], old[int(swarm.ids[r])][1])


# ----------------------------------------------------------------------------- MPI
@pytest.mark.mpi
def test_rank_property_after_migration():
    comm = MPI.COMM_WORLD
    mesh = dolfinx.mesh.create_unit_square(comm, 12, 12)
    u = _vector_function(mesh, 2, _cellular_flow)
    swarm = Swarm(mesh)
    generate(swarm, plugin(RandomUniform, 300, seed=5))
    manager = PropertyManager(swarm, [Rank(), InitialPosition()])
    manager.initialise(PropertyContext(u_new=u))
    ok_start = bool(np.all(manager.values("rank") == comm.rank))
    _run(swarm, manager, "rk2", u, 0.04, 10)  # update without at_output: rank is output-only
    stale = int(np.count_nonzero(manager.values("rank")[:, 0] != comm.rank))
    manager.update(PropertyContext(u_new=u), at_output=True)
    ok_end = bool(np.all(manager.values("rank") == comm.rank))
    assert comm.allreduce(ok_start and ok_end, op=MPI.LAND)
    assert comm.allreduce(stale, op=MPI.SUM) > 0  # particles did change rank
    assert swarm.global_num_particles() == 300


def _ode_run(comm, integrator):
    mesh = dolfinx.mesh.create_unit_square(comm, 12, 12)
    u = _vector_function(mesh, 2, _cellular_flow)
    swarm = Swarm(mesh)
    generate(swarm, plugin(RandomUniform, 200, seed=11))
    manager = PropertyManager(swarm, [DeformationGradient(), IntegratedStrain(), plugin(Damage, alpha=1.0, beta=0.5)])
    manager.initialise(PropertyContext(u_new=u))
    adv = Advector(swarm, integrator=integrator, odes=manager.odes())
    sent = 0
    for _ in range(30):
        sent += adv.step(u, u, 0.04).sent
    ids = np.concatenate(comm.allgather(swarm.ids))
    props = np.concatenate(comm.allgather(swarm.properties))
    order = np.argsort(ids)
    return ids[order], props[order], comm.allreduce(sent, op=MPI.SUM)


@pytest.mark.mpi
@pytest.mark.parametrize("integrator", ["rk2", "rk4"])
def test_ode_properties_across_ranks_match_serial(integrator, monkeypatch):
    import particles.advection.advector

    comm = MPI.COMM_WORLD
    sent_per_move = []
    migrate = particles.advection.advector._migrate

    def counting_migrate(swarm):
        counts = migrate(swarm)
        sent_per_move.append(counts[0])
        return counts

    monkeypatch.setattr(particles.advection.advector, "_migrate", counting_migrate)
    ids, props, sent = _ode_run(comm, integrator)
    stages = {"rk2": 2, "rk4": 4}[integrator]
    mid_step = sum(c for i, c in enumerate(sent_per_move) if i % stages != stages - 1)
    ref_ids, ref_props, _ = _ode_run(MPI.COMM_SELF, integrator)
    assert sent > 0
    assert comm.allreduce(mid_step, op=MPI.SUM) > 0  # particles changed rank between stages
    np.testing.assert_array_equal(ids, np.arange(200))
    np.testing.assert_array_equal(ref_ids, ids)
    np.testing.assert_allclose(props, ref_props, rtol=0, atol=1e-12)
    F = ref_props[:, :4].reshape(-1, 2, 2)
    assert np.max(np.abs(F - np.eye(2))) > 0.5  # the flow really deformed the particles
