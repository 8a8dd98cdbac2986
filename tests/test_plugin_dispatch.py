"""Plugins are chosen through their registry only: no code compares a plugin-name setting with a
registered name (``if solver == "multigrid":``, ``bc.kind in ("free_slip", ...)``, ``match law:
case "constant":``). What differs between implementations is asked of the registry's entry
(``STOKES_SOLVER_CHOICES[name].nested``, ``VELOCITY_BC_KINDS[kind].moves``, ``bc.spec.dirichlet(...)``).

The scan: every module of fembase/, particles/ and convection/ is parsed; a comparison (``==``,
``!=``, ``in``, ``not in``) or a ``match``/``case`` whose one side reads a plugin-name setting and
whose other side is a string literal (or a tuple, list or set of them) naming an entry of that
family's registry is dispatch outside the registry. "Reads a plugin-name setting": the side's
attribute names, subscript keys and variable names include one of the family's words
(:data:`FAMILIES`: ``kind``, ``solver``, ``geometry``, ``source``, ...; ``law.name`` reads
``law``). The registries themselves are found by the scan (every module-level ``Registry(...)``
or ``linear_solvers(...)``), so a new one is checked as soon as :data:`FAMILIES` names its words.

:data:`ALLOWED` lists the comparisons not converted yet, each with why it stays; an entry that no
longer matches anything fails the test too (take it off the list).
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("fembase", "particles", "convection")

FAMILIES: dict[str, tuple[str, ...]] = {
    # the words a plugin-name setting is read by -> the registries (by variable name) of its names
    "kind": ("VELOCITY_BC_KINDS", "TEMPERATURE_BC_KINDS"),
    "solver": ("STOKES_SOLVER_CHOICES", "STOKES_SOLVERS", "TRANSPORT_SOLVERS"),
    "geometry": ("DOMAINS",),
    "law": ("VISCOSITY_LAWS",),
    "laws": ("VISCOSITY_LAWS",),
    "temperature_law": ("TEMPERATURE_LAWS",),
    "mixing": ("MIXING_RULES",),
    "combination": ("COMBINATIONS",),
    "measure": ("STRAIN_RATE_MEASURES",),
    "source": ("COMPOSITION_SOURCES",),
    "strategy": ("BALANCE_STRATEGIES",),
    "generator": ("GENERATORS",),
    "integrator": ("INTEGRATORS",),
    "interpolator": ("INTERPOLATORS",),
    "properties": ("PROPERTIES",),
    "fields_format": ("FIELD_WRITERS",),
    "format": ("FIELD_WRITERS", "PARTICLE_WRITERS"),
    "statistics": ("POSTPROCESSORS",),
    "postprocessor": ("POSTPROCESSORS",),
    "stress": ("STRESS_CARRIERS",),
}
"""Words that read a plugin-name setting, and the registries whose names it takes."""

ALLOWED: dict[tuple[str, str], str] = {
    # (module path, comparison as ast.unparse writes it) -> why it stays, for now
    ("convection/geometry/shell.py", "mesh.geometry == 'annulus'"):
        "geometry/ may compare a geometry's name (tests/test_layers.py); the annulus and the shell share a class",
}


def _registries() -> dict[str, set[str]]:
    """Names registered in each module-level ``Registry(...)``/``linear_solvers(...)``, by variable name."""
    out: dict[str, set[str]] = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            for node in ast.parse(path.read_text()).body:
                if not (isinstance(node, (ast.Assign, ast.AnnAssign)) and isinstance(node.value, ast.Call)):
                    continue
                func = node.value.func
                if (func.id if isinstance(func, ast.Name) else getattr(func, "attr", "")) not in (
                        "Registry", "linear_solvers"):
                    continue
                target = node.targets[0] if isinstance(node, ast.Assign) else node.target
                module = importlib.import_module(".".join(path.relative_to(ROOT).with_suffix("").parts))
                out.setdefault(target.id, set()).update(getattr(module, target.id))
    return out


def _literals(node: ast.AST) -> list[str]:
    """The string literal, or the strings of a tuple/list/set of literals, else []."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)) and node.elts and all(
            isinstance(e, ast.Constant) and isinstance(e.value, str) for e in node.elts):
        return [e.value for e in node.elts]  # type: ignore[attr-defined]
    return []


def _words(node: ast.AST) -> set[str]:
    """The attribute names, string subscript keys and variable names ``node`` reads."""
    words = set()
    for sub in ast.walk(node):
        if isinstance(sub, ast.Attribute):
            words.add(sub.attr)
        elif isinstance(sub, ast.Name):
            words.add(sub.id)
        elif isinstance(sub, ast.Subscript) and isinstance(sub.slice, ast.Constant):
            words.add(str(sub.slice.value))
    return words


def _registered(setting: ast.AST, literal: ast.AST, registries: dict[str, set[str]]) -> bool:
    names = _literals(literal)
    if not names or _literals(setting):
        return False
    known = set().union(*(registries.get(r, set()) for w in _words(setting) for r in FAMILIES.get(w, ())))
    return any(name in known for name in names)


def dispatch_outside_registries(source: str, registries: dict[str, set[str]]) -> list[tuple[int, str]]:
    """(line, comparison) of every comparison of a plugin-name setting with a registered name in ``source``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Compare) and len(node.ops) == 1 and isinstance(
                node.ops[0], (ast.Eq, ast.NotEq, ast.In, ast.NotIn)):
            left, right = node.left, node.comparators[0]
            if _registered(left, right, registries) or _registered(right, left, registries):
                found.append((node.lineno, ast.unparse(node)))
        elif isinstance(node, ast.Match):
            for case in node.cases:
                patterns = [case.pattern, *getattr(case.pattern, "patterns", ())]
                if any(isinstance(p, ast.MatchValue) and _registered(node.subject, p.value, registries)
                       for p in patterns):
                    text = f"match {ast.unparse(node.subject)}: case {ast.unparse(case.pattern)}"
                    found.append((case.pattern.lineno, text))
    return found


def test_plugins_dispatch_through_their_registries():
    registries = _registries()
    assert {"STOKES_SOLVERS", "STOKES_SOLVER_CHOICES", "VELOCITY_BC_KINDS", "TEMPERATURE_BC_KINDS", "DOMAINS",
            "VISCOSITY_LAWS", "GENERATORS"} <= set(registries)
    wrong, used = [], set()
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            relative = str(path.relative_to(ROOT))
            for line, text in dispatch_outside_registries(path.read_text(), registries):
                if (relative, text) in ALLOWED:
                    used.add((relative, text))
                else:
                    wrong.append(f"{relative}:{line}: {text}")
    assert not wrong, "dispatch outside a registry (ask the registry's entry instead):\n" + "\n".join(wrong)
    assert not set(ALLOWED) - used, f"allowed comparisons that are gone (take them off ALLOWED): {set(ALLOWED) - used}"


def test_the_scan_finds_an_if_elif_over_names():
    registries = {"STOKES_SOLVERS": {"direct", "multigrid"}, "VELOCITY_BC_KINDS": {"free_slip", "no_slip"}}
    source = '''
if self.solver == "multigrid":
    pass
elif bc.kind in ("free_slip", "no_slip"):
    pass
match config["stokes"]["solver"]:
    case "direct":
        pass
if name == "multigrid" or bc.value == "free_slip" or bc.kind == "traction":
    pass
'''
    assert sorted(line for line, _ in dispatch_outside_registries(source, registries)) == [2, 4, 7]


SHAPED = ("convection.model.composition:COMPOSITION_SOURCES", "convection.postprocess.postprocessors:POSTPROCESSORS",
          "convection.io.fields:FIELD_WRITERS", "particles.io.output:PARTICLE_WRITERS",
          "convection.geometry.registry:DOMAINS", "convection.physics.rheology:VISCOSITY_LAWS",
          "particles.generation:GENERATORS", "particles.interpolation:INTERPOLATORS",
          "particles.properties:PROPERTIES", "convection.geometry.boundary:VELOCITY_BC_KINDS",
          "convection.geometry.boundary:TEMPERATURE_BC_KINDS", "convection.solvers.stokes.solver:STOKES_SOLVER_CHOICES")
"""The registries whose families have the one plugin shape (docs/developers.md, "The one plugin
shape"): a family that gets it joins the list, none leaves it."""


def test_shaped_families_have_settings_and_build():
    """Every entry of a shaped family has a frozen ``Settings`` dataclass whose fields are made by
    ``param`` (or ``subsection``) and a classmethod ``build(settings, context)``, and none keeps an
    older constructor (``create``, ``from_settings``) beside it."""
    import dataclasses
    import inspect

    wrong = []
    for where in SHAPED:
        module, name = where.split(":")
        for entry_name, entry in getattr(importlib.import_module(module), name).items():
            settings = getattr(entry, "Settings", None)
            if not (dataclasses.is_dataclass(settings) and settings.__dataclass_params__.frozen):
                wrong.append(f"{name}[{entry_name!r}].Settings is not a frozen dataclass")
            elif any(not ({"schema", "section"} & set(f.metadata)) for f in dataclasses.fields(settings)):
                wrong.append(f"{name}[{entry_name!r}].Settings has fields not made by param")
            if not isinstance(inspect.getattr_static(entry, "build", None), classmethod):
                wrong.append(f"{name}[{entry_name!r}] has no classmethod build(settings, context)")
            wrong += [f"{name}[{entry_name!r}] keeps {old}()" for old in ("create", "from_settings")
                      if hasattr(entry, old)]
    assert not wrong, wrong
