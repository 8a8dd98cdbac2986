"""The elastic stress history as mesh fields (``physics.elasticity.stress: fields``, issue 48), as
ASPECT carries it in compositional fields: one continuous Lagrange field per stored component
(:func:`convection.physics.elasticity.stress_labels`), the old stress ``tau^n`` the Stokes forms read.

One step of length ``dt`` (:class:`FieldStress`, the model calls it):

1. :meth:`FieldStress.advance`: each component is advected with the material's velocity (relative
   to the mesh on a moving mesh) by the composition fields' transport solver
   (:class:`convection.solvers.transport.TransportSolver`: SUPG, variable-step BDF2, no diffusion);
2. :meth:`FieldStress.update`, after the flow solve: ``tau <- 2 eta_ve eps(u) + chi R tau R^T``
   (``R = exp(dt W)``, :func:`convection.physics.elasticity.rotated`; with a fixed ``dt_e`` the
   averaged factors of :meth:`convection.physics.elasticity.Elasticity.update_factors`), the
   particles' update, made a field by an L2 projection onto the fields' space. The projection, not
   an interpolation: the expression is discontinuous between cells (``grad u``), and an interpolated
   shared node would take the value of whichever of its cells came last, which depends on the
   partition. The same change is added to the transport's history (``T_old``), so that BDF2 advects
   the updated stress and a uniform stress in a uniform flow stays uniform (the history otherwise
   holds the stress before the update, and BDF2 would extrapolate the update as a time derivative).

The fields are carried to a new mesh like composition fields and kept in checkpoints.
"""

from __future__ import annotations

from typing import Any, ClassVar, NamedTuple

import dolfinx.fem
import dolfinx.fem.petsc
import dolfinx.mesh
import numpy as np
import ufl
from petsc4py import PETSc

from convection.model.composition import Transfer, TransportedFields
from convection.model.rheology_fields import Flow
from convection.physics.elasticity import STRESS_COMPONENTS, Elasticity, ElasticitySettings, rotated, stress_labels
from convection.solvers.transport import TransportSolver
from fembase.dolfinx_compat import create_vector, petsc_vector

__all__ = ["FieldStress", "StressContext"]


class StressContext(NamedTuple):
    """What the stress fields are made from, beside ``physics.elasticity``.

    Attributes:
        mesh: The model's mesh.
        approximation: The physics, with its elasticity.
        stabilisation: The advection's stabilisation (``energy.stabilisation``).
    """

    mesh: dolfinx.mesh.Mesh
    approximation: Any
    stabilisation: str


class FieldStress(TransportedFields):
    """The stress history as advected mesh fields (module docstring). All methods are collective.

    Args:
        mesh: The mesh.
        approximation: The physics (the transport solvers need it; no heating is applied).
        elasticity: The Maxwell elasticity (its update factors).
        degree: The fields' Lagrange degree (>= 1).
        stabilisation: The advection's stabilisation (``energy.stabilisation``).
    """

    name: ClassVar[str] = "fields"
    description: ClassVar[str] = "the stress history as advected mesh fields"
    Settings: ClassVar[type] = ElasticitySettings

    @classmethod
    def build(cls, settings: ElasticitySettings, context: StressContext, /) -> FieldStress:
        """The fields of ``physics.elasticity`` (its ``stress_degree``) on the context's mesh."""
        elasticity = context.approximation.elasticity
        assert elasticity is not None, "the stress fields need elasticity"
        return cls(context.mesh, context.approximation, elasticity, degree=settings.stress_degree,
                   stabilisation=context.stabilisation)

    def __init__(self, mesh: dolfinx.mesh.Mesh, approximation: Any, elasticity: Elasticity, /, *, degree: int = 2,
                 stabilisation: str = "supg") -> None:
        self.elasticity = elasticity
        self.solvers = [TransportSolver(mesh, approximation, bcs={}, degree=degree, stabilisation=stabilisation,
                                        diffusivity=0.0, heating=False, name=label, velocity_extrapolation=False)
                        for label in stress_labels(mesh.geometry.dim)]
        for solver in self.solvers:
            solver.set_initial(lambda x: np.zeros(x.shape[1]))
        self._projection: _Projection | None = None

    @property
    def fields(self) -> dict[str, dolfinx.fem.Function]:
        """The old stress's components by label (the Stokes forms read them)."""
        return {s.name: s.T for s in self.solvers}

    def update(self, flow: Flow, dt: float, /) -> None:
        """``tau <- 2 eta_ve eps + chi R tau R^T`` for the flow just solved and the step ``dt`` (0: the
        flow before the first step, nothing changes)."""
        if dt <= 0.0:
            return
        key = (flow.stokes, *(id(f) for f in flow.fields.values()), *(id(f) for f in flow.fractions or ()))
        if self._projection is None or self._projection.key != key:
            self._forget_projection()
            self._projection = _Projection(self, flow, key)
        new = self._projection.solve(dt)
        for solver, values in zip(self.solvers, new):
            change = values - solver.T.x.array
            for f in (solver.T, solver.T_old, solver.T_old2):  # the history moves with the update
                f.x.array[:] += change

    def to_mesh(self, mesh: dolfinx.mesh.Mesh, transfer: Transfer, /) -> None:
        """Carry the fields and their transport history to ``mesh`` (the projection is made again there)."""
        super().to_mesh(mesh, transfer)
        self._forget_projection()

    def destroy(self) -> None:
        super().destroy()
        self._forget_projection()

    def _forget_projection(self) -> None:
        if self._projection is not None:
            self._projection.destroy()
            self._projection = None


class _Projection:
    """The L2 projection of the updated stress onto the fields' space: the mass matrix (assembled at
    every solve: a free surface moves the mesh) and one right-hand side per component."""

    def __init__(self, stress: FieldStress, flow: Flow, key: tuple, /) -> None:
        self.key = key
        stokes = flow.stokes
        discretisation = stokes.discretisation
        mesh = stokes.mesh
        gdim = mesh.geometry.dim
        space = stress.solvers[0].V
        self.dt = dolfinx.fem.Constant(mesh, PETSc.ScalarType(0.0))
        eta = discretisation.maxwell_viscosity(flow.T, flow.fractions, {"u": stokes.u, "p": stokes.p,
                                                                         "fields": flow.fields})
        eta_ve, chi = stress.elasticity.update_factors(eta, flow.fractions, discretisation.elastic_rate,
                                                       discretisation.elastic_share)
        L = ufl.grad(stokes.u)
        old = Elasticity.stress(stress.fields, gdim)
        new = 2.0 * eta_ve * ufl.sym(L) + chi * rotated(old, L, self.dt)
        trial, test = ufl.TrialFunction(space), ufl.TestFunction(space)
        degree = stress.solvers[0].degree
        dx = ufl.dx(domain=mesh, metadata={"quadrature_degree": 3 * degree})
        self.a = dolfinx.fem.form(trial * test * dx)
        self.L = [dolfinx.fem.form(new[i, j] * test * dx) for i, j in STRESS_COMPONENTS[gdim]]
        self.A = dolfinx.fem.petsc.create_matrix(self.a)
        self.b = create_vector(self.L[0])
        self.x = dolfinx.fem.Function(space)
        self.ksp = PETSc.KSP().create(mesh.comm)
        self.ksp.setOperators(self.A)
        self.ksp.setType("cg")
        self.ksp.getPC().setType("jacobi")
        self.ksp.setTolerances(rtol=1.0e-13, atol=1.0e-300, max_it=1000)

    def solve(self, dt: float, /) -> list[np.ndarray]:
        """The projected new stress, one array per component (local and ghost values)."""
        self.dt.value = dt
        self.A.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(self.A, self.a)
        self.A.assemble()
        out = []
        for L in self.L:  # every right-hand side first: they read the old stress
            with self.b.localForm() as local:
                local.set(0.0)
            dolfinx.fem.petsc.assemble_vector(self.b, L)
            self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
            self.x.x.array[:] = 0.0
            self.ksp.solve(self.b, petsc_vector(self.x))
            if self.ksp.getConvergedReason() < 0:
                raise RuntimeError(f"the stress projection did not converge (PETSc reason "
                                   f"{self.ksp.getConvergedReason()})")
            self.x.x.scatter_forward()
            out.append(self.x.x.array.copy())
        return out

    def destroy(self) -> None:
        for obj in (self.ksp, self.A, self.b):
            obj.destroy()
