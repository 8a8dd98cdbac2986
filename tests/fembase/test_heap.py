"""fembase.heap: after PETSc is loaded, a large block freed goes back to the system."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = """
import ctypes, sys
import numpy as np
from petsc4py import PETSc  # loads SuperLU_DIST with Debian's PETSc: no mapped blocks, no trimming
from fembase.heap import return_freed_memory

class Info(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                                 "fsmblks", "uordblks", "fordblks", "keepcost")]
libc = ctypes.CDLL("libc.so.6")
libc.mallinfo2.restype = Info

def resident():
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024

assert return_freed_memory() is True
assert return_freed_memory() is True  # idempotent
mapped = libc.mallinfo2().hblkhd
block = np.ones(8_000_000)  # 64 MB, every page touched
assert libc.mallinfo2().hblkhd - mapped >= block.nbytes, "the block is not mapped on its own"
before = resident()
del block
assert before - resident() >= 60 * 2**20, (before, resident())
print("ok")
"""


def test_freed_block_leaves_the_process():
    if not sys.platform.startswith("linux"):
        return
    proc = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split()[-1] == "ok"
