"""The hand-written stub ``aptkt/_core.pyi`` against the compiled extension, by mypy's stubtest
(as pydantic-core checks its stub): every name, parameter (name, kind, default), constructor,
property and class flag the stub declares must match ``aptkt._core``, and every name the
compiled module holds must be declared. A binding change that does not update the stub fails
here. No allow-list: stubtest sees everything the extension defines.
"""

from __future__ import annotations

import subprocess
import sys


def test_the_stub_matches_the_compiled_extension():
    r = subprocess.run(
        [sys.executable, "-m", "mypy.stubtest", "aptkt._core"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stdout + r.stderr
