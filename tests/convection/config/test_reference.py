"""The generated config reference (``python -m convection schema``, docs/config-reference.md):
complete against the schema and the registries, committed as generated, and its YAML form a
valid config at the defaults."""

from __future__ import annotations

import dataclasses
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from convection.config.loader import SCHEMA, load_config
from convection.geometry.registry import DOMAINS
from convection.config.reference import render_markdown, render_yaml
from convection.schema import REQUIRED, Field, Names

ROOT = Path(__file__).resolve().parents[3]
COMMITTED = ROOT / "docs" / "config-reference.md"


def _leaves(schema, prefix=""):
    """(dotted key, Field) of every leaf, walked here independently of convection.config.reference."""
    for name, node in schema.items():
        key = prefix + name
        if isinstance(node, Field):
            yield key, node
            for sub, item in (node.items or {}).items():
                yield f"{key}.{'<material>' if name == 'materials' else '<name>'}.{sub}", item
        else:
            yield from _leaves(node, key + ".")


@pytest.fixture(scope="module")
def markdown() -> str:
    return render_markdown()


def _section(markdown: str, heading: str) -> str:
    """The text under a Markdown heading line, up to the next heading of the same or a higher level."""
    level = heading.split(" ")[0]
    start = markdown.index("\n" + heading + "\n")
    rest = markdown[start + len(heading) + 2:]
    match = re.search(rf"\n#{{1,{len(level)}}} ", rest)
    return rest[: match.start()] if match else rest


def test_committed_reference_is_the_generated_one(markdown):
    assert COMMITTED.read_text() == markdown, (
        "docs/config-reference.md is out of date: regenerate it with "
        "`python -m convection schema > docs/config-reference.md`")


def test_every_key_is_listed_with_help_and_default(markdown):
    keys = list(_leaves(SCHEMA))
    assert len(keys) > 100
    rows = {m.group(1): m.group(0) for m in re.finditer(r"^\| `([^`]+)` \|.*$", markdown, re.M)}
    for key, field in keys:
        assert key in rows, f"{key} missing from the reference"
        assert field.help, f"{key} has no help text"
        assert field.help.replace("|", "\\|") in rows[key]
        expected = "`required`" if field.default is REQUIRED else None
        if expected:
            assert expected in rows[key]


def test_every_registry_name_is_listed_under_its_key(markdown):
    checked = 0
    for key, field in _leaves(SCHEMA):
        if isinstance(field.choices, Names):
            names = list(field.choices.registry())
            assert names
            text = _section(markdown, f"### `{key}`")
            for name in names:
                assert f"- `{name}`: " in text, f"{key}: {name} missing"
                checked += 1
    assert checked > 40


def test_every_plugin_and_parameter_is_listed(markdown):
    from convection.physics.rheology import VISCOSITY_LAWS
    from particles.generation import GENERATORS
    from particles.interpolation import INTERPOLATORS
    from particles.properties import PROPERTIES

    for title, registry in (("Particle generators", GENERATORS), ("Particle properties", PROPERTIES),
                            ("Particle interpolators", INTERPOLATORS), ("Viscosity laws", VISCOSITY_LAWS)):
        text = _section(markdown, f"### {title}")
        for name, cls in registry.items():
            entry = _section(text, f"#### `{name}`")
            assert cls.description[1:] in entry
            for f in dataclasses.fields(getattr(cls, "Settings", cls)):  # a plugin's parameters: its Settings
                if f.init and not f.name.startswith("_"):
                    assert re.search(rf"^\| `{f.name}` \|", entry, re.M), f"{title} {name}: {f.name} missing"
        if title == "Viscosity laws":
            for name in registry:
                assert re.search(r"^\| `min_viscosity` \|", _section(text, f"#### `{name}`"), re.M), name


def test_yaml_form_holds_every_key_and_loads_as_a_config(tmp_path):
    document = yaml.safe_load(render_yaml())

    def flat(mapping, prefix=""):
        for name, value in mapping.items():
            if isinstance(value, dict) and not (prefix + name).endswith(("generator", "interpolator")) \
                    and name not in ("materials", "phase_transitions", "constants", "petsc_options", "points"):
                yield from flat(value, prefix + name + ".")
            else:
                yield prefix + name, value

    values = dict(flat(document))
    box = DOMAINS["box"]
    other = {key for key, _ in _leaves(SCHEMA)
             if key.startswith("boundary.") and key.split(".")[-1] not in box.config_boundaries
             or key.startswith("mesh.") and key.split(".")[-1] not in (*box.config_keys, "geometry", "max_cells")}
    assert {key.split(".")[-1] for key in other} == {"inner", "outer", "west", "east", "radii", "angles", "resolution",
                                                     "geometry_degree"}
    for key in other:  # commented out: the YAML form's mesh is a box
        assert re.search(rf"^ +# {key.split('.')[-1]}: ", render_yaml(), re.M), key
    expected = {key: field for key, field in _leaves(SCHEMA) if "<" not in key and key not in other}
    assert set(values) == set(expected)
    for key, field in expected.items():
        assert values[key] == (None if field.default is REQUIRED else field.default), key
    document["physics"]["Ra"] = 1.0e4
    document["time"]["end"] = 0.1
    document["output"]["directory"] = str(tmp_path / "out")
    document["mesh"]["cells"] = [4, 4]
    config = load_config(None, document=document)
    assert config["mesh"]["cells"] == [4, 4] and config["stokes"]["solver"] == "auto"


def test_cli_prints_the_reference(markdown):
    out = subprocess.run([sys.executable, "-m", "convection", "schema"], cwd=ROOT, capture_output=True, text=True,
                         check=True)
    assert out.stdout == markdown
    yaml_out = subprocess.run([sys.executable, "-m", "convection", "schema", "--format", "yaml"], cwd=ROOT,
                              capture_output=True, text=True, check=True)
    assert yaml_out.stdout == render_yaml()
