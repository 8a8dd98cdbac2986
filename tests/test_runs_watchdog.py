"""The tests' subprocess runner (tests/_runs.py): the output as ``subprocess.run`` gives it, and a
hung process killed with everything it started once its idle-machine budget is spent."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

import _runs
from _runs import Watchdog, guarded_run


def _gone(pid: int) -> bool:
    """Whether ``pid`` has exited (gone, or a zombie not yet reaped)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
    except (FileNotFoundError, ProcessLookupError):
        return True


def test_output_and_exit_code_as_subprocess_run_gives_them():
    proc = guarded_run([sys.executable, "-c", "import sys; print('out'); sys.stderr.write('err'); sys.exit(3)"])
    assert (proc.returncode, proc.stdout, proc.stderr) == (3, "out\n", "err")


def test_a_hung_run_is_killed_with_its_children(tmp_path):
    pidfile = tmp_path / "child.pid"
    script = ("import subprocess, sys, time; p = subprocess.Popen(['sleep', '600']); "
              "open(sys.argv[1], 'w').write(str(p.pid)); time.sleep(600)")
    with pytest.raises(subprocess.TimeoutExpired):
        guarded_run([sys.executable, "-c", script, str(pidfile)], budget=1)
    child = int(pidfile.read_text())
    watchdog = Watchdog(60)
    while not _gone(child) and not watchdog.expired():
        pass
    assert _gone(child)


def test_a_busy_machine_stretches_the_budget(monkeypatch):
    """At a load of ten times the cores a wall-clock second counts a tenth; on an idle machine, one."""
    clock = [100.0]
    monkeypatch.setattr(_runs.time, "monotonic", lambda: clock[0])
    cores = len(os.sched_getaffinity(0))
    load = [10.0 * cores]
    monkeypatch.setattr(_runs.os, "getloadavg", lambda: (load[0], load[0], load[0]))
    watchdog = Watchdog(10)
    clock[0] += 99
    assert not watchdog.expired() and watchdog.spent == pytest.approx(9.9)
    load[0] = 0.5
    clock[0] += 0.2
    assert watchdog.expired() and watchdog.spent == pytest.approx(10.1)
