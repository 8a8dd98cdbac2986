"""The tests import the project's own modules plainly: ``pytest.importorskip`` is for optional
third-party packages (gmsh, assess, mkdocs), since on a module of fembase, particles or convection
it would turn a broken import into a silent skip."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("fembase", "particles", "convection")


def _own_importorskips(path: Path) -> list[str]:
    """``line module`` for each importorskip of a first-party module (or of a computed name) in ``path``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", None)) == "importorskip":
            name = node.args[0].value if node.args and isinstance(node.args[0], ast.Constant) else None
            if not isinstance(name, str) or name.split(".")[0] in PACKAGES:
                found.append(f"{node.lineno} {name}")
    return found


def test_no_importorskip_of_the_project():
    wrong = [f"{path.relative_to(ROOT)}:{hit}" for path in sorted((ROOT / "tests").rglob("*.py"))
             for hit in _own_importorskips(path)]
    assert not wrong, wrong


def test_the_check_sees_importorskip(tmp_path):
    path = tmp_path / "skips.py"
    path.write_text('import pytest\nfrom pytest import importorskip\npytest.importorskip("gmsh")\n'
                    'pytest.importorskip("particles.advection")\nimportorskip("convection")\n'
                    'pytest.importorskip(name)\n')
    assert _own_importorskips(path) == ["4 particles.advection", "5 convection", "6 None"]
