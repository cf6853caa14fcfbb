"""Every kernel the cycle can reach is compiled or loaded before the first SYNC: in a fresh
process, after activation, every controller through every motion and command gains no
numba signature (each would be a compile of 0.3-0.7 s, or a cache load of ms, inside a
control cycle: an independent client's first HOME faulted OVERRUN that way)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("rig", ["testbench", "hexapod"])
def test_no_kernel_is_compiled_or_loaded_after_activation(rig):
    proc = subprocess.run([sys.executable, "-m", "tests.support.first_motion_probe", rig], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    doc = json.loads(proc.stdout.strip().splitlines()[-1])
    assert doc["kernels"] >= 40                      # the probe found the project's kernels
    assert doc["gained"] == []
    assert doc["ready"] and all(s.endswith("READY") for s in doc["states"]), doc["states"]
