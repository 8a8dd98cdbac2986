"""pytest plugin: end the process when one test takes longer than PIC_TEST_WATCHDOG seconds.

Loaded by scripts/test.sh when PIC_TEST_WATCHDOG is set (scripts/ci_release.sh sets it). A
collective test whose ranks part ways (one raises, another waits in a collective) would otherwise
sit until mpirun's own timeout; often the waiting rank is inside DOLFINx's C++ holding the GIL,
where neither a Python signal handler nor a Python timer thread (pytest-timeout) gets to run.
faulthandler's watchdog is a C thread that needs no GIL: it prints every thread's traceback, then
exits the process with code 1, and mpirun ends that collective run.
"""

from __future__ import annotations

import faulthandler
import os

import pytest

_SECONDS = float(os.environ.get("PIC_TEST_WATCHDOG", "0") or 0)
# The process's real stderr, kept before pytest captures fd 2 (what is written to the capture file
# would be lost with the process).
_STDERR = os.fdopen(os.dup(2), "w") if _SECONDS > 0 else None


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    if _SECONDS > 0:
        faulthandler.dump_traceback_later(_SECONDS, repeat=False, file=_STDERR, exit=True)
    try:
        yield
    finally:
        if _SECONDS > 0:
            faulthandler.cancel_dump_traceback_later()


def pytest_report_header(config):
    if _SECONDS > 0:
        return f"watchdog: a test running longer than {_SECONDS:g} s ends the process (PIC_TEST_WATCHDOG)"
    return None
