"""The stress update of ``elastic_stress`` as one compiled loop over particles (issue 48, the cost):
``tau <- 2 eta_ve eps + chi R tau R^T`` on affine triangles and tetrahedra with a P2 velocity and ``eta_ve``,
``chi`` of degree 0 or 1 (discontinuous), where the vectorised path spent 6 times the rest of the
particle time (tabulating bases, gathering and contracting with einsum, then the rotation).

The same arithmetic as :meth:`particles.properties.elastic_stress.ElasticStress.refresh` written
per particle: the velocity's gradient ``L = (dphi_i / dX) u_i K`` from the P2 basis in barycentric
coordinates (basix order, as :func:`fembase.kernels.evaluate_simplex_p12`), ``eta_ve`` and ``chi``
at the particle, and the rotation ``R = exp(dt W)``, in 2D ``[[cos a, sin a], [-sin a, cos a]]``
with ``a = dt (L_01 - L_10) / 2`` (Rodrigues' formula for a 2 x 2 spin), in 3D Rodrigues' formula
for a 3 x 3 spin (:func:`update_tetrahedra`). The results equal the
vectorised path's to round-off (tests/particles/properties/test_elastic_stress.py).
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

from particles.properties._base import EvaluatorCache
from particles.storage.swarm import Swarm

__all__ = ["fast_update", "update_tetrahedra", "update_triangles"]


@numba.njit(cache=True)
def update_triangles(cells, xref, u_dofs, u, K, f_dofs, eta_ve, chi, dt, stress, start):  # pragma: no cover
    """Update the stress columns ``stress[:, start:start + 3]`` (xx, yy, xy) in place.

    A P2 velocity's gradient is linear on an affine triangle: ``L = L_0 + X L_X + Y L_Y`` in the
    reference coordinates ``(X, Y)``. The three matrices are made once per run of particles in the
    same cell (the swarm is sorted by cell) from its velocity dofs and inverse Jacobian, with its
    ``eta_ve`` and ``chi`` values; a particle then needs 8 products for ``L``. The rotation by
    ``a = dt (L_01 - L_10) / 2`` takes ``sin a`` and ``cos a = sqrt(1 - sin^2 a)`` (``|a| < 1``; beyond, ``cos``).

    Args:
        cells: shape=(n,), int32 (all >= 0). xref: shape=(n, 2).
        u_dofs: the velocity's cell dofs (blocks), shape=(ncells, 6). u: its values, shape=(2 num_dofs,).
        K: the inverse Jacobians ``dX/dx``, shape=(ncells, 2, 2).
        f_dofs: the cell dofs of ``eta_ve`` and ``chi``, shape=(ncells, 1 or 3) (DG0 or DG1).
        eta_ve, chi: their values. dt: the step. stress: the property table, shape=(n, ncols).
    """
    linear = f_dofs.shape[1] == 3
    U = np.zeros((6, 2))
    R = np.zeros((3, 2, 2))  # d u_i / d X, d u_i / d Y: constant, X and Y parts
    G = np.zeros((3, 2, 2))  # L_0, L_X, L_Y
    E = np.zeros(3)
    C = np.zeros(3)
    last = -1
    for p in range(cells.shape[0]):
        c = cells[p]
        if c != last:  # a new cell: its gradient's three parts (basix order: vertices 0, 1, 2; edges 12, 02, 01)
            for k in range(6):
                d = 2 * u_dofs[c, k]
                U[k, 0] = u[d]
                U[k, 1] = u[d + 1]
            for i in range(2):
                R[0, i, 0] = -3.0 * U[0, i] - U[1, i] + 4.0 * U[5, i]
                R[1, i, 0] = 4.0 * (U[0, i] + U[1, i]) - 8.0 * U[5, i]
                R[2, i, 0] = 4.0 * (U[0, i] + U[3, i] - U[4, i] - U[5, i])
                R[0, i, 1] = -3.0 * U[0, i] - U[2, i] + 4.0 * U[4, i]
                R[1, i, 1] = 4.0 * (U[0, i] + U[3, i] - U[4, i] - U[5, i])
                R[2, i, 1] = 4.0 * (U[0, i] + U[2, i]) - 8.0 * U[4, i]
            for m in range(3):
                for i in range(2):
                    for j in range(2):
                        G[m, i, j] = R[m, i, 0] * K[c, 0, j] + R[m, i, 1] * K[c, 1, j]
            for k in range(f_dofs.shape[1]):
                E[k] = eta_ve[f_dofs[c, k]]
                C[k] = chi[f_dofs[c, k]]
            last = c
        X = xref[p, 0]
        Y = xref[p, 1]
        l00 = G[0, 0, 0] + X * G[1, 0, 0] + Y * G[2, 0, 0]
        l01 = G[0, 0, 1] + X * G[1, 0, 1] + Y * G[2, 0, 1]
        l10 = G[0, 1, 0] + X * G[1, 1, 0] + Y * G[2, 1, 0]
        l11 = G[0, 1, 1] + X * G[1, 1, 1] + Y * G[2, 1, 1]
        if linear:
            L = 1.0 - X - Y
            viscosity = L * E[0] + X * E[1] + Y * E[2]
            memory = L * C[0] + X * C[1] + Y * C[2]
        else:
            viscosity = E[0]
            memory = C[0]
        angle = 0.5 * dt * (l01 - l10)
        sn = math.sin(angle)
        cs = math.sqrt(1.0 - sn * sn) if abs(angle) < 1.0 else math.cos(angle)
        txx, tyy, txy = stress[p, start], stress[p, start + 1], stress[p, start + 2]
        # R tau R^T with R = [[cs, sn], [-sn, cs]]
        rxx = cs * cs * txx + 2.0 * cs * sn * txy + sn * sn * tyy
        ryy = sn * sn * txx - 2.0 * cs * sn * txy + cs * cs * tyy
        rxy = (cs * cs - sn * sn) * txy + cs * sn * (tyy - txx)
        stress[p, start] = 2.0 * viscosity * l00 + memory * rxx
        stress[p, start + 1] = 2.0 * viscosity * l11 + memory * ryy
        stress[p, start + 2] = viscosity * (l01 + l10) + memory * rxy


@numba.njit(cache=True)
def _tetrahedron_gradients(X, Y, Z, g):  # pragma: no cover
    """``g[k] = (d phi_k / dX, dY, dZ)`` of the P2 basis on the reference tetrahedron at ``(X, Y, Z)``
    (basix order: vertices 0-3, then edges (2, 3), (1, 3), (1, 2), (0, 3), (0, 2), (0, 1))."""
    L = 1.0 - X - Y - Z
    a0 = 1.0 - 4.0 * L
    g[0, 0], g[0, 1], g[0, 2] = a0, a0, a0
    g[1, 0], g[1, 1], g[1, 2] = 4.0 * X - 1.0, 0.0, 0.0
    g[2, 0], g[2, 1], g[2, 2] = 0.0, 4.0 * Y - 1.0, 0.0
    g[3, 0], g[3, 1], g[3, 2] = 0.0, 0.0, 4.0 * Z - 1.0
    g[4, 0], g[4, 1], g[4, 2] = 0.0, 4.0 * Z, 4.0 * Y
    g[5, 0], g[5, 1], g[5, 2] = 4.0 * Z, 0.0, 4.0 * X
    g[6, 0], g[6, 1], g[6, 2] = 4.0 * Y, 4.0 * X, 0.0
    g[7, 0], g[7, 1], g[7, 2] = -4.0 * Z, -4.0 * Z, 4.0 * (L - Z)
    g[8, 0], g[8, 1], g[8, 2] = -4.0 * Y, 4.0 * (L - Y), -4.0 * Y
    g[9, 0], g[9, 1], g[9, 2] = 4.0 * (L - X), -4.0 * X, -4.0 * X


@numba.njit(cache=True)
def update_tetrahedra(cells, xref, u_dofs, u, K, f_dofs, eta_ve, chi, dt, stress, start):  # pragma: no cover
    """Update the stress columns ``stress[:, start:start + 6]`` (xx, yy, zz, xy, xz, yz) in place; the
    arguments as :func:`update_triangles` (``xref`` shape=(n, 3), ``u_dofs`` shape=(ncells, 10), ``K``
    shape=(ncells, 3, 3), ``f_dofs`` shape=(ncells, 1 or 4)). The rotation ``R = I + a S + b S^2``,
    ``S = dt W``, ``theta = sqrt(S : S / 2)``, ``a = sin(theta) / theta``, ``b = (1 - cos(theta)) / theta^2``
    (Rodrigues' formula)."""
    linear = f_dofs.shape[1] == 4
    U = np.zeros((10, 3))
    Kc = np.zeros((3, 3))
    E = np.zeros(4)
    C = np.zeros(4)
    g = np.zeros((10, 3))
    G = np.zeros((3, 3))
    Lg = np.zeros((3, 3))
    S = np.zeros((3, 3))
    R = np.zeros((3, 3))
    T = np.zeros((3, 3))
    M = np.zeros((3, 3))
    voigt = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
    last = -1
    for p in range(cells.shape[0]):
        c = cells[p]
        if c != last:  # a new cell: gather its values
            for k in range(10):
                d = 3 * u_dofs[c, k]
                for i in range(3):
                    U[k, i] = u[d + i]
            for i in range(3):
                for j in range(3):
                    Kc[i, j] = K[c, i, j]
            for k in range(f_dofs.shape[1]):
                E[k] = eta_ve[f_dofs[c, k]]
                C[k] = chi[f_dofs[c, k]]
            last = c
        X, Y, Z = xref[p, 0], xref[p, 1], xref[p, 2]
        _tetrahedron_gradients(X, Y, Z, g)
        for i in range(3):  # G[i, m] = d u_i / d X_m
            for m in range(3):
                acc = 0.0
                for k in range(10):
                    acc += g[k, m] * U[k, i]
                G[i, m] = acc
        for i in range(3):  # L = d u_i / d x_j
            for j in range(3):
                Lg[i, j] = G[i, 0] * Kc[0, j] + G[i, 1] * Kc[1, j] + G[i, 2] * Kc[2, j]
        if linear:
            L = 1.0 - X - Y - Z
            viscosity = L * E[0] + X * E[1] + Y * E[2] + Z * E[3]
            memory = L * C[0] + X * C[1] + Y * C[2] + Z * C[3]
        else:
            viscosity = E[0]
            memory = C[0]
        squared = 0.0
        for i in range(3):
            for j in range(3):
                S[i, j] = 0.5 * dt * (Lg[i, j] - Lg[j, i])
                squared += S[i, j] * S[i, j]
        theta = math.sqrt(0.5 * squared)
        if theta > 1e-8:
            a = math.sin(theta) / theta
            b = (1.0 - math.cos(theta)) / (theta * theta)
        else:  # the series, exact to round-off
            a = 1.0 - theta * theta / 6.0
            b = 0.5 - theta * theta / 24.0
        for i in range(3):
            for j in range(3):
                s2 = S[i, 0] * S[0, j] + S[i, 1] * S[1, j] + S[i, 2] * S[2, j]
                R[i, j] = (1.0 if i == j else 0.0) + a * S[i, j] + b * s2
        for k in range(6):
            i, j = voigt[k]
            T[i, j] = T[j, i] = stress[p, start + k]
        for i in range(3):  # M = R T
            for j in range(3):
                M[i, j] = R[i, 0] * T[0, j] + R[i, 1] * T[1, j] + R[i, 2] * T[2, j]
        for k in range(6):  # (M R^T)_ij, the strain rate (L + L^T) / 2
            i, j = voigt[k]
            rotated = M[i, 0] * R[j, 0] + M[i, 1] * R[j, 1] + M[i, 2] * R[j, 2]
            stress[p, start + k] = viscosity * (Lg[i, j] + Lg[j, i]) + memory * rotated


def fast_update(swarm: Swarm, functions: tuple[Any, Any, Any], evaluators: EvaluatorCache, dt: float, start: int, /
                ) -> bool:
    """Run :func:`update_triangles` (2D) or :func:`update_tetrahedra` (3D) on every particle of
    ``swarm`` when it applies (affine simplices, a P2 velocity, ``eta_ve`` and ``chi`` of degree 0 or 1
    with the same dofmap, no discarded particle); whether it ran. ``functions``: the velocity,
    ``eta_ve`` and ``chi``; ``start``: the first stress column of ``swarm.properties``."""
    velocity, eta, chi = (evaluators.get(swarm, f.function_space) for f in functions)
    geometry = velocity.geometry
    dim = geometry.tdim
    if not (geometry.affine and dim in (2, 3) and geometry.gdim == dim and velocity.bs == dim
            and velocity.element.degree == 2 and not velocity.element.discontinuous and eta.bs == chi.bs == 1
            and eta.element.degree <= 1 and eta.dofs.shape[1] == (dim + 1 if eta.element.degree == 1 else 1)
            and (eta.dofs is chi.dofs or np.array_equal(eta.dofs, chi.dofs))):
        return False
    n = swarm.num_particles
    cells = np.ascontiguousarray(swarm.cells[:n], dtype=np.int32)
    if n == 0 or cells.min() < 0 or not swarm.properties.flags.c_contiguous:
        return False
    update = update_triangles if dim == 2 else update_tetrahedra
    update(cells, np.ascontiguousarray(swarm.xref[:n], dtype=np.float64), velocity.dofs, functions[0].x.array,
           geometry.K, eta.dofs, functions[1].x.array, functions[2].x.array, float(dt), swarm.properties, int(start))
    return True
