"""Bad configuration inputs give one line naming the key, exit code 2, no traceback, no hang.

Each case runs the real CLI under ``mpirun -n 2`` (and once serially) in a subprocess.
"""

import os
import sys
from pathlib import Path

import pytest

from convection.config.loader import ConfigError, load_config
from convection.launch import mpirun

from _runs import guarded_run

ROOT = Path(__file__).resolve().parents[3]
GOOD = ROOT / "configs" / "blankenbach_1a.yaml"


def _run(args, *, ranks=2, budget=120):
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    cmd = [sys.executable, "-m", "convection", *args]
    if ranks > 1:
        cmd = [*mpirun(ranks), *cmd]
    return guarded_run(cmd, cwd=ROOT, env=env, budget=budget)


def _write(tmp_path, text):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    return str(path)


CASES = {
    "unknown key": (["run", str(GOOD), "--set", "mesh.colls=[4,4]"], "mesh.colls"),
    "wrong type": (["run", str(GOOD), "--set", "physics.Ra=hot"], "physics.Ra"),
    "missing file": (["run", "configs/does_not_exist.yaml"], "not found"),
    "negative end time": (["run", str(GOOD), "--set", "time.end=-1"], "time.end"),
    "bad choice": (["run", str(GOOD), "--set", "stokes.solver=magic"], "stokes.solver"),
    "schur approximation of the direct solver": (["run", str(GOOD), "--set", "stokes.schur=wbfbt"], "stokes.schur"),
    "bad expression": (["run", str(GOOD), "--set", "initial.temperature=1-q"], "initial.temperature"),
    "negative particles per cell": (["run", str(GOOD), "--set", "particles.generator.particles_per_cell=-5"],
                                    "particles.generator"),
    "missing particle file": (["run", str(GOOD), "--set", "particles.generator={name: from_file, path: nowhere.txt}"],
                              "'nowhere.txt' not found"),
    "unknown particle property": (["run", str(GOOD), "--set", "particles.properties=[velocity, strain]"],
                                  "particles.properties[1]"),
    "property without the one it reads": (["run", str(GOOD), "--set", "particles.enabled=true",
                                           "--set", "particles.properties=[velocity, displacement]"],
                                          "particles.properties[1]': 'displacement' needs the particle property "
                                          "'initial_position'"),
    "unknown material key": (["run", str(GOOD), "--set", "materials={lid: {initial: 'z > 0.8', density: 1}}"],
                             "materials.lid.density"),
    "runaway integer power": (["run", str(GOOD), "--set", "initial.temperature=9**9**9"], "initial.temperature"),
    "runaway refinement": (["run", str(GOOD), "--set", "adaptivity.enabled=true", "--set", "adaptivity.max_level=50"],
                           "adaptivity.max_level"),
    "too many particles": (["run", str(GOOD), "--set", "particles.enabled=true",
                            "--set", "particles.generator.particles_per_cell=1e7"], "particles_per_cell"),
    "compressible without Di": (["run", str(GOOD), "--set", "physics.approximation=tala"], "physics.reference.Di"),
    "phase transition density jump without units": (["run", str(GOOD), "--set", "phase_transitions={p: {depth: 0.5, "
                                                     "width: 0.05, density_jump: 0.08}}"],
                                                     "phase_transitions.p.density_jump"),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_bad_input_under_mpirun(name):
    args, needle = CASES[name]
    proc = _run(args, ranks=2)
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, proc.stderr  # printed once (rank 0), one line
    assert needle in lines[0]
    assert "Traceback" not in proc.stderr


def test_missing_required_value(tmp_path):
    path = _write(tmp_path, "mesh: {cells: [4, 4]}\nphysics: {Ra: 1e4}\noutput: {directory: out}\n")
    proc = _run(["run", path], ranks=1)
    assert proc.returncode == 2
    assert proc.stderr.strip() == "error: config key 'time.end': required value missing (end time (nondimensional))"


def test_invalid_yaml(tmp_path):
    proc = _run(["run", _write(tmp_path, "mesh: [cells: 4\n")], ranks=1)
    assert proc.returncode == 2 and "invalid YAML" in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.parametrize("overrides, message", [
    # a value with a unit is reported as written, not as the solver's number (-99.99999999999999)
    (["materials.block.viscosity=-1e23 Pa s"],
     "config key 'materials.block.viscosity': expected a positive number or a law {name: ..., ...}, got -1e23 Pa s"),
    (["time.end=-3 Myr"], "config key 'time.end': must be > 0.0, got -3 Myr"),
    # a viscosity law's parameter, nested laws included, at its key as written
    (["materials.block.viscosity={name: power_law, n: 3, eta0: -1e23 Pa s}"],
     "config key 'materials.block.viscosity.eta0': must be > 0.0, got -1e23 Pa s"),
    (["materials.block.viscosity={name: composite, laws: [1e23 Pa s, {name: von_mises, yield_stress: 1 MPa, "
      "weakening: {end: 0}}]}"],
     "config key 'materials.block.viscosity.laws[1].weakening.end': must be > 0.5, got 0.0"),
    # a negative particle density is refused where it is, in the model's units (the run failed with exit 1)
    (["composition.source=particles",
      "particles.generator={name: random_density, num_particles: 100, density: 'z - 300*km', seed: 1}"],
     "config key 'particles.generator.density': 'z - 300*km' is -0.585938 at x = 0 km, z = 0 km: a density must be "
     ">= 0 everywhere"),
    (["composition.source=particles",
      "particles.generator={name: metropolis_hastings, num_particles: 100, density: '0*x', seed: 1}"],
     "config key 'particles.generator.density': '0*x' is 0 everywhere in the domain: no particle could be placed"),
    # a plugin's parameters are its Settings' fields: one it lacks is named with those it has
    (["composition.source=particles", "particles.generator={name: random_uniform, num_particles: 100, seeds: 1}"],
     "config key 'particles.generator': particle generator 'random_uniform' has no parameter 'seeds'; its "
     "parameters: ['num_particles', 'seed']"),
    (["composition.source=particles", "particles.interpolator={name: cell_average, mean: median}"],
     "config key 'particles.interpolator': unknown mean 'median'; valid: ['arithmetic', 'geometric', 'harmonic']"),
    (["composition.source=particles", "particles.properties=[{name: damage}, {name: damage, alpha: -1, label: d}]"],
     "config key 'particles.properties[1]': particle property 'damage' has no parameter 'label'; its parameters: "
     "['alpha', 'beta', 'initial', 'new_particles', 'update']"),
])
def test_check_refuses_in_the_users_terms(overrides, message):
    config = ROOT / "configs" / "sinking_block.yaml"
    proc = _run(["check", str(config), *[a for o in overrides for a in ("--set", o)]], ranks=1)
    assert proc.returncode == 2
    assert proc.stderr.strip() == f"error: {message}"


def test_invalid_yaml_names_line_and_column(tmp_path):
    """The line and column where PyYAML found the problem, and the problem."""
    with pytest.raises(ConfigError) as err:
        load_config(_write(tmp_path, "mesh:\n  cells: [8, 8]\n  upper: {a: 1\n  lower: [0, 0]\n"))
    assert str(err.value) == (f"config file '{tmp_path / 'bad.yaml'}': invalid YAML at line 4, column 8: expected ',' "
                              "or '}', but got ':'")


def test_check_prints_resolved_config():
    proc = _run(["check", str(GOOD), "--set", "time.end=0.5", "--output", "elsewhere"], ranks=1)
    assert proc.returncode == 0, proc.stderr
    assert "end: 0.5" in proc.stdout and "directory: elsewhere" in proc.stdout


def test_load_config_defaults_and_overrides():
    config = load_config(GOOD, ["mesh.cells=[8, 4]", "physics.Rb=1e3"])
    assert config["mesh"]["cells"] == [8, 4]
    assert config["physics"]["Rb"] == 1000.0  # "1e3" (a string for PyYAML) coerced to float
    assert config["adaptivity"]["enabled"] is False
    with pytest.raises(ConfigError, match="mesh.upper"):
        load_config(GOOD, ["mesh.lower=[0, 0]", "mesh.upper=[1, 0]"])
    with pytest.raises(ConfigError, match="boundary.velocity.top.value"):
        load_config(GOOD, ["boundary.velocity.top={kind: prescribed, value: [1, 0, 0]}"])


FAIL_ON_RANK_1 = """
import sys
from mpi4py import MPI
import convection.io.fields
output_function = convection.io.fields.FieldOutput._output_function
calls = []


def failing(self, name, f):
    calls.append(name)
    if len(calls) > 4 and MPI.COMM_WORLD.rank == 1:  # rank 1 alone, with the field file open
        raise RuntimeError("injected failure on rank 1")
    return output_function(self, name, f)


convection.io.fields.FieldOutput._output_function = failing
from convection.app.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_error_on_one_rank_stops_every_rank(tmp_path):
    """An unexpected error on one rank while the other is in a collective call (here: rank 1 fails
    between two fields of an output, rank 0 writes the next field): the run stops at once with one line naming the
    rank and exit code 1, instead of the other rank waiting forever (the run's cleanup, itself
    collective, is skipped then)."""
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    cmd = [*mpirun(2), sys.executable, "-c", FAIL_ON_RANK_1, "run", str(GOOD), "--output", str(tmp_path / "run"),
           "--set", "mesh.cells=[8,8]", "--set", "time.max_steps=3", "--set", "output.fields_every=1",
           "--set", "output.progress=none"]
    proc = guarded_run(cmd, cwd=ROOT, env=env, budget=120)
    assert proc.returncode != 0
    assert "error (rank 1): RuntimeError: injected failure on rank 1" in proc.stderr


def test_error_on_every_rank_prints_once(tmp_path):
    """The same unexpected error on every rank (here: both ranks fail at the same field output)
    prints one line for all of them, exit code 1, without an MPI abort."""
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    script = FAIL_ON_RANK_1.replace(" and MPI.COMM_WORLD.rank == 1", "").replace("on rank 1", "everywhere")
    cmd = [*mpirun(2), sys.executable, "-c", script, "run", str(GOOD), "--output", str(tmp_path / "run"),
           "--set", "mesh.cells=[8,8]", "--set", "time.max_steps=3", "--set", "output.fields_every=1",
           "--set", "output.progress=none"]
    proc = guarded_run(cmd, cwd=ROOT, env=env, budget=120)
    assert proc.returncode == 1, proc.stderr
    errors = [line for line in proc.stderr.splitlines() if "error" in line]
    assert errors[0] == ("error (every rank): RuntimeError: injected failure everywhere (--debug shows the "
                         "traceback)"), proc.stderr
    assert sum("injected failure" in line for line in proc.stderr.splitlines()) == 1, proc.stderr
    assert "MPI_ABORT" not in proc.stderr


@pytest.mark.parametrize("ranks", [1, 2])
@pytest.mark.parametrize("statistic, needle", [
    ("nusselt", "'nusselt' needs the energy equation (energy.enabled: true)"),
    ("entrainment", "'entrainment' needs diagnostics.entrainment_material"),
])
def test_statistic_that_does_not_apply_is_refused_by_check(tmp_path, ranks, statistic, needle):
    """A statistic the model cannot measure is a config error at check time (exit 2, one line)."""
    proc = _run(["check", str(GOOD), "--set", "energy.enabled=false", "--set", "initial.composition=z < 0.2",
                 "--set", f"output.statistics=[time, {statistic}]"], ranks=ranks)
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("error")]
    assert len(lines) == 1 and lines[0].startswith(f"error: config key 'output.statistics': {needle}"), proc.stderr
