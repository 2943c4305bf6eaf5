"""fmpy is imported without the `ldconfig -p` process its import would start (14 ms of every run's start)."""

from __future__ import annotations

import subprocess
import sys

import pytest

_CHILD = """
import subprocess
started = []
popen_init = subprocess.Popen.__init__
def recording(self, args, *a, **k):
    started.append(args)
    popen_init(self, args, *a, **k)
subprocess.Popen.__init__ = recording
import ctypes.util
find_library = ctypes.util.find_library
import twin.cosim, fmpy
block = fmpy.calloc(16, 8)  # fmpy's allocator, as an FMU's callbacks use it
assert block
fmpy.free(block)
assert ctypes.util.find_library is find_library, "the lookup is answered differently only during fmpy's import"
print(started)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the ldconfig lookup is Linux's")
def test_importing_twin_cosim_starts_no_process_and_fmpy_allocates() -> None:
    out = subprocess.run([sys.executable, "-c", _CHILD], capture_output=True, text=True, check=False, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"
