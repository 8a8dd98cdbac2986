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

An expression from a config cannot take the machine down: its text, node count and nesting depth
are bounded (:data:`MAX_LENGTH`, :data:`MAX_NODES`, :data:`MAX_DEPTH`); only numbers may be
literals (no strings, so no ``'%2000000000s' % 1``); every number is a NumPy double, so arithmetic
overflows to inf instead of growing an exact Python integer (``9**9**9``, ``(True+True)**...``)
and ``1/0`` is inf rather than an exception; and :meth:`Expression.check` refuses an expression
that fails or gives a non-finite value at any probe point.
"""

from __future__ import annotations

import ast
import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from convection.schema import short_repr

__all__ = ["FUNCTIONS", "MAX_DEPTH", "MAX_LENGTH", "MAX_NODES", "Expression", "ExpressionError"]

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
MAX_LENGTH = 4000
"""Longest expression text (characters)."""
MAX_NODES = 2000
"""Most syntax-tree nodes of an expression (``x + 1`` has 5)."""
MAX_DEPTH = 100
"""Deepest nesting of an expression's syntax tree (a sum of n terms nests n deep)."""
_HIDDEN = "__"
"""Prefix of the names the compiled code uses for its literals and helpers (not for user constants)."""
_ERRORS = (ArithmeticError, ValueError, TypeError, IndexError, RecursionError, MemoryError)
"""What evaluating a checked expression can still raise (shapes, domain errors)."""


class ExpressionError(ValueError):
    """An expression that cannot be parsed or uses something not allowed."""


def _depth(tree: ast.AST) -> int:
    """Nesting depth of a syntax tree (iterative: safe for any depth)."""
    deepest, stack = 0, [(tree, 1)]
    while stack:
        node, depth = stack.pop()
        deepest = max(deepest, depth)
        stack.extend((child, depth + 1) for child in ast.iter_child_nodes(node))
    return deepest


def _replace_children(tree: ast.AST, replace: Any) -> None:
    """Replace every child ``c`` of every node by ``replace(c)`` (None: keep it); iterative."""
    for node in list(ast.walk(tree)):
        for field, child in ast.iter_fields(node):
            if isinstance(child, ast.AST):
                setattr(node, field, replace(child) or child)
            elif isinstance(child, list):
                child[:] = [(replace(c) or c) if isinstance(c, ast.AST) else c for c in child]


def _numeric(tree: ast.Expression) -> dict[str, Any]:
    """Rewrite a checked tree so that every value is a NumPy number, and return the names it now
    uses: ``not a`` becomes ``logical_not(a)``, ``a and b`` ``logical_and(a, b)`` (``or`` alike), a
    chained comparison ``0 < x < 1`` the ``and`` of its pairs (all elementwise on arrays), and each literal a name bound
    to a ``numpy.float64`` (``True`` is 1.0), so no exact (unbounded) Python integer or bool can arise."""
    values: dict[str, Any] = {f"{_HIDDEN}not": np.logical_not, f"{_HIDDEN}and": np.logical_and,
                              f"{_HIDDEN}or": np.logical_or}

    def call(name: str, args: list[ast.expr], node: ast.AST) -> ast.expr:
        return ast.copy_location(ast.Call(func=ast.Name(id=f"{_HIDDEN}{name}", ctx=ast.Load()), args=args,
                                          keywords=[]), node)

    def pairwise(name: str, args: list[ast.expr], node: ast.AST) -> ast.expr:
        return args[0] if len(args) == 1 else call(name, [args[0], pairwise(name, args[1:], node)], node)

    class Logical(ast.NodeTransformer):  # bottom-up (the depth is bounded before this runs)
        def visit_UnaryOp(self, node: ast.UnaryOp) -> ast.AST:
            self.generic_visit(node)
            return call("not", [node.operand], node) if isinstance(node.op, ast.Not) else node

        def visit_BoolOp(self, node: ast.BoolOp) -> ast.AST:  # elementwise: a and b -> logical_and(a, b)
            self.generic_visit(node)
            return pairwise("and" if isinstance(node.op, ast.And) else "or", list(node.values), node)

        def visit_Compare(self, node: ast.Compare) -> ast.AST:  # 0 < x < 1 -> (0 < x) and (x < 1)
            self.generic_visit(node)
            if len(node.ops) == 1:
                return node
            operands = [node.left, *node.comparators]
            return pairwise("and", [ast.copy_location(ast.Compare(left=operands[i], ops=[op],
                                                                  comparators=[operands[i + 1]]), node)
                                    for i, op in enumerate(node.ops)], node)

    def literal(node: ast.AST) -> ast.AST | None:
        if isinstance(node, ast.Constant):
            name = f"{_HIDDEN}k{len(values)}"
            values[name] = np.float64(float(node.value))  # type: ignore[arg-type]  # a number: checked before
            return ast.copy_location(ast.Name(id=name, ctx=ast.Load()), node)
        return None

    Logical().visit(tree)
    _replace_children(tree, literal)
    return values


class Expression:
    """A vectorised scalar function of position compiled from a string.

    Args:
        text: The expression.
        constants: Extra named constants usable in ``text`` (numbers; not starting with ``__``).
        gdim: Geometric dimension (2: ``z`` is the second coordinate; 3: the third).

    Raises:
        ExpressionError: the text is too long, too large or too deep, cannot be parsed, or uses
            something not allowed (naming it).
    """

    def __init__(
        self, text: str, /, *, constants: Mapping[str, float] | None = None, gdim: int = 2
    ) -> None:
        self.text = str(text)
        self.gdim = gdim
        self.constants = {"pi": math.pi, "e": math.e, **self._numbers(constants or {})}
        tree = self._parse()
        self._check_names(tree)
        self._literals = _numeric(tree)
        try:
            self._code = compile(ast.fix_missing_locations(tree), "<config expression>", "eval")
        except (RecursionError, MemoryError, ValueError) as err:
            raise ExpressionError(f"cannot compile {short_repr(self.text)}: {type(err).__name__}") from None

    def _numbers(self, constants: Mapping[str, Any]) -> dict[str, float]:
        out = {}
        for name, value in constants.items():
            if str(name).startswith(_HIDDEN):
                raise ExpressionError(f"constant name {short_repr(name)} must not start with {_HIDDEN!r}")
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ExpressionError(f"constant {short_repr(name)} must be a number, got {short_repr(value)}")
            try:
                out[str(name)] = float(value)
            except OverflowError:
                raise ExpressionError(f"constant {short_repr(name)} is too large: {short_repr(value)}") from None
        return out

    def _parse(self) -> ast.Expression:
        if len(self.text) > MAX_LENGTH:
            raise ExpressionError(f"{short_repr(self.text)} is longer than {MAX_LENGTH} characters")
        try:
            tree = ast.parse(self.text, mode="eval")
        except SyntaxError as err:
            raise ExpressionError(f"cannot parse {short_repr(self.text)}: {err.msg}") from None
        except RecursionError:
            raise ExpressionError(f"cannot parse {short_repr(self.text)}: nested too deeply") from None
        except (MemoryError, ValueError) as err:  # too complex for the parser; a NUL byte
            raise ExpressionError(f"cannot parse {short_repr(self.text)}: {err or type(err).__name__}") from None
        nodes = sum(1 for _ in ast.walk(tree))
        if nodes > MAX_NODES:
            raise ExpressionError(f"{short_repr(self.text)} has {nodes} terms and operators, more than {MAX_NODES}")
        if _depth(tree) > MAX_DEPTH:
            raise ExpressionError(f"{short_repr(self.text)} is nested more than {MAX_DEPTH} levels deep")
        return tree

    def _check_names(self, tree: ast.Expression) -> None:
        for node in ast.walk(tree):
            if not isinstance(node, _ALLOWED_NODES):
                raise ExpressionError(f"{type(node).__name__} is not allowed in {short_repr(self.text)}")
            if isinstance(node, ast.Constant) and (
                    isinstance(node.value, complex) or not isinstance(node.value, (int, float))):
                raise ExpressionError(f"only numbers may be literals in {short_repr(self.text)}, got "
                                      f"{short_repr(node.value)}")
            if isinstance(node, ast.Call) and not (isinstance(node.func, ast.Name) and node.func.id in FUNCTIONS):
                raise ExpressionError(
                    f"unknown function in {short_repr(self.text)}; allowed: {sorted(FUNCTIONS)}"
                )
            if isinstance(node, ast.Call) and node.keywords:
                raise ExpressionError(f"keyword arguments are not allowed in {short_repr(self.text)}")
            if isinstance(node, ast.Name) and not (
                node.id in FUNCTIONS or node.id in self.constants or node.id in _COORDINATES
            ):
                raise ExpressionError(
                    f"unknown name {short_repr(node.id)} in {short_repr(self.text)}; use x, y, z, r, phi, theta, pi, e,"
                    f" functions {sorted(FUNCTIONS)} or constants {sorted(set(self.constants) - {'pi', 'e'})}"
                )

    def check(self, points: npt.NDArray[np.float64], /) -> None:
        """Evaluate at ``points`` (shape=(3, n)) and raise ExpressionError if that fails or gives
        a non-finite value at any of them (``1/(x - 0.25)``, ``log(x)`` on a boundary, ``9**9**9``),
        naming the first such point."""
        try:
            values = self(points)
        except _ERRORS as err:
            raise ExpressionError(f"cannot evaluate {short_repr(self.text)}: {type(err).__name__}: "
                                  f"{short_repr(str(err))[1:-1]}") from None
        bad = ~np.isfinite(values)
        if np.any(bad):
            i = int(np.argmax(bad))
            where = ", ".join(f"{c + 0.0:.6g}" for c in points[: self.gdim, i])  # + 0.0: no "-0"
            raise ExpressionError(f"{short_repr(self.text)} is {values[i]} at ({where}); it must be finite "
                                  "everywhere in the domain")

    def __call__(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Evaluate at points ``x``, shape=(3, n) (DOLFINx interpolation layout); returns shape=(n,).
        Floating-point warnings are silenced (an overflow gives inf; :meth:`check` refuses those)."""
        namespace = dict(FUNCTIONS)
        namespace.update({name: np.float64(value) for name, value in self.constants.items()})
        namespace.update(self._literals)
        namespace.update({"x": x[0], "y": x[1], "z": x[self.gdim - 1]})
        names = self._code.co_names
        with np.errstate(all="ignore"):
            if "r" in names or "theta" in names:
                r = np.sqrt(np.sum(x[: self.gdim] ** 2, axis=0))
                namespace["r"] = r
                if "theta" in names:
                    z = x[2] if self.gdim == 3 else np.zeros_like(r)
                    namespace["theta"] = np.arccos(np.clip(np.where(r > 0, z / np.where(r > 0, r, 1.0), 0.0),
                                                           -1.0, 1.0))
            if "phi" in names:
                namespace["phi"] = np.arctan2(x[1], x[0])
            value = eval(self._code, {"__builtins__": {}}, namespace)  # noqa: S307 - names checked above
            return np.broadcast_to(np.asarray(value, dtype=np.float64), x.shape[1:]).copy()

    def __repr__(self) -> str:
        return f"Expression({self.text!r})"
