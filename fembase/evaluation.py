"""Evaluate DOLFINx Functions and their gradients at particles (seed paper section 2.5).

Particles store their cell and reference coordinates, so no search is needed: the basis is
tabulated at ``xref`` with basix, the cell's DOF values are gathered through the dofmap and
contracted,

    u(x_p) = sum_i phi_i(X_p) u_{dofs(K_p, i)},
    grad u(x_p) = sum_i u_{dofs(K_p, i)} (d phi_i / dX)(X_p) K(X_p),

with ``K = dX/dx`` the (pseudo-)inverse Jacobian of the cell map. Lagrange P1/P2 on simplices use
a compiled kernel (:func:`fembase.kernels.evaluate_simplex_p12`); everything else the vectorised
basix path. DOLFINx permutes the dofmap of Lagrange elements so that no dof transformation is
needed (``V.element.needs_dof_transformations`` is False); elements that would need one are
rejected.

:func:`locate` (bounding-box search + pull-back) is re-exported from :mod:`fembase.geometry`.
"""

from __future__ import annotations

import basix
import numpy as np
import numpy.typing as npt

import dolfinx.fem

from fembase.dolfinx_compat import cell_dofmap
from fembase.geometry import CellGeometry, Located, locate
from fembase.kernels import evaluate_simplex_p12

__all__ = ["Evaluator", "Located", "evaluate", "evaluate_gradient", "locate"]


class Evaluator:
    """Point evaluation of Functions of one function space at particles.

    Args:
        V: A DOLFINx function space with an identity-mapped scalar or blocked element
            (Lagrange / DG of any degree, scalar or vector).
        geometry: The :class:`CellGeometry` of ``V.mesh``; built if omitted.

    Attributes:
        value_size: Number of value components (the block size).
        fast: Whether values use the compiled P1/P2 simplex kernel.
    """

    def __init__(self, V: dolfinx.fem.FunctionSpace, /, *, geometry: CellGeometry | None = None) -> None:
        self.V = V
        mesh = V.mesh
        self.geometry = geometry if geometry is not None else CellGeometry(mesh)
        element = V.element.basix_element
        if element.map_type != basix.MapType.identity or element.value_size != 1:
            raise NotImplementedError("only identity-mapped scalar or blocked elements are supported")
        if V.element.needs_dof_transformations:
            raise NotImplementedError("elements that need DOF transformations are not supported")
        self.element = element
        self.bs: int = V.dofmap.bs
        self.value_size: int = self.bs
        ncells = self.geometry.num_local_cells
        self.dofs = np.ascontiguousarray(cell_dofmap(V)[:ncells], dtype=np.int32)
        self.fast: bool = (
            self.geometry.simplex
            and self.geometry.tdim in (2, 3)
            and element.family == basix.ElementFamily.P
            and element.degree in (1, 2)
            and not element.discontinuous
        )

    def _coefficients(self, u: dolfinx.fem.Function) -> npt.NDArray[np.float64]:
        W = u.function_space
        same = W is self.V or (W.mesh is self.V.mesh and W.ufl_element() == self.V.ufl_element())
        if not same:
            raise ValueError("Function is not in this evaluator's function space")
        return u.x.array

    def values(
        self,
        u: dolfinx.fem.Function,
        cells: npt.NDArray[np.int32],
        xref: npt.NDArray[np.float64],
        *,
        out: npt.NDArray[np.float64] | None = None,
        alpha: float = 1.0,
        beta: float = 0.0,
    ) -> npt.NDArray[np.float64]:
        """Values of ``u`` at particles, optionally accumulated: ``out = beta * out + alpha * u``.

        Args:
            u: Function in ``V``.
            cells: Local cells, shape=(n,), int32; rows with cells < 0 (discarded particles)
                get unspecified values (the compiled kernel leaves ``out`` unchanged there).
            xref: Reference coordinates, shape=(n, tdim).
            out: Result array, shape=(n, value_size), C-contiguous float64 (allocated if None).
            alpha: Scale of the values.
            beta: Scale of the old ``out`` (0: overwritten). E.g. an Euler push in place is
                ``values(u, cells, xref, out=x, alpha=dt, beta=1)``.

        Returns:
            ``out``, shape=(n, value_size), float64.
        """
        coeffs = self._coefficients(u)
        n = cells.shape[0]
        if out is None:
            out = np.empty((n, self.bs), dtype=np.float64)
            beta = 0.0
        elif out.shape != (n, self.bs) or out.dtype != np.float64 or not out.flags.c_contiguous:
            raise ValueError(f"out must be a C-contiguous float64 array of shape {(n, self.bs)}")
        if n == 0:
            return out
        if self.fast:
            evaluate_simplex_p12(
                np.ascontiguousarray(cells, dtype=np.int32), np.ascontiguousarray(xref, dtype=np.float64),
                self.dofs, coeffs, self.bs, self.element.degree, float(alpha), float(beta), out,
            )
            return out
        phi = self.element.tabulate(0, np.ascontiguousarray(xref, dtype=np.float64))[0, :, :, 0]
        local = coeffs.reshape(-1, self.bs)[self.dofs[np.maximum(cells, 0)]]
        vals = np.einsum("nd,ndb->nb", phi, local)
        if beta == 0.0:
            np.multiply(vals, alpha, out=out)
        else:
            out *= beta
            out += alpha * vals
        return out

    def gradients(
        self, u: dolfinx.fem.Function, cells: npt.NDArray[np.int32], xref: npt.NDArray[np.float64]
    ) -> npt.NDArray[np.float64]:
        """Gradients of ``u`` at particles, ``out[p, i, j] = d u_i / d x_j``.

        Args:
            u: Function in ``V``.
            cells: Local cells (>= 0), shape=(n,), int32.
            xref: Reference coordinates, shape=(n, tdim).

        Returns:
            shape=(n, value_size, gdim), float64.
        """
        coeffs = self._coefficients(u)
        xref = np.ascontiguousarray(xref, dtype=np.float64)
        n = cells.shape[0]
        gdim = self.geometry.gdim
        if n == 0:
            return np.empty((0, self.bs, gdim), dtype=np.float64)
        cells = np.maximum(cells, 0)  # (discarded rows, cells < 0: values unspecified)
        dphi = self.element.tabulate(1, xref)[1:, :, :, 0]
        local = coeffs.reshape(-1, self.bs)[self.dofs[cells]]
        ref_grad = np.einsum("tnd,ndb->nbt", dphi, local)
        if self.geometry.affine:
            K = self.geometry.K[cells]
        else:
            K = np.linalg.pinv(self.geometry.jacobians(cells, xref))
        return np.einsum("nbt,ntg->nbg", ref_grad, K)


def evaluate(
    u: dolfinx.fem.Function, cells: npt.NDArray[np.int32], xref: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """Values of ``u`` at reference points ``xref`` (n, tdim) of local ``cells`` (n,); (n, value_size)."""
    return Evaluator(u.function_space).values(u, cells, xref)


def evaluate_gradient(
    u: dolfinx.fem.Function, cells: npt.NDArray[np.int32], xref: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """Gradients of ``u`` at reference points ``xref`` of local ``cells``; (n, value_size, gdim)."""
    return Evaluator(u.function_space).gradients(u, cells, xref)
