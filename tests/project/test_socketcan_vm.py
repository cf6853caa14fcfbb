"""Real SocketCAN: the kernel here has no CAN support, so a VM (virtme-ng with the Debian
kernel, qemu in software emulation) creates vcan0 and runs a short lockstep sha-step over
`socketcan:vcan0` on the stock CANopen devices (`--devices canopen`: SDO configuration, NMT,
PDOs, heartbeats over the kernel's interface) at a lower rate than one real bus carries them
(250 Hz: half the cycles at 500, which the suite's budget needs), with the emulator, the
controller and the host all inside it; then the kernel's SYNC at 500 Hz as the controller
starts it on SocketCAN (`hydrapod protocol sync-check`). The transport under test is the same
for the project's own profile, whose codecs and E2E run over the other buses in the suite.

`make test` installs qemu, the kernel and busybox (apt) and virtme-ng (the test extra);
nothing here skips when they are missing: it fails and says what to install.

Under software emulation numba's compiler takes minutes, so the kernels are compiled for a
generic x86-64 CPU (NUMBA_CPU_NAME=generic, a portable cache) by a host run of the same
scenario first. The guest's root is the host's over 9p, where every file a process opens is
a round trip through qemu: the checkout (its venv included), the standard library and the
kernel cache go to the guest as ext4 disk images (`mke2fs -d`) mounted over the same paths,
and only the run's output crosses 9p (`--rwdir`). docs/MEASUREMENTS.md has the figures.
"""

from __future__ import annotations

import glob
import json
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent
# one controller, one load, one position 10 mm from the start (the shortest move there): the bus
# path is what is under test, and emulated, it is ~20x slower
RATE_HZ = 250.0
SCENARIO = ["hil", "run", "sha-step", "--short", "--controllers", "pi", "--loads", "0", "--positions", "140",
            "--devices", "canopen", "--rate-hz", str(RATE_HZ), "--no-plots"]
VM_TIMEOUT_S = 900                # ~3x the slowest run seen inside `make test`
SYNC_S = 2.0                      # the kernel's SYNC listened to for this long


def _image(tree: Path, image: Path) -> None:
    """An ext4 image of `tree` (mke2fs -d, no journal), room to spare for the guest's writes
    (bytecode, numba's index)."""
    du = subprocess.run(["du", "-sk", str(tree)], capture_output=True, text=True, check=True)
    used_kb = int(du.stdout.split()[0])
    files = sum(len(names) + 1 for _, _, names in os.walk(tree))
    size_mb = used_kb * 13 // 10 // 1024 + 128
    subprocess.run(["mke2fs", "-q", "-F", "-t", "ext4", "-O", "^has_journal", "-N", str(files * 2 + 4096),
                    "-d", str(tree), str(image), f"{size_mb}M"], check=True, capture_output=True, timeout=300)


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
    stdlib = Path(sysconfig.get_paths()["stdlib"])
    aux = work / "aux"                    # the image's tree: the standard library, numba's cache
    # the base interpreter's own packages, tests and static library: never imported by the venv's runs
    shutil.copytree(stdlib, aux / "stdlib", symlinks=True,
                    ignore=shutil.ignore_patterns("site-packages", "test", "idle_test", "config-*"))
    env = {"NUMBA_CACHE_DIR": str(aux / "numba"), "NUMBA_CPU_NAME": "generic"}

    # on the host: the portable kernel cache (and a reference run)
    host = subprocess.run([str(BIN / "hydrapod"), *SCENARIO, "--out", str(work / "host"), "--json"],
                          capture_output=True, text=True, timeout=600, env={**os.environ, **env}, cwd=ROOT)
    assert host.returncode == 0, host.stdout[-2000:] + host.stderr[-2000:]
    _image(ROOT, work / "checkout.ext4")
    _image(aux, work / "aux.ext4")

    exports = " ".join(f"{k}={v}" for k, v in env.items())
    # the disks are /dev/vda and /dev/vdb in --disk order; the aux image mounts where it was
    # built, so the cache's paths are the host run's
    # each stage echoes its name: a failed run's output says how far the guest came
    script = ("echo STAGE=booted && modprobe vcan && ip link add dev vcan0 type vcan && ip link set up vcan0 && "
              f"modprobe ext4 && mount /dev/vda {ROOT} && mount /dev/vdb {aux} && "
              f"mount --bind {aux / 'stdlib'} {stdlib} && echo STAGE=mounted && "
              f"cd {ROOT} && {exports} {BIN / 'hydrapod'} {' '.join(SCENARIO)} --bus socketcan:vcan0 "
              f"--start-timeout-s 900 --out {work / 'vm'} --json > {work / 'vm.json'} 2> {work / 'vm.stderr'}; "
              "echo VM_EXIT=$?; "
              # the kernel's SYNC as the controller starts it on SocketCAN, its counters received back
              f"{BIN / 'hydrapod'} protocol sync-check --bus socketcan:vcan0 --rate-hz 500 --seconds {SYNC_S} --json "
              f"> {work / 'sync.json'} 2>> {work / 'vm.stderr'}; echo SYNC_EXIT=$?")
    # a file, not the command itself: vng passes --exec on the kernel's command line, which
    # the kernel cuts at 2048 bytes (the guest then hangs at boot, saying nothing)
    (work / "guest.sh").write_text(script + "\n")
    # one vCPU: the run inside is lockstep (one process busy at a time), and under software
    # emulation each vCPU is a host thread that the other test worker needs
    try:
        vm = subprocess.run([str(vng), "--run", kernel, "--disable-kvm", "--cpus", "1", "--memory", "2G",
                             "--rwdir", str(work), "--disk", str(work / "checkout.ext4"),
                             "--disk", str(work / "aux.ext4"), "--exec", f"sh {work / 'guest.sh'}"],
                            capture_output=True, text=True, timeout=VM_TIMEOUT_S,
                            env={**os.environ, "PATH": f"{BIN}:{os.environ.get('PATH', '')}"})
    except subprocess.TimeoutExpired as late:
        said = (late.stdout or b"").decode(errors="replace")[-2000:] if isinstance(late.stdout, bytes) \
            else (late.stdout or "")[-2000:]
        pytest.fail(f"the VM did not finish within {VM_TIMEOUT_S} s; its output: {said!r}")
    stderr_tail = (work / "vm.stderr").read_text()[-2000:] if (work / "vm.stderr").exists() else ""
    # exit 1 is a failed check: the run's own report says which
    report = (work / "vm.json").read_text()[-3000:] if (work / "vm.json").exists() else ""
    # the children's own stderr: an emulator that exited 0 is not in the run's failure line
    logs = sorted((work / "vm").rglob("*.stderr.log"))
    children = "".join(f"\n{log.name}:\n{log.read_text()[-1500:]}" for log in logs)
    assert "VM_EXIT=0" in vm.stdout, vm.stdout[-2000:] + vm.stderr[-2000:] + stderr_tail + report + children
    doc = json.loads((work / "vm" / "metrics.json").read_text())
    assert doc["bus"] == "socketcan:vcan0" and doc["devices"] == "canopen" and doc["rate_hz"] == RATE_HZ
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
    # the kernel's SYNC: every counter in order. Its rate and period error are the emulated
    # machine's timer (924 of 1000 in 2 s alone, p99 error 0.3 ms; 464 with the host's CPU
    # shared four ways, p99 14 ms): the floor only says the kernel kept sending
    assert "SYNC_EXIT=0" in vm.stdout, (work / "sync.json").read_text() if (work / "sync.json").exists() else ""
    sync = json.loads((work / "sync.json").read_text())
    assert sync["passed"] and sync["counter_gaps"] == 0 and sync["syncs"] >= 0.2 * sync["expected"], sync
