"""Below the loader, code takes typed settings: no module of ``convection/`` outside ``config/``
reads a raw config mapping (issue 47, item 1; docs/developers.md, "Declare a parameter once").

``config/`` turns a resolved config into one frozen :class:`convection.config.settings.RunSettings`;
the factory and the rooms receive its fields. Three things would mean a room reads the mapping
again, and each is checked in every module of ``convection/`` but ``config/``:

- a config section read by its name: a subscript or ``.get``/``.pop``/``.setdefault`` with a
  section's name as the key, on something named like a config (``config["adaptivity"]``,
  ``saved.config.get("mesh")``, ``cfg["balance"]``), or followed by a key of the section on
  anything (``x["adaptivity"]["enabled"]``, ``x["stokes"].get("solver")``); a component or state
  named like a section (``components["free_surface"]``) is not a config read;
- a parameter named ``config``, ``cfg`` or ``*_config`` that is a mapping (annotated with ``dict``,
  ``Mapping`` or ``Any``, or not annotated; a config file's path is not);
- a function named ``from_config`` or ``*_from_config`` (a builder from raw config values).

What still does, is listed below with the reason; the lists only shrink. Not covered by this scan
(issue 47, what remains of "one way to declare a parameter"): none of the rooms' own validators remain;
the viscosity laws declare their parameters with ``param`` (physics/rheology.py). ``particles/``
takes typed settings: ``ParticleManager.from_config`` and the loader's particle checks read each
system's ``ParticleSettings``, and its generators, interpolators and properties are made through
their registries from their own ``Settings`` (``REGISTRY.settings(name, **parameters)``, then
``REGISTRY.build(name, settings, context)``), the way the last test below checks.
"""

import ast
from pathlib import Path

from convection.config.loader import SCHEMA

ROOT = Path(__file__).resolve().parents[1]
FRONT_END = ROOT / "convection" / "config"

SECTIONS = frozenset(SCHEMA) - {"name"}  # "name" is every registry entry's too
"""The config's sections: a string key among these indexes a config mapping."""

SECTION_READS = {
    ("convection/io/continuation.py", "energy"): "the degree of the source run's temperature, from its checkpoint",
}
"""(module, section) -> why it is read there."""

CONFIG_PARAMETERS = {
    ("convection/app/factory.py", "build_model"): "the public door: makes the RunSettings (config.settings)",
    ("convection/app/factory.py", "run_config"): "the public door: makes the RunSettings; writes the document",
    ("convection/io/checkpoint.py", "write_checkpoint"): "a checkpoint keeps the resolved document, unread",
    ("convection/io/checkpoint.py", "__init__"): "the Checkpointer keeps the resolved document, unread",
}
"""(module, function) -> why it takes the config mapping."""

FROM_CONFIG: dict[tuple[str, str], str] = {}
"""(module, function) -> why it builds from raw config values (item 4 of issue 47: one way to
declare a parameter)."""


def _modules():
    for path in sorted((ROOT / "convection").rglob("*.py")):
        if FRONT_END not in path.parents:
            yield path.relative_to(ROOT).as_posix(), ast.parse(path.read_text())


def _read(node: ast.AST) -> tuple[ast.AST, str] | None:
    """(What is read from, the constant text key) of a subscript or ``.get``-like call, else None."""
    if isinstance(node, ast.Subscript):
        target, key = node.value, node.slice
    elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
          and node.func.attr in ("get", "pop", "setdefault") and node.args):
        target, key = node.func.value, node.args[0]
    else:
        return None
    return (target, key.value) if isinstance(key, ast.Constant) and isinstance(key.value, str) else None


def _config_like(node: ast.AST) -> bool:
    name = node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else ""
    return "config" in name or "cfg" in name or name == "document"


def _section_key(node: ast.AST) -> str | None:
    """The section ``node`` reads as a config section, if any (see the module docstring)."""
    outer = _read(node)
    if outer is None:
        return None
    target, key = outer
    if key in SECTIONS and _config_like(target):
        return key
    inner = _read(target)  # x["section"]["key"], x["section"].get("key")
    return inner[1] if inner is not None and inner[1] in SECTIONS else None


def _section_reads():
    for module, tree in _modules():
        for node in ast.walk(tree):
            key = _section_key(node)
            if key is not None:
                yield module, key, node.lineno


def _functions():
    for module, tree in _modules():
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                yield module, node


def _takes_config(function: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    arguments = function.args
    for argument in (*arguments.posonlyargs, *arguments.args, *arguments.kwonlyargs):
        annotation = argument.annotation
        mapping = annotation is None or any(word in ast.unparse(annotation) for word in ("dict", "Mapping", "Any"))
        if mapping and (argument.arg in ("config", "cfg") or argument.arg.endswith("_config")):
            return True
    return False


def test_no_room_reads_a_config_section():
    wrong = [f"{module}:{line} reads config section {key!r}" for module, key, line in _section_reads()
             if (module, key) not in SECTION_READS]
    assert not wrong, wrong


def test_no_room_takes_the_config_mapping():
    wrong = [f"{module}:{f.lineno} {f.name}() takes a config mapping" for module, f in _functions()
             if _takes_config(f) and (module, f.name) not in CONFIG_PARAMETERS]
    assert not wrong, wrong


def test_no_room_builds_from_raw_config_values():
    wrong = [f"{module}:{f.lineno} {f.name}()" for module, f in _functions()
             if (f.name == "from_config" or f.name.endswith("_from_config")) and (module, f.name) not in FROM_CONFIG]
    assert not wrong, wrong


def test_the_allow_lists_hold_only_what_is_still_there():
    """A module converted leaves the lists: an entry that no longer matches is an error."""
    reads = {(module, key) for module, key, _ in _section_reads()}
    functions = {(module, f.name) for module, f in _functions()}
    takes = {(module, f.name) for module, f in _functions() if _takes_config(f)}
    assert set(SECTION_READS) <= reads, sorted(set(SECTION_READS) - reads)
    assert set(CONFIG_PARAMETERS) <= takes, sorted(set(CONFIG_PARAMETERS) - takes)
    assert set(FROM_CONFIG) <= functions, sorted(set(FROM_CONFIG) - functions)


def test_the_checks_catch_a_raw_read():
    """The scan sees the forms a regression would take."""
    tree = ast.parse("def f(run_config):\n    a = config['adaptivity']\n    b = cfg.get('balance')\n"
                     "    c = x['stokes']['solver']\n    d = x['mesh'].get('cells')\n    e = parts['time']\n")
    keys = [_section_key(node) for node in ast.walk(tree)]
    assert {"adaptivity", "balance", "stokes", "mesh"} <= set(keys) and "time" not in keys
    assert _takes_config(next(n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)))


def _raw_values(value, where: str):
    """Where a mapping or a list sits in ``value`` (dataclasses, tuples and mappings searched)."""
    import dataclasses
    from collections.abc import Mapping

    if isinstance(value, (dict, list)):
        yield where
    if dataclasses.is_dataclass(value):
        for f in dataclasses.fields(value):
            yield from _raw_values(getattr(value, f.name), f"{where}.{f.name}")
    elif isinstance(value, Mapping):
        for key, item in value.items():
            yield from _raw_values(item, f"{where}.{key}")
    elif isinstance(value, tuple):
        for i, item in enumerate(value):
            yield from _raw_values(item, f"{where}[{i}]")


def test_the_boundary_section_is_typed(tmp_path):
    """The ``boundary`` section reaches the rooms typed: each velocity condition its kind's name
    and its kind's ``Settings`` (None: traction free), each temperature condition a
    ``TemperatureBC``; no mapping or list of the document is left in it, and the conditions are
    built through the registry."""
    from convection.config.loader import config_domain, load_config
    from convection.config.settings import run_settings
    from convection.geometry.boundary import (
        DEFAULT_TEMPERATURE, DEFAULT_VELOCITY, VELOCITY_BC_KINDS, PrescribedSettings, TemperatureBC, VelocityBC,
        VelocityCondition,
    )

    config = load_config(None, document={
        "mesh": {"cells": [4, 4]}, "physics": {"Ra": 1e4}, "time": {"end": 1}, "output": {"directory": str(tmp_path)},
        "boundary": {"velocity": {"top": {"kind": "prescribed", "value": [1, "x"]}, "bottom": "no_slip", "left": None},
                     "temperature": {"top": {"dirichlet": 0}, "bottom": {"dirichlet": "1"}}}})
    boundary = run_settings(config).boundary
    assert not list(_raw_values(boundary, "boundary"))
    velocity = boundary.velocity
    assert velocity["top"] == VelocityCondition("prescribed", PrescribedSettings((1.0, "x")))
    assert isinstance(velocity["top"].settings.value[0], float)
    assert velocity["bottom"].kind == "no_slip" and velocity["left"] is None and velocity["right"] == DEFAULT_VELOCITY
    assert all(isinstance(c.settings, VELOCITY_BC_KINDS[c.kind].Settings) for c in velocity.values() if c is not None)
    assert boundary.temperature == {"left": DEFAULT_TEMPERATURE, "right": DEFAULT_TEMPERATURE,
                                    "bottom": TemperatureBC("dirichlet", 1.0), "top": TemperatureBC("dirichlet", 0.0),
                                    "front": DEFAULT_TEMPERATURE, "back": DEFAULT_TEMPERATURE}
    assert boundary.velocity_bcs(config_domain(config)) == {
        "right": VelocityBC("free_slip"), "bottom": VelocityBC("no_slip"), "top": VelocityBC("prescribed", (1.0, "x"))}


def test_particle_plugins_declare_their_parameters_once():
    """A particle plugin's parameters are the fields of its frozen ``Settings``, made by
    :func:`fembase.params.param` with their help (the config reference reads it there; nothing is
    scraped from a docstring), and the plugin itself holds no parameter of its own: it is made by
    ``build(settings, context)`` and keeps the settings."""
    import dataclasses

    from particles.generation import GENERATORS
    from particles.interpolation import INTERPOLATORS
    from particles.properties import PROPERTIES

    plugins = [(name, cls) for registry in (GENERATORS, PROPERTIES, INTERPOLATORS) for name, cls in registry.items()]
    assert len(plugins) == len(GENERATORS) + len(PROPERTIES) + len(INTERPOLATORS) >= 27
    wrong = [f"{name}.{f.name}" for name, cls in plugins for f in dataclasses.fields(cls.Settings)
             if f.init and not f.name.startswith("_") and not f.metadata.get("schema", {}).get("help")]
    assert not wrong, wrong
    not_frozen = [name for name, cls in plugins if not cls.Settings.__dataclass_params__.frozen]
    assert not not_frozen, not_frozen
    own = [name for name, cls in plugins if dataclasses.is_dataclass(cls) or "build" not in dir(cls)]
    assert not own, f"a plugin that is a dataclass of its own parameters, or has no build: {own}"
