"""The layering of the packages: fembase (the floor) imports neither particles nor convection,
particles never imports convection, and no package imports another package's private modules."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("fembase", "particles", "convection")
ALLOWED = {"fembase": {"fembase"}, "particles": {"fembase", "particles"},
           "convection": {"fembase", "particles", "convection"}}


def _imports(path: Path):
    """(imported module, line) of every import of a first-party module in ``path``."""
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            yield node.module, node.lineno
        elif isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, node.lineno


@pytest.mark.parametrize("package", PACKAGES)
def test_package_imports_only_the_layers_below(package):
    wrong = []
    for path in sorted((ROOT / package).rglob("*.py")):
        for module, line in _imports(path):
            top = module.split(".")[0]
            if top in PACKAGES and top not in ALLOWED[package]:
                wrong.append(f"{path.relative_to(ROOT)}:{line} imports {module}")
    assert not wrong, wrong


@pytest.mark.parametrize("package", PACKAGES)
def test_no_private_module_of_another_package(package):
    """``a.b._c`` may be imported only from inside ``a/b/`` (its subfolders included)."""
    wrong = []
    for path in sorted((ROOT / package).rglob("*.py")):
        here = ".".join(path.relative_to(ROOT).with_suffix("").parts[:-1])
        for module, line in _imports(path):
            parts = module.split(".")
            private = [i for i, p in enumerate(parts) if p.startswith("_") and not p.startswith("__")]
            owner = ".".join(parts[:private[0]]) if private else ""
            if parts[0] in PACKAGES and private and here != owner and not here.startswith(owner + "."):
                wrong.append(f"{path.relative_to(ROOT)}:{line} imports {module}")
    assert not wrong, wrong


def test_no_dolfinx_version_checks_outside_the_floor():
    """Only fembase may know which DOLFINx it runs on."""
    wrong = [f"{path.relative_to(ROOT)}" for package in ("particles", "convection")
             for path in sorted((ROOT / package).rglob("*.py")) if "__version__" in path.read_text()]
    assert not wrong, wrong
