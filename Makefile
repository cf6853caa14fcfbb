# hydrapod
#   make demo    creates .venv if needed; the main job: emulator + controller on the default bus,
#                pm-circle at the thesis's timing, the thesis's two controllers and computed torque,
#                in lockstep (PACING=realtime: at 500 Hz on the wall clock); metrics and plots in hil-out/
#   make test    creates .venv if needed; the suite but the realtime tier (what .ci/run runs)
#   make check   the suite without the HIL runs, the VM and the slow in-process runs (~2 min)
#   make realtime  the realtime HIL tier alone (a benchmark: an idle machine that keeps 500 Hz)
#   make lint    ruff over the tree
PYTHON ?= python3
VENV   ?= .venv
PY      = $(VENV)/bin/python
STAMP   = $(VENV)/.installed
# the lockstep tiers on every CPU
WORKERS ?= 2
PYTEST  = $(PY) -m pytest -p no:cacheprovider

# every process imports the project's modules: let Python keep their bytecode (a shell or CI
# that sets PYTHONDONTWRITEBYTECODE would have each HIL child recompile them, 20x slower in the VM)
export PYTHONDONTWRITEBYTECODE :=

# lockstep: the same on any machine; realtime passes only where the machine keeps 500 Hz
PACING ?= lockstep
demo: $(STAMP)
	$(VENV)/bin/hydrapod hil run pm-circle --pacing $(PACING) --bus default --out hil-out

.PHONY: demo test check realtime lint venv vm-deps bus-load socketcan-check clean

venv: $(STAMP)

# Reinstall when the package metadata changes; the install is editable, so code edits
# need no reinstall.
$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --upgrade pip
	$(PY) -m pip install -e '.[test]'
	touch $(STAMP)

# The SocketCAN test (tests/project/test_socketcan_vm.py) boots a Debian kernel in qemu: install
# what it needs when missing (root, or sudo).
VM_DEBS  = qemu-system-x86 linux-image-amd64 busybox-static
SUDO    := $(shell test "$$(id -u)" = 0 || echo sudo)
vm-deps:
	@dpkg -s $(VM_DEBS) >/dev/null 2>&1 || { $(SUDO) apt-get update && \
	  DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y --no-install-recommends $(VM_DEBS); }

test: $(STAMP) vm-deps
	$(PYTEST) -n $(WORKERS) --dist loadgroup -m "not realtime" --durations=15

# HIL runs at 500 Hz in realtime pacing, alone on the machine: whether they run clean is the
# machine's speed (a loop that cannot keep its period faults OVERRUN, as it must), so this is a
# benchmark for an idle machine that keeps 500 Hz, not part of `test` (docs/TIMING.md)
realtime: $(STAMP)
	$(PYTEST) -m realtime --durations=5

check: $(STAMP)
	$(PYTEST) -n $(WORKERS) --dist loadgroup -m "not hil and not realtime and not vm and not slow"

lint: $(STAMP)
	$(VENV)/bin/ruff check .

bus-load: $(STAMP)
	$(VENV)/bin/hydrapod bus-load --rate-hz 500

# The bus tests against real SocketCAN (vcan0) inside a VM, for kernels without CAN.
# Needs virtme-ng (vng on PATH), qemu-system-x86 and a Debian kernel image in /boot.
# The VM has no NIC, hence no multicast route: only the SocketCAN and virtual tests run.
KERNEL ?= $(lastword $(sort $(wildcard /boot/vmlinuz-*)))
socketcan-check: $(STAMP)
	@command -v vng >/dev/null || { echo "socketcan-check: vng not on PATH (pip install virtme-ng)"; exit 2; }
	@test -n "$(KERNEL)" || { echo "socketcan-check: no /boot/vmlinuz-* (apt-get install linux-image-amd64)"; exit 2; }
	vng --run $(KERNEL) --disable-kvm --exec "modprobe vcan && ip link add dev vcan0 type vcan && \
	  ip link set up vcan0 && cd $(CURDIR) && HYDRAPOD_TEST_BUS=socketcan:vcan0 \
	  $(PY) -m pytest -p no:cacheprovider tests/protocol/test_bus.py -k 'socketcan or default or two_processes or virtual'"

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis .numba-cache *.egg-info
