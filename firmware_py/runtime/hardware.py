"""The controller's hardware interface: the rig's devices on the bus, behind one interface for
either device profile (`hardware_dbc.DbcHardware`, the project's own nodes; or
`hardware_canopen.CanopenHardware`, stock CiA 408 valves and CiA 404/406 sensors).

The loop owns the SYNC, the host's frames and its own; a hardware interface takes the
devices' frames (`dispatch`), says when a cycle's samples are all in (`all_fresh`), fills
the device side of the Measurements (`read`), puts the ValveCommands on the bus (`write`),
and before any NMT start names what must answer at each node (`expected_devices`) and
configures it (`prepare`). What the nodes say of themselves (heartbeat, boot-up, EMCY) is kept
here the same way for both.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from protocol.enums import NmtState
from protocol.interfaces import Measurements, ValveCommands


class Hardware(ABC):
    """The bookkeeping both profiles share; a profile implements the frames (its abstract
    methods: a profile lacking one cannot be built)."""

    profile = ""

    def __init__(self, n_legs: int, nodes: list[int], imu_node: int | None, stats, clock):
        self.n_legs, self.nodes, self.imu_node, self.stats, self.clock = n_legs, list(nodes), imu_node, stats, clock
        self.has_imu = imu_node is not None
        self.names: dict[int, str] = {}                  # node -> the device's name, for lines naming it
        self.nmt_state = {node: -1 for node in self.nodes}
        self.heartbeat_seen = np.full(len(self.nodes), -np.inf)
        self.booted: set[int] = set()                    # nodes that booted since they were identified
        self.valve_nodes: set[int] = set()               # nodes whose EMCY is a valve's (else a sensor's)
        self._emergency = False                          # an EMCY with an error code from a valve ...
        self._sensor_emergency = False                   # ... from a sensor
        # the latest valid samples that do not come every cycle, and whether one came since the last read
        self._pressure = np.zeros((n_legs, 3))           # PA, PB, PS
        self._pressure_valid = np.zeros(n_legs, dtype=bool)
        self._pressure_new = np.zeros(n_legs, dtype=bool)
        self._rejected = np.zeros(n_legs, dtype=bool)    # a leg's frame was rejected this cycle
        self._attitude = np.zeros(3)
        self._attitude_new = False
        self._rate = np.zeros(3)
        self._rate_new = False
        self._now = np.zeros(())                         # read's clock as a 0-d array: no conversion per cycle

    def new_measurements(self) -> Measurements:
        return Measurements(self.n_legs, len(self.nodes))

    def name_of(self, node: int) -> str:
        return f"node {node} ({self.names.get(node, '?')})"

    # -- what the nodes say of themselves ------------------------------------------------------
    def heartbeat(self, k: int, state: int) -> None:
        """Node `self.nodes[k]`'s heartbeat; a boot-up: it restarted and may be another device now."""
        self.heartbeat_seen[k] = self.clock()
        node = self.nodes[k]
        if state == NmtState.BOOTUP:
            self.booted.add(node)
            self.restarted(node)
        self.nmt_state[node] = state

    def emergency(self, node: int, error_code: int) -> None:
        """An EMCY; error code 0 announces a reset, not an error."""
        self.stats.emergencies += 1
        if error_code == 0:
            return
        if node in self.valve_nodes:
            self._emergency = True
        else:
            self._sensor_emergency = True

    def all_in_state(self, ready) -> bool:
        return all(ready(self.nmt_state[n]) for n in self.nodes)

    def not_in_state(self, ready) -> list[int]:
        return [n for n in self.nodes if not ready(self.nmt_state[n])]

    # -- the cycle -----------------------------------------------------------------------------
    def read(self, meas: Measurements, now: float) -> None:
        """The device side of the cycle's Measurements: the legs' samples (the profile's), the
        latest pressures and attitude, and the node events since the last read."""
        self.read_legs(meas)
        np.copyto(meas.rejected, self._rejected)
        self._now[()] = now
        np.subtract(self._now, self.heartbeat_seen, out=meas.heartbeat_age_s)
        meas.attitude_rad[:] = self._attitude
        meas.attitude_fresh, self._attitude_new = self._attitude_new, False
        meas.rate_rad_s[:] = self._rate
        meas.rate_fresh, self._rate_new = self._rate_new, False
        np.copyto(meas.pressure_valid, self._pressure_valid)
        meas.pa_pa[:] = self._pressure[:, 0]
        meas.pb_pa[:] = self._pressure[:, 1]
        meas.ps_pa[:] = self._pressure[:, 2]
        np.copyto(meas.pressure_fresh, self._pressure_new)
        self._pressure_new.fill(False)
        meas.emergency, self._emergency = self._emergency, False
        meas.sensor_emergency, self._sensor_emergency = self._sensor_emergency, False

    def begin_cycle(self, counter: int) -> None:
        """SYNC `counter` was sent: its window opens."""
        self._rejected.fill(False)
        self.begin_window(counter)

    # -- per profile ---------------------------------------------------------------------------
    @abstractmethod
    def filters(self) -> list[dict]:
        """python-can acceptance filters for the devices' frames (SDO answers are the loop's)."""

    @abstractmethod
    def dispatch(self, msg) -> bool:
        """A received frame: True when it was a device's (taken, or counted as rejected)."""

    @abstractmethod
    def begin_window(self, counter: int) -> None:
        """SYNC `counter` was sent: this cycle's samples are awaited from now."""

    @abstractmethod
    def end_cycle(self) -> int:
        """The cycle's window closed: how many of the samples due every cycle did not come."""

    @abstractmethod
    def all_fresh(self) -> bool:
        """Every leg's samples of this cycle are in."""

    @abstractmethod
    def read_legs(self, meas: Measurements) -> None:
        """Each leg's samples of this cycle (and whether they came) into `meas`."""

    @abstractmethod
    def write(self, cmd: ValveCommands, send) -> None:
        """Each valve's command, `send(message)` for each frame."""

    @abstractmethod
    def restarted(self, node: int) -> None:
        """A node booted again: its frames' state starts afresh."""

    @abstractmethod
    def expected_devices(self) -> dict:
        """Node id -> (the identity its configured EDS gives, that EDS's name)."""

    @abstractmethod
    def prepare(self, client_of, nodes) -> object:
        """After `nodes` were identified, before their NMT start: configure them through
        `client_of(node)` (an SDO client); what `adopt` takes on the loop's thread."""

    @abstractmethod
    def adopt(self, prepared) -> None:
        """What `prepare` gave, taken on the loop's thread."""

    @abstractmethod
    def leg_report(self) -> str:
        """What the receiver last made of each leg's frames, for a fault's line."""

    @abstractmethod
    def describe(self) -> str:
        """Where the devices expected are configured, for the activation's log."""
