"""Several particle systems in a config: the list form, its names, --set into a listed system,
composition.particle_system, per-system checks, and a checkpoint that lacks a system's part."""

from __future__ import annotations

import shutil

import pytest
import yaml

from _runs import CONFIGS, error_line, run_cli, sets

from convection.config.loader import dump_config, load_config
from convection.config.particle_systems import particle_sections, primary_system
from convection.schema import ConfigError

CONFIG = CONFIGS / "vankeken_1a_tracers.yaml"


def _document():
    return yaml.safe_load(CONFIG.read_text())


def test_the_list_form_resolves_and_round_trips():
    config = load_config(CONFIG, ["particles.tracers.output.every_steps=2", "particles.0.population.min_per_cell=3"])
    sections = particle_sections(config)
    assert list(sections) == ["dense", "tracers"] and primary_system(config) == "dense"
    assert sections["tracers"]["output"]["every_steps"] == 2 and sections["dense"]["population"]["min_per_cell"] == 3
    assert sections["tracers"]["interpolator"] == {"name": "cell_average", "mean": "arithmetic"}  # a default
    assert load_config(None, document=yaml.safe_load(dump_config(config))) == config
    chosen = load_config(CONFIG, ["composition.particle_system=tracers", "particles.tracers.properties=[]",
                                  "particles.tracers.output.properties=null"])
    assert primary_system(chosen) == "tracers"


def test_one_mapping_is_one_system_named_particles():
    config = load_config(CONFIGS / "vankeken_1a.yaml")
    assert list(particle_sections(config)) == ["particles"] and primary_system(config) == "particles"
    assert particle_sections(load_config(CONFIGS / "blankenbach_1a.yaml")) == {}


@pytest.mark.parametrize("change, key", [
    (lambda d: d.update(particles=[]), "'particles': an empty list"),
    (lambda d: d["particles"].append(dict(d["particles"][0])), "'particles[2].name': 'dense' names two systems"),
    (lambda d: d["particles"][1].update(name="has space"), "'particles[1].name': expected a name"),
    (lambda d: d["particles"][1].pop("name"), "'particles[1].name'"),
    (lambda d: d["particles"].__setitem__(1, "tracers"), "'particles[1]': expected a system"),
    (lambda d: d["particles"][1].update(enabled=True), "'particles.tracers.enabled': unknown"),
    (lambda d: d["particles"][1].update(integrator="rk9"), "'particles.tracers.integrator'"),
    (lambda d: d["particles"][1]["generator"].update(name="nope"), "'particles.tracers.generator'"),
    (lambda d: d["particles"][1]["output"].update(properties=["dense"]),
     "'particles.tracers.output.properties': 'dense' is not carried"),
    (lambda d: d.setdefault("composition", {}).update(particle_system="x"),
     "'composition.particle_system': 'x' is not a particle system"),
    (lambda d: d["particles"][1]["generator"].update(num_particles=2e8), "'particles.tracers.generator.num_particles'"),
])
def test_refused_with_the_key(change, key):
    document = _document()
    change(document)
    with pytest.raises(ConfigError, match="config key " + key.replace("[", r"\[").replace("]", r"\]")
                       .replace("(", r"\(").replace(")", r"\)")):
        load_config(None, document=document)


def test_the_materials_go_to_the_primary_system_only():
    """The tracers do not carry the composition: asking their output for it is refused; the dense
    system's output may write it."""
    with pytest.raises(ConfigError, match="'particles.tracers.output.properties': 'composition' is not carried"):
        load_config(CONFIG, ["particles.tracers.output.properties=[composition]"])
    load_config(CONFIG, ["particles.dense.output.properties=[composition]", "particles.dense.output.every_steps=5"])


def test_set_into_a_list_names_what_is_wrong():
    with pytest.raises(ConfigError, match="'nope' is neither an index nor the name"):
        load_config(CONFIG, ["particles.nope.seed=1"])
    with pytest.raises(ConfigError, match="'particles.5' is not a section|'5' is neither"):
        load_config(CONFIG, ["particles.5.seed=1"])


def test_a_checkpoint_without_a_systems_part_is_refused(tmp_path):
    """A checkpoint folder holds one swarm file per system; one missing is named, no traceback."""
    run = tmp_path / "run"
    proc = run_cli(["run", str(CONFIG), "--output", str(run), *sets(["mesh.cells=[8,8]", "time.max_steps=2",
                                                                     "output.progress=none"])])
    assert proc.returncode == 0, proc.stderr
    checkpoint = sorted((run / "checkpoints").iterdir())[-1]
    assert (checkpoint / "particles_dense.h5").is_file() and (checkpoint / "particles_tracers.h5").is_file()
    (checkpoint / "particles_tracers.h5").unlink()
    line = error_line(run_cli(["resume", str(run)]), 1, "particles_tracers.h5 is missing")
    assert "particles_tracers.h5" in line
    shutil.rmtree(run)
