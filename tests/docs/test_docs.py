"""The user guide (docs/, mkdocs.yml): the site builds with no warnings, and what its pages show
works — every shell command of every page runs in a tiny form, every config snippet is a valid
config, every Python snippet runs."""

from __future__ import annotations

import copy
import os
import re
import shlex
import sys
from pathlib import Path

import pytest
import yaml

from _runs import guarded_run, shrink
from convection.config.loader import SCHEMA, load_config
from convection.launch import mpi_environment, mpirun

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
PAGES = sorted(DOCS.glob("*.md"))
CI = (ROOT / ".ci" / "run").read_text()
MKDOCS = Path(sys.executable).with_name("mkdocs")

pytest.importorskip("mkdocs")

# Commands that CI itself runs (.ci/run: scripts/test.sh here, then scripts/ci_release.sh, which
# runs scripts/test.sh in a fresh root of the other release with scripts/in_release_root.sh), or
# that a test of this file runs: each pattern with the text that must be in .ci/run or the test.
COVERED = {
    r"^bash scripts/test\.sh": ("ci", "bash scripts/test.sh"),
    r"^bash scripts/ci_release\.sh": ("ci", "bash scripts/ci_release.sh"),
    r"^bash scripts/in_release_root\.sh trixie -- bash scripts/test\.sh": ("ci", "scripts/ci_release.sh"),
    r"^\.venv/bin/mkdocs build": ("test", "test_site_builds_without_warnings"),
}
_RAN: set[str] = set()
TINY_RUN = ["time.max_steps=2", "output.progress=none", "output.fields_every=1"]


def _blocks(path: Path, language: str) -> list[str]:
    return re.findall(rf"^```{language}\n(.*?)^```", path.read_text(), re.S | re.M)


def _commands(path: Path) -> list[str]:
    """The commands of a page's ```bash blocks (continuation lines joined, comments dropped)."""
    out = []
    for block in _blocks(path, "bash"):
        for line in block.replace("\\\n", " ").splitlines():
            line = re.sub(r"\s+#.*$", "", line).strip()
            if line and not line.startswith("#"):
                out.append(" ".join(line.split()))
    return out


def _shrink(config: Path) -> list[str]:
    """Overrides that make a shipped config tiny (a box: a quarter of the cells per direction; a
    shell: a cell size 1.8 times larger; at most 2000 particles)."""
    return shrink(config, divisor=4, coarsen=1.8, max_particles=2000, max_per_cell=8)


def _tiny(command: str) -> tuple[list[str], str | None]:
    """The argv of a page's command in its tiny form, and the file its stdout goes to (or None)."""
    redirect = None
    if " > " in command:
        command, redirect = (part.strip() for part in command.split(" > ", 1))
    words = shlex.split(command)
    ranks = 1
    if words[0] == "mpirun":
        ranks, words = int(words[2]), words[3:]
    if words[0] == ".venv/bin/python":
        words[0] = sys.executable
    assert words[0] == sys.executable, f"unknown command: {command}"
    if words[1:3] == ["-m", "convection"] and words[3] == "run":
        words += [a for item in [*TINY_RUN, *_shrink(ROOT / words[4])] for a in ("--set", item)]
    elif words[1:3] == ["-m", "convection"] and words[3] == "resume":
        words += ["--set", "time.max_steps=4", "--set", "output.progress=none"]
    return ([*mpirun(ranks), *words] if ranks > 1 else words), redirect


def test_site_builds_without_warnings(tmp_path):
    proc = guarded_run([str(MKDOCS), "build", "--strict", "-d", str(tmp_path / "site")], cwd=ROOT,
                       budget=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "WARNING" not in proc.stdout + proc.stderr
    site = tmp_path / "site"
    for page in PAGES:
        assert (site / page.with_suffix(".html").name).is_file(), page.name
    assert (site / "demos" / "first_model.html").is_file() and (site / "demos" / "rayleigh_taylor.html").is_file()
    for readme in (ROOT / "benchmarks").glob("*/README.md"):
        assert (site / "benchmarks" / f"{readme.parent.name}.html").is_file()


def test_every_page_is_in_the_nav():
    nav = yaml.safe_load((ROOT / "mkdocs.yml").read_text())["nav"]
    text = yaml.safe_dump(nav)
    for page in PAGES:
        assert page.name in text, f"{page.name} is not in mkdocs.yml's nav"


@pytest.mark.parametrize("page", [p for p in PAGES if _commands(p)], ids=lambda p: p.stem)
def test_page_commands_run_in_tiny_form(page, tmp_path):
    """Each command of the page, in order, in a fresh folder holding the configs (so relative
    output folders land there): run commands for 2 steps of a shrunk config, resumes 2 more."""
    for folder in ("configs", "benchmarks"):
        (tmp_path / folder).symlink_to(ROOT / folder)
    env = {**mpi_environment(), "PYTHONDONTWRITEBYTECODE": "1"}
    for command in _commands(page):
        covered = next((how for pattern, how in COVERED.items() if re.match(pattern, command)), None)
        if covered is not None:
            kind, text = covered
            source = CI if kind == "ci" else Path(__file__).read_text()
            assert text in source, f"{command!r}: not run by {'CI' if kind == 'ci' else 'this file'}"
            continue
        if command.startswith("bash scripts/run.sh"):  # the README's main job, to t = 20, once
            if "run.sh" in _RAN:
                continue
            _RAN.add("run.sh")
            argv, redirect, cwd = ["bash", "scripts/run.sh", "--end", "20"], None, ROOT
        else:
            (argv, redirect), cwd = _tiny(command), tmp_path
        proc = guarded_run(argv, cwd=cwd, env=env, budget=900)
        assert proc.returncode == 0, f"{command}\n{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}"
        if redirect:
            (tmp_path / redirect).write_text(proc.stdout)


def _merge(base: dict, extra: dict) -> dict:
    out = copy.deepcopy(base)
    for key, value in extra.items():
        out[key] = _merge(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out


def test_config_snippets_are_valid(tmp_path):
    """Every ```yaml block whose keys are config sections is a valid config (filled up with the
    required keys where it does not give them)."""
    base = {"physics": {"Ra": 1.0e4}, "time": {"end": 0.1}, "output": {"directory": str(tmp_path / "out")},
            "mesh": {"cells": [4, 4]}}
    checked = 0
    for page in PAGES:
        for block in _blocks(page, "yaml"):
            snippet = yaml.safe_load(block)
            if not isinstance(snippet, dict) or not set(snippet) <= set(SCHEMA):
                continue
            document = _merge(base, snippet)
            if "scaling" in snippet:  # a model with units: its Ra follows from the scaling (or it needs none)
                document["physics"].pop("Ra")
            if "geometry" in document["mesh"]:
                document["mesh"].pop("cells")
            if "output" in snippet and "directory" not in snippet["output"]:
                document["output"]["directory"] = str(tmp_path / "out")
            try:
                load_config(None, document=document)
            except Exception as err:  # noqa: BLE001 - reported with the page
                pytest.fail(f"{page.name}: {err}\n{block}")
            checked += 1
    assert checked >= 8


def test_python_snippets_run(tmp_path):
    (tmp_path / "configs").symlink_to(ROOT / "configs")
    checked = 0
    for page in PAGES:
        for block in _blocks(page, "python"):
            if "model.step" not in block and "run_config" not in block:
                continue
            proc = guarded_run([sys.executable, "-c", block], cwd=tmp_path, budget=600,
                               env={**os.environ, "PYTHONDONTWRITEBYTECODE": "1"})
            assert proc.returncode == 0, f"{page.name}\n{block}\n{proc.stderr[-3000:]}"
            checked += 1
    assert checked >= 1
