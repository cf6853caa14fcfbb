"""Every allocation a stretch of code makes, transient ones included: the NumPy data buffers
(through NumPy's memory handler) and the blocks of Python's object allocator (objects and
their small buffers), counted by a small C hook (`alloc_counter.c`) compiled here on first
use with the machine's C compiler and Python headers, into a cache directory.

tracemalloc compares what is alive before and after; a buffer made and freed inside a cycle
leaves no trace there. This sees it.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import shutil
import subprocess
import sysconfig
import tempfile
from contextlib import contextmanager
from functools import cache
from pathlib import Path

SOURCE = Path(__file__).with_name("alloc_counter.c")
MODULE = "_hydrapod_alloc_counter"


class CounterBuildError(RuntimeError):
    """The C hook could not be compiled (no compiler or no Python headers)."""


@cache
def counter():
    """The compiled counter module (built once per source and interpreter)."""
    import numpy as np
    source = SOURCE.read_bytes()
    include = [sysconfig.get_paths()["include"], np.get_include()]
    key = hashlib.sha256(source + repr(include).encode() + np.__version__.encode()).hexdigest()[:16]
    suffix = sysconfig.get_config_var("EXT_SUFFIX")
    built = Path(tempfile.gettempdir()) / f"hydrapod-alloc-counter-{key}" / f"{MODULE}{suffix}"
    if not built.exists():
        compiler = shutil.which("cc") or shutil.which("gcc")
        if compiler is None:
            raise CounterBuildError("no C compiler (cc or gcc) on PATH: the allocation counter is built with one")
        built.parent.mkdir(parents=True, exist_ok=True)
        # each process its own partial file: pytest's workers may build at once; the rename is atomic
        partial = built.with_suffix(f".{os.getpid()}.partial")
        command = [compiler, "-shared", "-fPIC", "-O2", *(f"-I{d}" for d in include), str(SOURCE), "-o", str(partial)]
        result = subprocess.run(command, capture_output=True, text=True)
        if result.returncode != 0:
            raise CounterBuildError(f"building the allocation counter failed: {result.stderr.strip()[:400]}")
        partial.replace(built)
    spec = importlib.util.spec_from_file_location(MODULE, built)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class Counts:
    """NumPy buffers and Python object-allocator blocks counted while switched on."""

    def __init__(self):
        self.module = counter()

    def on(self) -> None:
        self.module.on()

    def off(self) -> None:
        self.module.off()

    def pause(self) -> None:
        """Leave out what follows, until `resume` (which counts again only if this was counting)."""
        self.module.pause()

    def resume(self) -> None:
        self.module.resume()

    def trace(self) -> dict[str, int]:
        """From now on, where each NumPy buffer is made: "file:line" -> how many (a dict that fills)."""
        return self.module.trace()

    @property
    def numpy_buffers(self) -> int:
        return self.module.counts()[0]

    @property
    def python_blocks(self) -> int:
        return self.module.counts()[1]


@contextmanager
def counting():
    """The hooks installed and the counts at zero for the block (counting switched on and off
    by the caller with `on()` / `off()` around what it measures)."""
    module = counter()
    module.install()
    module.reset()
    try:
        yield Counts()
    finally:
        module.off()
        module.uninstall()


def cycle_allocations(controller_cfg, emulator_cfg, cycles: int = 2000) -> list[dict]:
    """Per controller and rig, moving through a back-and-forth movement on the in-process bus:
    the NumPy buffers and the Python object-allocator blocks one steady cycle makes (the
    emulated rig's own work left out)."""
    from firmware_py.motion_control.joint_space import CONTROLLER_NAMES
    from firmware_py.rig_model import RIGS
    from hil.in_process import bus_loop
    from protocol.enums import State, WaypointFlag
    rows = []
    with counting() as counts:
        for rig in RIGS:
            for kind in CONTROLLER_NAMES:
                loop, ctl, bus = bus_loop(controller_cfg, emulator_cfg, rig, kind,
                                          outside=(counts.pause, counts.resume))
                x, y, z = (0.0, 0.0, float(ctl.status.hold_m[0])) if rig == "testbench" else ctl.rig.home_pose
                segments = cycles // 100 + 10                # 0.2 s each: the window inside the movement
                for k in range(min(segments, 30)):
                    last = k == min(segments, 30) - 1
                    ctl.host.waypoint_position(k & 0x0F, x, y, z + (0.005 if k % 2 == 0 else 0.0))
                    ctl.host.waypoint_rotation(k & 0x0F, 0.0, 0.0, 0.0)
                    ctl.host.waypoint_commit(k & 0x0F, k, 0.2, 0.05,
                                             int(WaypointFlag.START | WaypointFlag.LAST) if last else 0)
                    loop.cycle()
                for _ in range(200):
                    loop.cycle()
                window = min(cycles, 2800)
                numpy_before, python_before = counts.numpy_buffers, counts.python_blocks
                counts.on()
                for _ in range(window):
                    loop.cycle()
                counts.off()
                rows.append({"rig": rig, "controller": kind, "cycles": window,
                             "state": ctl.status.state.name,
                             "numpy_buffers_per_cycle": (counts.numpy_buffers - numpy_before) / window,
                             "python_blocks_per_cycle": round((counts.python_blocks - python_before) / window, 1)})
                assert ctl.status.state in (State.RUNNING, State.READY, State.FAULT)
    return rows


def format_allocations(rows: list[dict]) -> str:
    lines = [f"{'rig':<10} {'controller':<16} {'cycles':>6} {'NumPy buffers':>13} {'Python blocks':>13}  "
             f"(per steady cycle, the controller's loop; state at the end)"]
    for r in rows:
        lines.append(f"{r['rig']:<10} {r['controller']:<16} {r['cycles']:6d} {r['numpy_buffers_per_cycle']:13g} "
                     f"{r['python_blocks_per_cycle']:13.1f}  {r['state']}")
    return "\n".join(lines)
