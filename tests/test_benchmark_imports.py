"""Benchmarks are modules: no benchmark script or test edits ``sys.path``, and no test (nor
benchmark) loads a benchmark script by its file path: tests write ``from benchmarks.vanKeken import
run`` and subprocesses ``python -m benchmarks.tosi.run`` (benchmarks/harness.py)."""

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SYS_PATH_EDIT = re.compile(r"sys\.path\.(insert|append|extend)\(|sys\.path\s*\+?=|addsitedir\(")
PATH_LOADERS = {"spec_from_file_location", "run_path", "SourceFileLoader", "load_source"}


def _sources(*folders: str) -> list[Path]:
    return [path for folder in folders for path in sorted((ROOT / folder).rglob("*.py"))
            if path != Path(__file__).resolve()]


def _strings(node: ast.AST) -> list[str]:
    return [n.value for n in ast.walk(node) if isinstance(n, ast.Constant) and isinstance(n.value, str)]


def _loads_a_benchmark_by_path(call: ast.Call) -> bool:
    """A call that names a benchmark script's file: a path loader given any path under benchmarks/,
    or any call (subprocess, open-and-exec, ...) given both "benchmarks" and a "....py" file."""
    func = call.func
    name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
    strings = _strings(call)
    mentions = any(s == "benchmarks" or s.startswith(("benchmarks/", "/benchmarks")) or "/benchmarks/" in s
                   for s in strings)
    return mentions and (name in PATH_LOADERS or any(s.endswith(".py") for s in strings))


def test_no_sys_path_edits_in_benchmarks_and_tests():
    wrong = [f"{path.relative_to(ROOT)}:{number}" for path in _sources("benchmarks", "tests")
             for number, line in enumerate(path.read_text().splitlines(), start=1) if SYS_PATH_EDIT.search(line)]
    assert not wrong, f"import through the package instead of editing sys.path: {wrong}"


def test_benchmarks_are_imported_as_modules():
    wrong = [f"{path.relative_to(ROOT)}:{node.lineno}" for path in _sources("benchmarks", "tests")
             for node in ast.walk(ast.parse(path.read_text()))
             if isinstance(node, ast.Call) and _loads_a_benchmark_by_path(node)]
    assert not wrong, f"import benchmarks.<folder>.<script> (or run python -m) instead of its path: {wrong}"


def test_the_guard_sees_what_it_guards_against():
    calls = ['importlib.util.spec_from_file_location("tk", ROOT / "benchmarks" / "tackley_king" / "run.py")',
             'subprocess.run([sys.executable, str(ROOT / "benchmarks" / "tosi" / "run.py"), "--case", "2"])',
             'runpy.run_path("benchmarks/performance/vortex.py")']
    assert all(_loads_a_benchmark_by_path(ast.parse(c, mode="eval").body) for c in calls)
    fine = ['subprocess.run([sys.executable, "-m", "benchmarks.tosi.run"], cwd=ROOT)',
            'importlib.import_module("benchmarks.free_surface.plume_lid")']
    assert not any(_loads_a_benchmark_by_path(ast.parse(c, mode="eval").body) for c in fine)
    assert SYS_PATH_EDIT.search("sys.path.insert(0, str(ROOT))") and not SYS_PATH_EDIT.search("print(sys.path)")


def test_the_harness_gives_the_declared_options_only():
    from benchmarks.harness import Benchmark, Case, Load, cases

    declared = Benchmark("A benchmark.\n\nMore.", out=Path("runs"), ranks=(1, 2), quick="", overrides=True)
    parser = declared.parser(cases=cases(Case("a", "vankeken_1a.yaml"), Case("b", "vankeken_1b.yaml")))
    args = parser.parse_args([])
    assert vars(args) == {"case": ["a"], "ranks": [1, 2], "quick": False, "out": Path("runs"), "set": []}
    args = parser.parse_args(["--case", "b", "a", "--ranks", "3", "--out", "x", "--set", "k=1", "--quick"])
    assert (args.case, args.ranks, args.out, args.set, args.quick) == (["b", "a"], [3], Path("x"), ["k=1"], True)
    assert parser.description == "A benchmark."
    assert vars(Benchmark(None).parser().parse_args([])) == {}
    load = Load.now()
    assert len(load.averages) == 3 and load.cores >= 1 and str(load).startswith("load average ")
