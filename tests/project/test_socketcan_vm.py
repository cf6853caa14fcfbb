"""Real SocketCAN: the kernel here has no CAN support, so a VM (virtme-ng with the Debian
kernel, qemu in software emulation) creates vcan0 and runs a short lockstep sha-step over
`socketcan:vcan0` with the emulator, the controller and the host all inside it.

`make test` installs qemu, the kernel and busybox (apt) and virtme-ng (the test extra);
nothing here skips when they are missing: it fails and says what to install.

Under software emulation numba's compiler takes minutes, so the kernels are compiled for a
generic x86-64 CPU (NUMBA_CPU_NAME=generic, a portable cache) by a host run of the same
scenario first, in a directory the VM may write (`--rwdir`); the VM loads them from there.
"""

from __future__ import annotations

import glob
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent
# one controller, one load, one position 10 mm from the start (the shortest move there): the bus
# path is what is under test, and emulated, it is ~20x slower
SCENARIO = ["hil", "run", "sha-step", "--short", "--controllers", "pi", "--loads", "0", "--positions", "140",
            "--no-plots"]
VM_TIMEOUT_S = 1500


def _kernel() -> str:
    kernels = sorted(glob.glob("/boot/vmlinuz-*"))
    assert kernels, "no /boot/vmlinuz-*: apt-get install linux-image-amd64 (make test installs it)"
    return kernels[-1]


@pytest.mark.vm
@pytest.mark.timeout(VM_TIMEOUT_S + 700)
def test_sha_step_over_socketcan_vcan0_inside_a_vm(tmp_path):
    vng = BIN / "vng"
    assert vng.exists(), f"{vng} missing: pip install virtme-ng (the test extra; make test installs it)"
    assert shutil.which("qemu-system-x86_64"), "qemu-system-x86_64 missing: apt-get install qemu-system-x86"
    kernel = _kernel()
    work = tmp_path
    env = {"NUMBA_CACHE_DIR": str(work / "numba"), "NUMBA_CPU_NAME": "generic"}

    # on the host: the portable kernel cache (and a reference run)
    host = subprocess.run([str(BIN / "hydrapod"), *SCENARIO, "--out", str(work / "host"), "--json"],
                          capture_output=True, text=True, timeout=600, env={**os.environ, **env}, cwd=ROOT)
    assert host.returncode == 0, host.stdout[-2000:] + host.stderr[-2000:]

    exports = " ".join(f"{k}={v}" for k, v in env.items())
    script = (f"modprobe vcan && ip link add dev vcan0 type vcan && ip link set up vcan0 && cd {ROOT} && "
              f"{exports} {BIN / 'hydrapod'} {' '.join(SCENARIO)} --bus socketcan:vcan0 --start-timeout-s 900 "
              f"--out {work / 'vm'} --json > {work / 'vm.json'} 2> {work / 'vm.stderr'}; echo VM_EXIT=$?")
    # one vCPU: the run inside is lockstep (one process busy at a time), and under software
    # emulation each vCPU is a host thread that the other test worker needs
    vm = subprocess.run([str(vng), "--run", kernel, "--disable-kvm", "--cpus", "1", "--memory", "2G",
                         "--rwdir", str(work),
                         "--exec", script], capture_output=True, text=True, timeout=VM_TIMEOUT_S,
                        env={**os.environ, "PATH": f"{BIN}:{os.environ.get('PATH', '')}"})
    stderr_tail = (work / "vm.stderr").read_text()[-2000:] if (work / "vm.stderr").exists() else ""
    # exit 1 is a failed check: the run's own report says which
    report = (work / "vm.json").read_text()[-3000:] if (work / "vm.json").exists() else ""
    assert "VM_EXIT=0" in vm.stdout, vm.stdout[-2000:] + vm.stderr[-2000:] + stderr_tail + report
    doc = json.loads((work / "vm" / "metrics.json").read_text())
    assert doc["bus"] == "socketcan:vcan0"
    assert doc["passed"] and doc["failure"] is None, doc.get("failure")
    assert doc["e2e_errors"] == 0 and doc["log"]["lost_frames"] == 0
    reference = json.loads((work / "host" / "metrics.json").read_text())
    # the whole experiment went over vcan0: every host frame and every step of the reference.
    # Not the frame count: a host's wait for an ack lasts a floor of wall time too, so the
    # cycles run meanwhile follow the machine's speed (2964 in the VM against 3520 on the host)
    host_frames = [name for name in reference["log"]["rx_status"] if name.startswith(("HOST_", "EMU_CTRL"))]
    assert host_frames and all(doc["log"]["rx_status"].get(name) == reference["log"]["rx_status"][name]
                               for name in host_frames)
    assert len(doc["metrics"]["steps"]) == len(reference["metrics"]["steps"]) > 0
    assert all(s["settling_s"] is not None for s in doc["metrics"]["steps"])
    assert doc["figures"] == [] and not list((work / "vm").glob("*.png"))          # --no-plots
