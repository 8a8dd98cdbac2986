"""The stress update of ``elastic_stress`` as one compiled loop over particles (issue 48, the cost):
``tau <- 2 eta_ve eps + chi R tau R^T`` on affine triangles with a P2 velocity and ``eta_ve``,
``chi`` of degree 0 or 1 (discontinuous), where the vectorised path spent 6 times the rest of the
particle time (tabulating bases, gathering and contracting with einsum, then the rotation).

The same arithmetic as :meth:`particles.properties.elastic_stress.ElasticStress.refresh` written
per particle: the velocity's gradient ``L = (dphi_i / dX) u_i K`` from the P2 basis in barycentric
coordinates (basix order, as :func:`fembase.kernels.evaluate_simplex_p12`), ``eta_ve`` and ``chi``
at the particle, and the rotation ``R = exp(dt W)``, in 2D ``[[cos a, sin a], [-sin a, cos a]]``
with ``a = dt (L_01 - L_10) / 2`` (Rodrigues' formula for a 2 x 2 spin). The results equal the
vectorised path's to round-off (tests/particles/properties/test_elastic_stress.py).
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

from particles.properties._base import EvaluatorCache
from particles.storage.swarm import Swarm

__all__ = ["fast_update", "update_triangles"]


@numba.njit(cache=True)
def update_triangles(cells, xref, u_dofs, u, K, f_dofs, eta_ve, chi, dt, stress, start):  # pragma: no cover
    """Update the stress columns ``stress[:, start:start + 3]`` (xx, yy, xy) in place.

    Args:
        cells: shape=(n,), int32 (all >= 0). xref: shape=(n, 2).
        u_dofs: the velocity's cell dofs (blocks), shape=(ncells, 6). u: its values, shape=(2 num_dofs,).
        K: the inverse Jacobians ``dX/dx``, shape=(ncells, 2, 2).
        f_dofs: the cell dofs of ``eta_ve`` and ``chi``, shape=(ncells, 1 or 3) (DG0 or DG1).
        eta_ve, chi: their values. dt: the step. stress: the property table, shape=(n, ncols).
    """
    linear = f_dofs.shape[1] == 3
    for p in range(cells.shape[0]):
        c = cells[p]
        X = xref[p, 0]
        Y = xref[p, 1]
        L = 1.0 - X - Y
        # d phi_i / dX, d phi_i / dY of the P2 basis (vertices 0, 1, 2; edges (1, 2), (0, 2), (0, 1))
        a0 = 1.0 - 4.0 * L
        gx1, gy2 = 4.0 * X - 1.0, 4.0 * Y - 1.0
        gx3, gy3 = 4.0 * Y, 4.0 * X
        gx4, gy4 = -4.0 * Y, 4.0 * (L - Y)
        gx5, gy5 = 4.0 * (L - X), -4.0 * X
        d0, d1, d2 = 2 * u_dofs[c, 0], 2 * u_dofs[c, 1], 2 * u_dofs[c, 2]
        d3, d4, d5 = 2 * u_dofs[c, 3], 2 * u_dofs[c, 4], 2 * u_dofs[c, 5]
        ux_X = a0 * u[d0] + gx1 * u[d1] + gx3 * u[d3] + gx4 * u[d4] + gx5 * u[d5]
        ux_Y = a0 * u[d0] + gy2 * u[d2] + gy3 * u[d3] + gy4 * u[d4] + gy5 * u[d5]
        uy_X = a0 * u[d0 + 1] + gx1 * u[d1 + 1] + gx3 * u[d3 + 1] + gx4 * u[d4 + 1] + gx5 * u[d5 + 1]
        uy_Y = a0 * u[d0 + 1] + gy2 * u[d2 + 1] + gy3 * u[d3 + 1] + gy4 * u[d4 + 1] + gy5 * u[d5 + 1]
        l00 = ux_X * K[c, 0, 0] + ux_Y * K[c, 1, 0]
        l01 = ux_X * K[c, 0, 1] + ux_Y * K[c, 1, 1]
        l10 = uy_X * K[c, 0, 0] + uy_Y * K[c, 1, 0]
        l11 = uy_X * K[c, 0, 1] + uy_Y * K[c, 1, 1]
        if linear:
            e0, e1, e2 = f_dofs[c, 0], f_dofs[c, 1], f_dofs[c, 2]
            viscosity = L * eta_ve[e0] + X * eta_ve[e1] + Y * eta_ve[e2]
            memory = L * chi[e0] + X * chi[e1] + Y * chi[e2]
        else:
            viscosity = eta_ve[f_dofs[c, 0]]
            memory = chi[f_dofs[c, 0]]
        angle = 0.5 * dt * (l01 - l10)
        cs, sn = math.cos(angle), math.sin(angle)
        txx, tyy, txy = stress[p, start], stress[p, start + 1], stress[p, start + 2]
        # R tau R^T with R = [[cs, sn], [-sn, cs]]
        rxx = cs * cs * txx + 2.0 * cs * sn * txy + sn * sn * tyy
        ryy = sn * sn * txx - 2.0 * cs * sn * txy + cs * cs * tyy
        rxy = (cs * cs - sn * sn) * txy + cs * sn * (tyy - txx)
        stress[p, start] = 2.0 * viscosity * l00 + memory * rxx
        stress[p, start + 1] = 2.0 * viscosity * l11 + memory * ryy
        stress[p, start + 2] = viscosity * (l01 + l10) + memory * rxy


def fast_update(swarm: Swarm, functions: tuple[Any, Any, Any], evaluators: EvaluatorCache, dt: float, start: int, /
                ) -> bool:
    """Run :func:`update_triangles` on every particle of ``swarm`` when it applies (affine triangles,
    a P2 velocity, ``eta_ve`` and ``chi`` of degree 0 or 1 with the same dofmap, no discarded
    particle); whether it ran. ``functions``: the velocity, ``eta_ve`` and ``chi``; ``start``: the
    first stress column of ``swarm.properties``."""
    velocity, eta, chi = (evaluators.get(swarm, f.function_space) for f in functions)
    geometry = velocity.geometry
    if not (geometry.affine and geometry.tdim == 2 and geometry.gdim == 2 and velocity.bs == 2
            and velocity.element.degree == 2 and not velocity.element.discontinuous and eta.bs == chi.bs == 1
            and eta.element.degree <= 1 and eta.dofs.shape[1] == (3 if eta.element.degree == 1 else 1)
            and (eta.dofs is chi.dofs or np.array_equal(eta.dofs, chi.dofs))):
        return False
    n = swarm.num_particles
    cells = np.ascontiguousarray(swarm.cells[:n], dtype=np.int32)
    if n == 0 or cells.min() < 0 or not swarm.properties.flags.c_contiguous:
        return False
    update_triangles(cells, np.ascontiguousarray(swarm.xref[:n], dtype=np.float64), velocity.dofs,
                     functions[0].x.array, geometry.K, eta.dofs, functions[1].x.array, functions[2].x.array,
                     float(dt), swarm.properties, int(start))
    return True
