"""Closed-form initial conditions written in configs, e.g. ``"1 - z + 0.01*cos(pi*x)*sin(pi*z)"``.

Expressions are parsed with :mod:`ast` and may use only the coordinates ``x, y, z``, the constants
``pi`` and ``e``, user constants given in the config, arithmetic, comparisons (which give 0/1), and
the functions in :data:`FUNCTIONS`. The vertical coordinate is always ``z``: in 2D, where DOLFINx
names the coordinates (x, y), ``z`` is the same as ``y`` (so ``"1 - z"`` is conductive in 2D and 3D).
For annuli and spherical shells the spherical coordinates around the origin are available too:
the radius ``r = |x|``, the longitude ``phi = atan2(y, x)`` in (-pi, pi] and, in 3D, the
colatitude ``theta = acos(z / r)`` in [0, pi] (pi/2 in 2D), so e.g. ``"(r_outer - r) / (r_outer -
r_inner)"`` is a linear profile across a shell (``r_inner``, ``r_outer``: constants of shell configs).
Anything else is rejected when the config is read, with a
message naming the unknown symbol.
"""

from __future__ import annotations

import ast
import math
from typing import Mapping

import numpy as np
import numpy.typing as npt

__all__ = ["FUNCTIONS", "Expression", "ExpressionError"]

FUNCTIONS = {
    "sin": np.sin, "cos": np.cos, "tan": np.tan, "exp": np.exp, "log": np.log, "sqrt": np.sqrt,
    "tanh": np.tanh, "sinh": np.sinh, "cosh": np.cosh, "abs": np.abs, "min": np.minimum,
    "max": np.maximum, "where": np.where, "clip": np.clip, "floor": np.floor,
    "erf": np.vectorize(math.erf, otypes=[float]), "erfc": np.vectorize(math.erfc, otypes=[float]),
}
_COORDINATES = ("x", "y", "z", "r", "phi", "theta")
_ALLOWED_NODES = (
    ast.Expression, ast.BinOp, ast.UnaryOp, ast.Compare, ast.BoolOp, ast.Call, ast.Name, ast.Load,
    ast.Constant, ast.IfExp, ast.Add, ast.Sub, ast.Mult, ast.Div, ast.Pow, ast.Mod, ast.USub,
    ast.UAdd, ast.Lt, ast.LtE, ast.Gt, ast.GtE, ast.Eq, ast.NotEq, ast.And, ast.Or, ast.Not,
    ast.BitAnd, ast.BitOr,
)


class ExpressionError(ValueError):
    """An expression that cannot be parsed or uses something not allowed."""


class _FloatLiterals(ast.NodeTransformer):
    def visit_Constant(self, node: ast.Constant) -> ast.Constant:
        if isinstance(node.value, int) and not isinstance(node.value, bool):
            return ast.copy_location(ast.Constant(float(node.value)), node)
        return node


class Expression:
    """A vectorised scalar function of position compiled from a string.

    Args:
        text: The expression.
        constants: Extra named constants usable in ``text``.
        gdim: Geometric dimension (2: ``z`` is the second coordinate; 3: the third).
    """

    def __init__(
        self, text: str, /, *, constants: Mapping[str, float] | None = None, gdim: int = 2
    ) -> None:
        self.text = str(text)
        self.gdim = gdim
        self.constants = {"pi": math.pi, "e": math.e, **dict(constants or {})}
        try:
            tree = ast.parse(self.text, mode="eval")
        except SyntaxError as err:
            raise ExpressionError(f"cannot parse {self.text!r}: {err.msg}") from None
        for node in ast.walk(tree):
            if not isinstance(node, _ALLOWED_NODES):
                raise ExpressionError(f"{type(node).__name__} is not allowed in {self.text!r}")
            if isinstance(node, ast.Call) and not (isinstance(node.func, ast.Name) and node.func.id in FUNCTIONS):
                raise ExpressionError(
                    f"unknown function in {self.text!r}; allowed: {sorted(FUNCTIONS)}"
                )
            if isinstance(node, ast.Name) and not (
                node.id in FUNCTIONS or node.id in self.constants or node.id in _COORDINATES
            ):
                raise ExpressionError(
                    f"unknown name {node.id!r} in {self.text!r}; use x, y, z, r, phi, theta, pi, e,"
                    f" functions {sorted(FUNCTIONS)} or constants {sorted(set(self.constants) - {'pi', 'e'})}"
                )
        # Integer literals become floats: Python's integer arithmetic is exact and unbounded, so
        # "9**9**9" would compute for hours; in floating point it overflows at once (an error).
        tree = _FloatLiterals().visit(tree)
        self._code = compile(tree, "<config expression>", "eval")

    def check(self, points: npt.NDArray[np.float64], /) -> None:
        """Evaluate at ``points`` (shape=(3, n)) and raise ExpressionError if that fails or gives
        no finite value (e.g. an overflow such as ``9**9**9``)."""
        try:
            with np.errstate(all="ignore"):
                values = self(points)
        except (ArithmeticError, ValueError, TypeError) as err:
            raise ExpressionError(f"cannot evaluate {self.text!r}: {err}") from None
        if not np.any(np.isfinite(values)):
            raise ExpressionError(f"{self.text!r} evaluates to {values[0]} in the domain")

    def __call__(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Evaluate at points ``x``, shape=(3, n) (DOLFINx interpolation layout); returns shape=(n,)."""
        namespace = dict(FUNCTIONS)
        namespace.update(self.constants)
        namespace.update({"x": x[0], "y": x[1], "z": x[self.gdim - 1]})
        names = self._code.co_names
        if "r" in names or "theta" in names:
            r = np.sqrt(np.sum(x[: self.gdim] ** 2, axis=0))
            namespace["r"] = r
            if "theta" in names:
                z = x[2] if self.gdim == 3 else np.zeros_like(r)
                with np.errstate(invalid="ignore", divide="ignore"):
                    namespace["theta"] = np.arccos(np.clip(np.where(r > 0, z / np.where(r > 0, r, 1.0), 0.0), -1.0, 1.0))
        if "phi" in names:
            namespace["phi"] = np.arctan2(x[1], x[0])
        value = eval(self._code, {"__builtins__": {}}, namespace)  # noqa: S307 - names checked above
        return np.broadcast_to(np.asarray(value, dtype=np.float64), x.shape[1:]).copy()

    def __repr__(self) -> str:
        return f"Expression({self.text!r})"
