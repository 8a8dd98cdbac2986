"""VTK beside DOLFINx: a scalar bar renders, or VTK loaded the wrong way is refused; never an abort.

``import dolfinx`` puts libdolfinx's ``std::regex`` internals (new ``std::string`` ABI) in the global
symbol scope; VTK's wheel (old ABI) loaded after it by a plain ``import pyvista`` binds to them and
its first scalar bar aborts the process (SIGABRT in ``vtkScalarBarActor::LayoutTicks``). That is how
the serial test process aborted at the 3D snapshot test on 2026-12-07: two earlier tests had read
fields with ``pytest.importorskip("pyvista")``. See :func:`convection.io.pictures.import_pyvista`.
"""

from __future__ import annotations

import ast
import sys

import pytest

from _runs import ROOT, guarded_run

SCRIPT = """
import ctypes, sys
from pathlib import Path
order, out = sys.argv[1], Path(sys.argv[2])
if order == "pyvista, dolfinx":
    import pyvista
import dolfinx
from convection.io.pictures.series import _REGEX_SYMBOL
print("global regex:", hasattr(ctypes.CDLL(None), _REGEX_SYMBOL))
if order == "dolfinx, pyvista":
    import pyvista
from convection.io.pictures import import_pyvista
try:
    pv = import_pyvista()
except RuntimeError as error:
    print("refused:", error)
    sys.exit(3)
plotter = pv.Plotter(off_screen=True, window_size=(200, 200))
plotter.add_mesh(pv.Sphere().elevation(), scalars="Elevation", scalar_bar_args={"title": "z", "fmt": "%.2f"})
assert len(plotter.scalar_bars) == 1
plotter.screenshot(str(out))
print("rendered")
"""


@pytest.mark.parametrize("order", ["dolfinx, import_pyvista", "pyvista, dolfinx", "dolfinx, pyvista"])
def test_a_scalar_bar_renders_or_vtk_is_refused(order, tmp_path):
    """Through import_pyvista after DOLFINx, and with VTK imported before DOLFINx, a scalar bar
    renders. A plain ``import pyvista`` after DOLFINx is refused with a RuntimeError where DOLFINx put
    std::regex internals in the global scope (Debian 12), and renders where it did not."""
    out = tmp_path / "bar.png"
    proc = guarded_run([sys.executable, "-c", SCRIPT, order, str(out)], cwd=ROOT)
    assert proc.returncode in (0, 3), (proc.returncode, proc.stderr[-3000:])  # -6: the abort
    refused = order == "dolfinx, pyvista" and "global regex: True" in proc.stdout
    if refused:
        assert proc.returncode == 3 and "import_pyvista() instead" in proc.stdout, proc.stdout
    else:
        assert proc.returncode == 0 and proc.stdout.splitlines()[-1] == "rendered", proc.stderr[-3000:]
        assert out.stat().st_size > 1000


def _plain_vtk_imports(path) -> list[str]:
    """``import pyvista``, ``import vtk...``, ``vtkmodules`` or ``importorskip("pyvista")`` in ``path``,
    outside ``if TYPE_CHECKING:`` blocks."""
    found = []
    checking = set()
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            checking.update(id(n) for child in node.body for n in ast.walk(child))
    for node in ast.walk(tree):
        if id(node) in checking:
            continue
        names = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names = [node.module]
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "importorskip":
            names = [arg.value for arg in node.args if isinstance(arg, ast.Constant)]
        found += [f"{path.relative_to(ROOT)}:{node.lineno}: {name}" for name in names
                  if name.split(".")[0] in ("pyvista", "vtk", "vtkmodules")]
    return found


def test_vtk_is_loaded_only_through_import_pyvista():
    """No module, test, demo or benchmark imports pyvista or VTK but import_pyvista (which loads it
    with RTLD_DEEPBIND) and the labels, which use a VTK already loaded for a scalar bar."""
    allowed = {"convection/io/pictures/series.py", "convection/io/pictures/labels.py"}
    found = []
    for folder in ("convection", "fembase", "particles", "tests", "demos", "benchmarks", "scripts"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            if str(path.relative_to(ROOT)) not in allowed:
                found += _plain_vtk_imports(path)
    assert found == []
    assert _plain_vtk_imports(ROOT / "convection/io/pictures/series.py")  # the check finds imports
