"""Small components: no class over 250 lines and no function over 80 in fembase/, particles/ and
convection/ (numba-compiled kernels excepted: they are written flat for speed)."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MAX_CLASS, MAX_FUNCTION = 250, 80


def _compiled(node: ast.AST) -> bool:
    return any("jit" in ast.unparse(d) or "numba" in ast.unparse(d) for d in getattr(node, "decorator_list", []))


def _too_long() -> list[str]:
    wrong = []
    for package in ("fembase", "particles", "convection"):
        for path in sorted((ROOT / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                lines = getattr(node, "end_lineno", 0) - getattr(node, "lineno", 0) + 1
                if isinstance(node, ast.ClassDef) and lines > MAX_CLASS:
                    wrong.append(f"{path.relative_to(ROOT)}:{node.lineno} class {node.name}: {lines} lines")
                elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and lines > MAX_FUNCTION \
                        and not _compiled(node):
                    wrong.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name}: {lines} lines")
    return wrong


def test_classes_and_functions_stay_small():
    assert not _too_long(), _too_long()
