"""The layering of the packages: fembase (the floor) imports neither particles nor convection,
particles never imports convection, and no package imports another package's private modules."""

import ast
from pathlib import Path
from collections.abc import Callable

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


OUTSIDE_THE_FLOOR = ("particles", "convection", "tests", "demos", "benchmarks", "scripts")
"""Where no code branches on the DOLFINx version: it asks a capability of
:mod:`fembase.dolfinx_compat` (e.g. ``repartitioned_manifolds_nest()``) instead."""


def _version_branches(path: Path) -> list[str]:
    """Where ``path`` reads the DOLFINx version: ``DOLFINX_VERSION`` named or imported, a
    ``__version__`` compared, or a version compared with a tuple of numbers (``sys.version_info``,
    Python's own, is not DOLFINx's); "line what" for each line."""
    found: dict[int, str] = {}
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Name) and node.id == "DOLFINX_VERSION" \
                or isinstance(node, ast.Attribute) and node.attr == "DOLFINX_VERSION" \
                or isinstance(node, ast.alias) and node.name == "DOLFINX_VERSION":
            found.setdefault(node.lineno, "names DOLFINX_VERSION")
        elif isinstance(node, ast.Compare):
            names = {n.id if isinstance(n, ast.Name) else n.attr for n in ast.walk(node)
                     if isinstance(n, (ast.Name, ast.Attribute))} - {"version_info"}
            tuples = any(isinstance(n, ast.Tuple) and n.elts and all(isinstance(e, ast.Constant) and
                                                                     isinstance(e.value, int) for e in n.elts)
                         for n in ast.walk(node))
            if "__version__" in names or tuples and any("version" in name.lower() for name in names):
                found.setdefault(node.lineno, f"compares {ast.unparse(node)!r}")
    return [f"{line} {what}" for line, what in sorted(found.items())]


def test_no_dolfinx_version_checks_outside_the_floor():
    """Only fembase may know which DOLFINx it runs on: outside it, code asks a capability."""
    wrong = [f"{path.relative_to(ROOT)}:{line}" for folder in OUTSIDE_THE_FLOOR
             for path in sorted((ROOT / folder).rglob("*.py")) for line in _version_branches(path)]
    wrong += [f"{path.relative_to(ROOT)}" for package in ("particles", "convection")
              for path in sorted((ROOT / package).rglob("*.py")) if "__version__" in path.read_text()]
    assert not wrong, wrong


def test_the_version_check_sees_version_branches(tmp_path):
    """The check above finds each way of branching on the version (what the loader once did)."""
    path = tmp_path / "branches.py"
    path.write_text("from fembase.dolfinx_compat import DOLFINX_VERSION\n"
                    "import dolfinx\n"
                    "new = dolfinx.__version__ >= '0.7'\n"
                    "if compat.DOLFINX_VERSION < (0, 7):\n    pass\n"
                    "old = version < (0, 7)\n"
                    "python = sys.version_info >= (3, 12)\n")
    assert [line.split()[0] for line in _version_branches(path)] == ["1", "3", "4", "6"]


ROOMS = ("geometry", "physics", "deform", "solvers", "adapt", "model", "postprocess", "io", "run", "config", "app")
"""convection's rooms from the floor up: a room imports only from rooms below it (and from the
floor modules ``schema``, ``expressions``, ``launch``, ``_lazy``, from particles and fembase)."""


def test_every_folder_of_convection_is_a_room():
    """A new folder of convection/ takes its place in ROOMS, so that its imports are checked."""
    folders = {p.parent.name for p in (ROOT / "convection").glob("*/__init__.py")}
    assert folders == set(ROOMS), sorted(folders ^ set(ROOMS))


def _modules() -> dict[str, Path]:
    """Every module of the three packages by dotted name (a package by its ``__init__``)."""
    out = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _module_imports(path: Path):
    """Imported module names of ``path`` (``from a import b`` gives ``a.b`` when that is a module),
    every import: those inside functions, and those under ``if TYPE_CHECKING:`` too (an import
    only the type checker runs still ties the two modules together)."""
    modules = _modules()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [f"{node.module}.{alias.name}" for alias in node.names]
            yield from [n for n in names if n in modules] or [node.module]
        elif isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)


def _room(module: str) -> int | None:
    parts = module.split(".")
    if parts[0] != "convection" or len(parts) < 2 or parts[1] not in ROOMS:
        return None
    return ROOMS.index(parts[1])


def _upward_imports(room: Callable[[str], int | None]) -> list[str]:
    """Every import (inside functions and for the type checker too) of a module whose ``room`` is
    above the importer's."""
    wrong = []
    for module, path in sorted(_modules().items()):
        here = room(module)
        if here is None:
            continue
        for imported in _module_imports(path):
            there = room(imported)
            if there is not None and there > here:
                wrong.append(f"{module} imports {imported}")
    return wrong


def test_convection_rooms_import_only_downwards():
    """No room of convection imports a room above it, not even inside a function or for the type
    checker only."""
    wrong = _upward_imports(_room)
    assert not wrong, wrong


PARTICLE_ROOMS = ("storage", "parallel", "relocation", "advection", "generation", "properties", "interpolation",
                  "population", "io")
"""particles' rooms from the floor up (the map in particles/__init__.py): a room imports only from rooms below
it; the public faces (manager, systems, settings, balance) import from any room, and no room from them."""


def _particle_room(module: str) -> int | None:
    parts = module.split(".")
    if parts[0] != "particles" or len(parts) < 2:
        return None
    return PARTICLE_ROOMS.index(parts[1]) if parts[1] in PARTICLE_ROOMS else len(PARTICLE_ROOMS)


def test_particle_rooms_import_only_downwards():
    """No room of particles imports a room above it or a public face (the faces rank above every
    room), not even inside a function or for the type checker only."""
    wrong = _upward_imports(_particle_room)
    assert not wrong, wrong


def test_no_import_cycles():
    """The module import graph (every import: inside functions and under ``if TYPE_CHECKING:``
    too) has no cycle."""
    modules = _modules()
    graph = {name: sorted({m for m in _module_imports(path) if m in modules and m != name})
             for name, path in modules.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles = []

    def connect(node: str) -> None:  # Tarjan's strongly connected components
        index[node] = low[node] = len(index)
        stack.append(node)
        for child in graph[node]:
            if child not in index:
                connect(child)
                low[node] = min(low[node], low[child])
            elif child in stack:
                low[node] = min(low[node], index[child])
        if low[node] == index[node]:
            component = []
            while True:
                top = stack.pop()
                component.append(top)
                if top == node:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            connect(node)
    assert not cycles, cycles


GEOMETRY_WORDS = {"box", "annulus", "spherical_shell", "sector", "shell", "radial", "vertical", "inner", "outer",
                  "top", "bottom", "left", "right", "front", "back", "west", "east"}
GEOMETRY_CLASSES = {"BoxDomain", "ShellDomain", "Annulus", "SphericalShell", "Sector", "BoxSpec", "ShellSpec",
                    "SectorSpec", "VerticalGravity", "RadialGravity"}


def test_only_geometry_tests_the_geometry():
    """Outside convection/geometry/ no code compares with a geometry's or a boundary's name or tests
    a domain's class: it asks the domain (:mod:`convection.geometry.domain`)."""
    wrong = []
    for path in sorted((ROOT / "convection").rglob("*.py")):
        if "geometry" in path.relative_to(ROOT).parts:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Compare):
                words = [n.value for n in ast.walk(node) if isinstance(n, ast.Constant) and n.value in GEOMETRY_WORDS]
                if words:
                    wrong.append(f"{path.relative_to(ROOT)}:{node.lineno} compares with {words[0]!r}")
            elif isinstance(node, ast.Call) and getattr(node.func, "id", None) in ("isinstance", "issubclass"):
                names = {n.id for n in ast.walk(node.args[1]) if isinstance(n, ast.Name)} & GEOMETRY_CLASSES
                if names:
                    wrong.append(f"{path.relative_to(ROOT)}:{node.lineno} tests the class {sorted(names)[0]}")
    assert not wrong, wrong
