"""Hostile configuration input: one line on stderr, the documented exit code, on 1 and 2 ranks.

One table (:data:`CASES`) of bad inputs — ``--set`` overrides or whole config files — each with the
expected exit code and a piece of the expected one-line message. Every case runs through the real
CLI (``python -m convection check``) in a subprocess on one rank; the cases marked ``two_ranks``
also under ``mpirun -n 2``, and those marked ``run`` also through ``run``, which must refuse them
before it creates the run folder. A few accepted inputs (code 0) guard against over-refusal.
The unit tests at the end check each mechanism in-process (fast).

These tests start ``mpirun`` themselves, so they are plain (not ``mpi``-marked) tests.
"""

from __future__ import annotations

import math
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import yaml

from convection.config.loader import load_config
from convection.expressions import MAX_LENGTH, Expression, ExpressionError
from convection.launch import RANK_SHELL, mpi_environment, mpirun
from convection.geometry.probes import MAX_PROBES, boundary_probes, domain_probes
from convection.config.loader import config_domain as domain_from_config
from convection.schema import ConfigError, check_document_shape, short_repr

from _runs import guarded_run

ROOT = Path(__file__).resolve().parents[3]
BOX = "configs/blankenbach_1a.yaml"
SHELL = "configs/annulus_layer.yaml"
BASE = "mesh: {cells: [4, 4]}\nphysics: {Ra: 1.0e4}\ntime: {end: 0.01}\noutput: {directory: '{out}'}\n"
"""A minimal config text; ``{out}`` becomes a folder under tmp_path."""
PARTICLES = "particles.enabled=true"
ABORT_SIGNS = ("MPI_ABORT", "mpirun has exited", "Traceback", "mpirun noticed", "prterun has exited", "prterun noticed")
"""Signs of an Open MPI abort block (Open MPI 4 says mpirun, Open MPI 5 prterun) or a traceback."""


def _alias_bomb(levels: int = 9) -> str:
    """A YAML flow list whose aliases expand to 9**levels items (a few hundred bytes of text)."""
    items = ["&a0 [" + ", ".join(["1"] * 9) + "]"]
    items += [f"&a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, levels)]
    return "[" + ", ".join(items) + "]"


def _sum(terms: int) -> str:
    return "+".join(["x"] * terms)


_TOWER = "(True+True)**(True+True)**(True+True)**(True+True)**(True+True)**(True+True)"


@dataclass(frozen=True)
class Case:
    """One hostile input.

    Attributes:
        id: Test id.
        sets: ``--set`` overrides (``{tmp}`` becomes tmp_path).
        code: Expected exit code.
        needle: A piece of the expected ``error:`` line (empty for code 0).
        text: Config file text instead of ``config`` (``{out}`` as in :data:`BASE`); bytes are
            written as they are.
        config: The config file (relative to the project) when ``text`` is None.
        two_ranks: Also run under ``mpirun -n 2``.
        run: Also through ``run``, which must refuse it before creating the run folder.
    """

    id: str
    sets: tuple[str, ...] = ()
    code: int = 2
    needle: str = ""
    text: str | bytes | None = None
    config: str = BOX
    two_ranks: bool = False
    run: bool = False


CASES = [
    # -- non-finite numbers in float keys (NaN passes < and <= bounds: runs that never end) --
    Case("end inf", ("time.end=.inf",), needle="'time.end': must be a finite number, got inf", run=True),
    Case("end nan", ("time.end=.nan",), needle="'time.end': must be a finite number, got nan", two_ranks=True),
    Case("end nan text", ("time.end=nan",), needle="'time.end': must be a finite number"),
    Case("end Infinity text", ("time.end=Infinity",), needle="'time.end': must be a finite number"),
    Case("end 400 digits", ("time.end=" + "1" * 400 + ".0",), needle="'time.end': must be a finite number"),
    Case("Ra nan", ("physics.Ra=.nan",), needle="'physics.Ra': must be a finite number", two_ranks=True, run=True),
    Case("box corner inf", ("mesh.upper=[1, .inf]",), needle="'mesh.upper[1]': must be a finite number"),
    Case("dirichlet nan", ("boundary.temperature.bottom={dirichlet: .nan}",),
         needle="'boundary.temperature.bottom.dirichlet': must be a finite number"),
    Case("dirichlet Infinity text", ("boundary.temperature.bottom={dirichlet: Infinity}",),
         needle="'boundary.temperature.bottom.dirichlet': must be a finite number"),
    Case("prescribed velocity inf", ("boundary.velocity.top={kind: prescribed, value: [.inf, 0]}",),
         needle="'boundary.velocity.top.value[0]': must be a finite number"),
    Case("material Rb nan", ("materials={lid: {initial: 'z > 0.8', Rb: .nan}}",),
         needle="'materials.lid.Rb': must be a finite number"),
    Case("constant inf", ("initial.constants={A: .inf}",), needle="'initial.constants.A': must be a finite number"),
    Case("petsc tolerance nan", ("stokes.petsc_options={ksp_rtol: .nan}",),
         needle="'stokes.petsc_options.ksp_rtol': must be a finite number"),
    Case("particles per cell nan", (PARTICLES, "particles.generator={name: random_uniform, particles_per_cell: .nan}"),
         needle="'particles.generator.particles_per_cell': must be a finite number"),
    Case("plate rate nan", ("boundary.velocity.outer={kind: plates, width: 0.1, plates: [{centre: [0], rate: .nan}]}",),
         config=SHELL, needle="'boundary.velocity.outer.plates[0].rate': must be a finite number"),
    Case("end 10 million digits", text=BASE.replace("end: 0.01", "end: " + "1" * 10_000_000),
         needle="MiB, more than a config may have"),
    Case("end 1000 digits in a file", text=BASE.replace("end: 0.01", "end: " + "1" * 1000 + ".0"),
         needle="'time.end': must be a finite number, got inf"),
    Case("integer 5000 digits in a file", text=BASE.replace("end: 0.01", "end: " + "1" * 5000),
         needle="a value cannot be read: Exceeds the limit (4300 digits)"),
    Case("integer 5000 digits", ("time.max_steps=" + "1" * 5000,),
         needle="--set time.max_steps: a value cannot be read"),
    # -- what ended in an MPI abort on 2 ranks --
    Case("prescribed 1/0", ("boundary.velocity.top={kind: prescribed, value: ['1/0', '0']}",),
         needle="'boundary.velocity.top.value[0]': '1/0' is inf", two_ranks=True, run=True),
    Case("5000-term expression", (f"initial.temperature={_sum(5000)}",),
         needle="'initial.temperature': 'x+x+", two_ranks=True, run=True),
    Case("5000-term velocity", (f"boundary.velocity.top={{kind: prescribed, value: ['{_sum(5000)}', 0]}}",),
         needle=f"longer than {MAX_LENGTH} characters"),
    Case("output folder is a file", ("output.directory={tmp}/a_file",),
         needle="'output.directory': ", two_ranks=True, run=True),
    Case("output folder inside a file", ("output.directory={tmp}/a_file/run",), needle="which is not a folder"),
    Case("output folder empty", ("output.directory=''",), needle="'output.directory': must name a folder",
         two_ranks=True),
    Case("output folder blank", ("output.directory='  '",), needle="'output.directory': must name a folder"),
    Case("output folder NUL", text=BASE.replace("{out}", '"out\\0x"').replace("'", ""),
         needle="'output.directory': must not contain a NUL"),
    # -- wrong exit code through the generic handler --
    Case("not UTF-8", text=b"name: \xff\xfe\n" + BASE.encode(), needle="not UTF-8 text (byte 0xff at line 1)",
         two_ranks=True),
    Case("nested 5000 deep", text=BASE + "name: " + "[" * 5000 + "]" * 5000 + "\n", needle="nested too deeply",
         two_ranks=True),
    Case("nested 100 deep", text=BASE + "stokes: {petsc_options: {a: " + "[" * 100 + "]" * 100 + "}}\n",
         needle="'stokes.petsc_options.a[0][0][0]"),
    Case("nested 5000 deep in --set", ("stokes.petsc_options={a: " + "[" * 5000 + "]" * 5000 + "}",),
         needle="--set stokes.petsc_options: nested too deeply"),
    Case("unknown keys of mixed types", text=BASE + "1: one\nfoo: two\n", needle="config key '1': keys must be names",
         two_ranks=True),
    Case("unknown entry of mixed types", ("boundary.velocity.top={kind: no_slip, 1: a, foo: b}",),
         needle="'boundary.velocity.top.1': keys must be names (text), got int 1"),
    Case("plate entries of mixed types", ("boundary.velocity.outer={kind: plates, plates: [{centre: [0], rate: 1, "
                                          "1: 2, b: 3}]}",), config=SHELL,
         needle="'boundary.velocity.outer.plates[0].1': keys must be names"),
    Case("velocity kind unknown", ("boundary.velocity.top=slip",),
         needle="'boundary.velocity.top': velocity condition 'slip' is not one of ['free_slip', 'no_slip', "),
    Case("prescribed by name alone", ("boundary.velocity.top=prescribed",),
         needle="'boundary.velocity.top': a prescribed velocity needs the form {kind: prescribed, value: [vx, vy("
                ", vz)]}"),
    Case("prescribed without value", ("boundary.velocity.top={kind: prescribed}",),
         needle="'boundary.velocity.top': a prescribed velocity needs 'value: [vx, vy(, vz)]'"),
    Case("prescribed component a list", ("boundary.velocity.top={kind: prescribed, value: [[1], 0]}",),
         needle="'boundary.velocity.top': value[0]: [1] must be a finite number or an expression"),
    Case("entry of a kind without entries", ("boundary.velocity.top={kind: no_slip, value: [0, 0]}",),
         needle="'boundary.velocity.top': unknown entry 'value'; allowed: ['kind']"),
    Case("plates width a text", ("boundary.velocity.outer={kind: plates, width: wide, plates: [{centre: [0], "
                                 "rate: 1}]}",), config=SHELL,
         needle="'boundary.velocity.outer': plates width must be a number, got 'wide'"),
    Case("interpolator name a list", ("particles.interpolator={name: [1]}",),
         needle="'particles.interpolator.name': [1] is not one of"),
    Case("cells 1.0e+308", ("mesh.cells=[1.0e+308, 4]",), needle="'mesh.cells[0]': must be an integer within +-2**63",
         two_ranks=True),
    Case("cells 1e308", ("mesh.cells=[1e308, 4]",), needle="'mesh.cells[0]': must be an integer within +-2**63"),
    Case("cells product beyond int64", ("mesh.cells=[4000000000000000000, 4000000000000000000]",),
         needle="'mesh.cells': the mesh can reach 3.2e+37 cells"),
    Case("box size overflows", ("mesh.lower=[-1e308, 0]", "mesh.upper=[1e308, 1]"),
         needle="'mesh.upper': the box size upper - lower must be a finite number"),
    Case("shell radii 1e300", ("mesh.radii=[1, 1e300]",), config=SHELL,
         needle="'mesh.resolution': the mesh can reach inf cells"),
    Case("shell resolution 1e-300", ("mesh.resolution=1e-300",), config=SHELL,
         needle="'mesh.resolution': the mesh can reach inf cells"),
    Case("max level 10**12", ("adaptivity.enabled=true", "adaptivity.max_level=1000000000000"),
         needle="'adaptivity.max_level': the mesh can reach inf cells"),
    Case("seed beyond int64", ("particles.population.seed=100000000000000000000",),
         needle="'particles.population.seed': must be an integer within +-2**63"),
    Case("generator seed beyond int64", ("particles.generator={name: random_uniform, particles_per_cell: 2, "
                                         "seed: 100000000000000000000}",),
         needle="'particles.generator.seed': must be an integer within +-2**63"),
    # -- accepted, then failing in the run: now refused by check --
    Case("property 1/0", (PARTICLES, "particles.properties=[{name: function, function: '1/0'}]"),
         needle="'particles.properties[0]': '1/0' is inf"),
    Case("property 10.0**400", (PARTICLES, "particles.properties=[{name: function, function: '10.0**400'}]"),
         needle="'particles.properties[0]': '10.0**400' is inf"),
    Case("property sqrt(-1)", (PARTICLES, "particles.properties=[{name: function, function: 'sqrt(-1)'}]"),
         needle="'particles.properties[0]': 'sqrt(-1)' is nan"),
    Case("density 1/0", (PARTICLES, "particles.generator={name: random_density, num_particles: 100, density: '1/0'}"),
         needle="'particles.generator': '1/0' is inf"),
    Case("temperature pole inside", ("initial.temperature=1/(x-0.25)",),
         needle="'initial.temperature': '1/(x-0.25)' is inf at (0.25, 0)"),
    Case("temperature log on the boundary", ("initial.temperature=log(x)",),
         needle="'initial.temperature': 'log(x)' is -inf at (0, 0)"),
    Case("material log on the boundary", ("materials={lid: {initial: 'log(z)'}}",),
         needle="'materials.lid.initial': 'log(z)' is -inf"),
    Case("velocity log on its side", ("boundary.velocity.bottom={kind: prescribed, value: ['log(z)', 0]}",),
         needle="'boundary.velocity.bottom.value[0]': 'log(z)' is -inf"),
    Case("refine fraction 5", ("adaptivity.refine_fraction=5",), needle="'adaptivity.refine_fraction': must be <= 1.0"),
    Case("stokes degree 100", ("stokes.degree=100",), needle="'stokes.degree': must be <= 4", run=True),
    Case("energy degree 100", ("energy.degree=100",), needle="'energy.degree': must be <= 4"),
    Case("min per cell 10**12", (PARTICLES, "particles.population.min_per_cell=1000000000000"),
         needle="'particles.population.min_per_cell': up to", two_ranks=True),
    Case("num particles 1e12", (PARTICLES, "particles.generator={name: random_uniform, num_particles: 1e12}"),
         needle="'particles.generator.num_particles': up to 1e+12 particles"),
    Case("initial rounds 10**6", ("adaptivity.enabled=true", "adaptivity.initial_steps=1000000"),
         needle="'adaptivity.initial_steps': must be <= 100"),
    Case("dt_max 1e-300", ("time.dt_max=1e-300",), needle="'time.dt_max': time.end / time.dt_max = 2e+300 steps"),
    # -- memory exhaustion from a small config --
    Case("alias bomb in mesh.cells", text=BASE.replace("cells: [4, 4]", "cells: " + _alias_bomb()),
         needle="the config holds more than 100000 values"),
    Case("alias bomb in petsc_options", text=BASE + "stokes: {petsc_options: {bomb: " + _alias_bomb() + "}}\n",
         needle="the config holds more than 100000 values", two_ranks=True),
    Case("boolean power tower", (f"initial.temperature={_TOWER}",), needle="is inf at"),
    Case("comparison power tower", ("initial.temperature=((1<2)+(1<2))**((1<2)+(1<2))**((1<2)+(1<2))**"
                                    "((1<2)+(1<2))**((1<2)+(1<2))**((1<2)+(1<2))*0+1",), code=0),
    Case("constant power tower", ("initial.constants={A: 9}", "initial.temperature=A**A**A"), needle="is inf at"),
    Case("string formatting", ("initial.temperature='%2000000000s' % 1",),
         needle="only numbers may be literals", two_ranks=True),
    Case("keyword argument", ("initial.temperature=clip(x, a_min=0, a_max=1)",), needle="keyword arguments"),
    Case("1000 materials", ("materials={" + ", ".join(f"m{i}: {{initial: '0'}}" for i in range(1000)) + "}",),
         needle="'materials': 1000 entries, more than 100"),
    Case("huge string in a message", ("physics.Ra=" + "a" * 100_000,), needle="expected a number, got str 'aaa"),
    # -- writing outside the run folder --
    Case("petsc viewer to a file", ("stokes.petsc_options={ksp_view: 'ascii:{tmp}/petsc.txt'}",),
         needle="'stokes.petsc_options': option ksp_view:", two_ranks=True, run=True),
    Case("petsc binary viewer", ("stokes.petsc_options={ksp_view_mat: binary}",), needle="option ksp_view_mat:"),
    Case("petsc monitor to a file", ("stokes.petsc_options={ksp_monitor_true_residual: ':{tmp}/monitor.txt'}",),
         needle="option ksp_monitor_true_residual:"),
    Case("petsc draw", ("stokes.petsc_options={ksp_monitor_lg_residualnorm: draw}",),
         needle="option ksp_monitor_lg_residualnorm:"),
    Case("petsc option with a dash", ("stokes.petsc_options={'-log_view': ':{tmp}/log.txt'}",),
         needle="option name '-log_view' must be"),
    Case("petsc option list value", ("stokes.petsc_options={ksp_rtol: [1, 2]}",), needle="the value must be"),
    # -- accepted (no over-refusal) --
    Case("petsc viewers that print", ("stokes.petsc_options={ksp_view: '::ascii_info', ksp_converged_reason: null, "
                                      "ksp_monitor: ascii, ksp_rtol: 1e-8}",), code=0),
    Case("velocity log on the other side", ("boundary.velocity.top={kind: prescribed, value: ['log(z)', 0]}",), code=0),
    Case("guarded pole", ("initial.temperature=where(r > 0, 1/where(r > 0, r, 1), 0)",), code=0),
]

_BY_ID = {case.id: case for case in CASES}
assert len(_BY_ID) == len(CASES), "case ids must be unique"


def _env() -> dict[str, str]:
    return mpi_environment()


_RECORD_EXIT = '"$0" "$@"; code=$?; echo $code > "$RANK_EXITS/rank_' + RANK_SHELL + '"; exit 0'
"""Run the command and write its exit code to $RANK_EXITS/rank_N: mpirun reports only the first
non-zero one, so these show that every rank exits with the same code. (The wrapper itself exits
with 0, so that mpirun does not kill the other ranks when one exits non-zero — Open MPI 4 and 5
both do by default; test_mpirun_exit_code_and_one_line checks mpirun's own exit code.)"""


def _command(args: list[str], ranks: int = 1) -> list[str]:
    cmd = [sys.executable, "-m", "convection", *args]
    if ranks > 1:
        cmd = [*mpirun(ranks), "sh", "-c", _RECORD_EXIT, *cmd]
    return cmd


_PMIX_NOTICE = re.compile(r"^\[[^\]]*\] PMIX ERROR: ")
"""Open MPI 5's launcher (prterun) logs "[host:pid] PMIX ERROR: PMIX_ERR_UNREACH in file
.../pmix_server.c" when a rank exits while the launcher still talks to it: a launcher line, like its
dashed notices (open-mpi/ompi issue 7529)."""


def _own_lines(stderr: str) -> list[str]:
    """The non-empty lines of stderr without Open MPI's launcher notices (blocks between lines of
    dashes: "a process returned a non-zero exit code" on more than one rank; Open MPI 5's PMIx
    lines)."""
    lines, notice = [], False
    for line in stderr.splitlines():
        if line.strip() and set(line.strip()) == {"-"}:
            notice = not notice
        elif line.strip() and not notice and not _PMIX_NOTICE.match(line):
            lines.append(line)
    return lines


def _arguments(case: Case, command: str, tmp_path: Path) -> list[str]:
    """The CLI arguments of ``case`` (writing its config file and the file some cases point at)."""
    (tmp_path / "a_file").write_text("not a folder\n")
    if case.text is None:
        config = str(ROOT / case.config)
    else:
        path = tmp_path / "case.yaml"
        if isinstance(case.text, bytes):
            path.write_bytes(case.text.replace(b"{out}", str(tmp_path / "out").encode()))
        else:
            path.write_text(case.text.replace("{out}", str(tmp_path / "out")))
        config = str(path)
    args = [command, config]
    for item in case.sets:
        args += ["--set", item.replace("{tmp}", str(tmp_path))]
    if command == "run" and not any(s.startswith("output.directory=") for s in case.sets):
        args += ["--output", str(tmp_path / "run")]
    return args


def _assert_answer(case: Case, proc: subprocess.CompletedProcess, code: int) -> None:
    """Exit code, exactly one ``error:`` line holding the needle, and no abort or traceback."""
    for sign in ABORT_SIGNS:
        assert sign not in proc.stderr, proc.stderr[-2000:]
    assert code == case.code, proc.stderr[-2000:]
    if case.code == 0:
        return
    lines = _own_lines(proc.stderr)
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr[-2000:]
    assert case.needle in lines[0], lines[0]


def _answer(case: Case, command: str, tmp_path: Path, ranks: int = 1) -> None:
    """Run ``case`` through the CLI and check the answer; on more than one rank, every rank's exit code."""
    exits = tmp_path / "rank_exits"
    exits.mkdir()
    env = dict(_env(), RANK_EXITS=str(exits))
    proc = guarded_run(_command(_arguments(case, command, tmp_path), ranks), cwd=ROOT, env=env,
                       budget=300)
    code = proc.returncode
    if ranks > 1:
        codes = {path.name: int(path.read_text()) for path in exits.iterdir()}
        assert sorted(codes) == [f"rank_{r}" for r in range(ranks)] and len(set(codes.values())) == 1, codes
        code = codes["rank_0"]
    _assert_answer(case, proc, code)


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_check_answers_in_one_line(case, tmp_path):
    _answer(case, "check", tmp_path)


@pytest.mark.parametrize("case", [c for c in CASES if c.two_ranks], ids=[c.id for c in CASES if c.two_ranks])
def test_check_answers_in_one_line_on_two_ranks(case, tmp_path):
    _answer(case, "check", tmp_path, ranks=2)


@pytest.mark.parametrize("case", [c for c in CASES if c.run], ids=[c.id for c in CASES if c.run])
def test_run_refuses_before_starting(case, tmp_path):
    _answer(case, "run", tmp_path)
    assert not (tmp_path / "run").exists()
    assert not (tmp_path / "petsc.txt").exists()


@pytest.mark.parametrize("name", ["prescribed 1/0", "output folder is a file", "petsc viewer to a file"])
def test_run_refuses_before_starting_on_two_ranks(name, tmp_path):
    _answer(_BY_ID[name], "run", tmp_path, ranks=2)
    assert not (tmp_path / "run").exists()
    assert not (tmp_path / "petsc.txt").exists()


def test_mpirun_exit_code_and_one_line(tmp_path):
    """With mpirun's defaults (the other ranks stopped after the first non-zero exit), mpirun exits
    with the code, and apart from Open MPI's notice about that exit there is one line."""
    case = _BY_ID["end nan"]
    command = [*mpirun(2), sys.executable, "-m", "convection",
               *_arguments(case, "check", tmp_path)]
    proc = guarded_run(command, cwd=ROOT, env=_env(), budget=120)
    _assert_answer(case, proc, proc.returncode)


def test_output_folder_is_taken_literally(tmp_path):
    """``--output`` is a folder name, not YAML: ``123`` and ``run #1`` stay text; ``''`` is refused."""
    for name in ("123", "run #1"):
        proc = guarded_run(_command(["check", str(ROOT / BOX), "--output", str(tmp_path / name)]), cwd=ROOT,
                           env=_env(), budget=120)
        assert proc.returncode == 0, proc.stderr
        assert yaml.safe_load(proc.stdout)["output"]["directory"] == str(tmp_path / name)
    proc = guarded_run(_command(["check", str(ROOT / BOX), "--output", ""]), cwd=ROOT, env=_env(),
                       budget=120)
    assert proc.returncode == 2 and proc.stderr.startswith("error: config key 'output.directory': must name a folder")


def test_command_line_mistake_is_one_line():
    proc = guarded_run(_command(["run"]), cwd=ROOT, env=_env(), budget=120)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "config" in lines[0], proc.stderr


# ---- the mechanisms, in-process ----


def test_every_float_key_refuses_non_finite_values():
    """One check serves every float key: NaN, +-inf and their texts, in a scalar or a list."""
    from convection.config.loader import SCHEMA
    from convection.schema import Field

    def float_keys(schema, prefix=""):
        for name, spec in schema.items():
            if isinstance(spec, Field):
                if spec.kind in ("float", "list[float]"):
                    yield prefix + name, spec
            else:
                yield from float_keys(spec, f"{prefix}{name}.")

    keys = list(float_keys(SCHEMA))
    assert len(keys) > 25
    for key, spec in keys:
        for bad in (".nan", "-.inf", "Infinity", "nan"):
            value = f"[{bad}, {bad}]" if spec.kind.startswith("list") else bad
            with pytest.raises(ConfigError, match="must be a finite number"):
                load_config(ROOT / BOX, [f"{key}={value}"])


def test_messages_are_short_single_lines():
    bomb = [1] * 9
    for _ in range(8):
        bomb = [bomb] * 9
    assert len(short_repr(bomb)) <= 120
    assert short_repr(10**5000) == "<integer of about 5000 digits>"
    err = ConfigError("a\nb " + "x" * 10_000)
    assert "\n" not in str(err) and len(str(err)) <= 400
    with pytest.raises(ConfigError, match=r"config key '\[8\]\[8\].*': the config holds more than 100000 values"):
        check_document_shape(bomb)
    from convection.config.loader import SCHEMA
    from convection.schema import validate

    with pytest.raises(ConfigError, match="unknown; allowed keys in top level"):  # sortable although mixed
        validate(SCHEMA, {1: "one", "foo": "two"})


def test_expressions_cannot_grow_without_bound():
    for text in (_TOWER, "((not 0)+(not 0))**((not 0)+(not 0))**((not 0)+(not 0))**((not 0)+(not 0))**(not 0)"):
        values = Expression(text)(np.zeros((3, 2)))
        assert values.dtype == np.float64  # NumPy numbers: inf or a small value, never a huge exact integer
    for text, needle in ((_sum(600), "more than 2000"), ("-" * 3000 + "x", "cannot parse|more than 2000"),
                         ("'%2000000000s' % 1", "only numbers"), ("1j", "only numbers"), ("x\0", "cannot parse")):
        with pytest.raises(ExpressionError, match=needle):
            Expression(text)
    with pytest.raises(ExpressionError, match="nested more than"):
        Expression("+".join(["(x)"] * 150))


def test_probes_cover_the_mesh_nodes_and_the_boundary():
    config = load_config(ROOT / BOX, ["mesh.cells=[4, 3]", "mesh.upper=[2, 1]"])
    points = domain_probes(domain_from_config(config))
    assert points.shape == (3, (6 * 4 + 1) * (6 * 3 + 1))
    for x, z in ((0.0, 0.0), (2.0, 1.0), (0.25, 1 / 3), (1.5, 0.5)):  # corners and P2/P3 nodes
        assert np.min(np.hypot(points[0] - x, points[1] - z)) < 1e-12
    top = boundary_probes(domain_from_config(config), "top")
    assert np.all(top[1] == 1.0) and top.shape[1] == 25
    big = load_config(ROOT / BOX, ["mesh.cells=[64, 64, 64]"])
    assert domain_probes(domain_from_config(big)).shape[1] <= MAX_PROBES
    shell = load_config(ROOT / SHELL)
    r = np.linalg.norm(domain_probes(domain_from_config(shell))[:2], axis=0)
    assert math.isclose(r.min(), 1.22) and math.isclose(r.max(), 2.22)
    assert np.allclose(np.linalg.norm(boundary_probes(domain_from_config(shell), "outer")[:2], axis=0), 2.22)
