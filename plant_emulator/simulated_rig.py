"""A rig as its controller sees it, without a bus: the one simulated hardware behind every
consumer. Per SYNC k:

1. each valve driver applies the command latched during cycle k-1 (CiA 408 state machine,
   `valve_node.py`) and checks its spool (EMCY on a fault);
2. the sensors sample the rig as it is at t_k (`sensors.py`; the injected sensor faults
   substituted, `sensor_faults.py`): each leg's encoder, load cell and spool every SYNC,
   its pressures and valve status and the IMU at their schedules (the DBC's SyncPeriod,
   or the [nodes] divisors);
3. the valves' spool setpoints drive the rig (the load-holding valves open only while
   ACTIVE) and it integrates exactly one period.

The emulator process (`emulator.py`) puts this on the bus: it encodes the samples as frames
and latches the VALVE_CMD frames it receives. In process (`read`, `write`), the same
samples and commands go through the DBC's codecs (the wire's resolution) into the
controller's `Measurements` and out of its `ValveCommands`: how the design tools, the
benches, the fuzzer and the tests run a controller against the emulated plant.
"""

from __future__ import annotations

import numpy as np

from physics import hydraulics as hy
from plant_emulator.injected import InjectedFaults
from plant_emulator.params import EmulatorConfig
from plant_emulator.sensor_faults import encoder_drift_m, substitute
from plant_emulator.sensors import SensorModel
from plant_emulator.valve_node import Emergency, ValveDriver, ValveState
from protocol.codec import CODECS
from protocol.dbc import sync_counter_overflow
from protocol.enums import EmuFault
from protocol.interfaces import (
    Measurements,
    ValveCommands,
    attitude_into,
    attitude_values,
    leg_pressure_into,
    leg_pressure_values,
    leg_state_into,
    leg_state_values,
    rate_into,
    rate_values,
    valve_command_of,
    valve_command_values,
)
from protocol.nodes import CONTROLLER_NODE, IMU_NODE, LEG_NODES

# the faults that change the rig's physics: applied when injected, undone when cleared
PHYSICAL_FAULTS = (EmuFault.VALVE_JAM, EmuFault.LEG_JAM, EmuFault.SEAL_LEAK, EmuFault.SUPPLY_LOSS,
                   EmuFault.SUPPLY_DROP)
# the scheduled frames' families, each with the [nodes] key that may override the DBC's
# SyncPeriod (0 keeps it) and a frame that has it
SCHEDULED = {"LEG_PRESSURE": ("leg_pressure_divisor", "LEG_PRESSURE_1"),
             "VALVE_STATUS": ("valve_status_divisor", "VALVE_STATUS_1"),
             "IMU_ATTITUDE": ("imu_divisor", "IMU_ATTITUDE"), "IMU_RATE": ("imu_divisor", "IMU_RATE")}


class SimulatedRig:
    """`rig` (rigs.py or linear_rig.py) with its valve drivers and sensors. The emulator
    drives the steps one by one; `read`/`write` are the in-process hardware interface."""

    def __init__(self, rig, cfg: EmulatorConfig, rng: np.random.Generator | None = None):
        rig.warm_up()                     # kernels loaded before the first SYNC, not in it
        self.rig, self.cfg = rig, cfg
        self.n = n = rig.n_legs
        self.nodes = LEG_NODES[:n]
        self.has_imu = hasattr(rig, "platform_pose")
        self.has_pressure = getattr(rig, "has_pressure_transducers", True)
        self.valves = [self.new_valve() for _ in range(n)]
        self.faults = InjectedFaults()
        self.sensors = SensorModel(cfg.sensors, rng if rng is not None else np.random.default_rng(cfg.sensors.seed))
        self.period_s = cfg.nodes.sync_period_s
        self._divisor = {family: getattr(cfg.nodes, key) or CODECS[frame].schedule.sync_period
                         for family, (key, frame) in SCHEDULED.items()}
        self.spool_demand = np.zeros(n)           # each valve's own demand over the last period
        # the last SYNC's samples (SI), and which of the scheduled ones it took
        self.position_m = np.zeros(n)
        self.force_n = np.zeros(n)
        self.pressure = np.zeros((n, 3))         # PA, PB and the supply at the P port
        self.attitude_rad = np.zeros(3)
        self.rate_rad_s = np.zeros(3)
        self.sampled = np.zeros(n, dtype=bool)   # the leg's node sampled (it is OPERATIONAL)
        self.pressure_due = np.zeros(n, dtype=bool)
        self.status_due = np.zeros(n, dtype=bool)
        self.attitude_due = self.rate_due = False
        # in process: a SYNC counter of its own, and each frame's values as sent and as decoded
        self.counter = 0
        self._overflow = sync_counter_overflow()
        self._wire = {name: (CODECS[name], CODECS[name].new_values(), CODECS[name].new_values())
                      for name in [f"LEG_STATE_{i}" for i in range(1, n + 1)] +
                      [f"LEG_PRESSURE_{i}" for i in range(1, n + 1)] + [f"VALVE_CMD_{i}" for i in range(1, n + 1)] +
                      ["IMU_ATTITUDE", "IMU_RATE"]}
        self._pressures = np.zeros((n, 3))
        self.boot()

    def new_valve(self) -> ValveDriver:
        nodes = self.cfg.nodes
        return ValveDriver(nodes.command_timeout_syncs, nodes.spool_jam_threshold, nodes.spool_jam_syncs)

    def due(self, family: str, name: str, counter: int) -> bool:
        """Whether frame `name` of `family` ("LEG_PRESSURE", "IMU_RATE", ...) is sent on SYNC
        `counter`: its family's divisor, its own SyncPhase."""
        period = self._divisor[family]
        if period <= 1:
            return period == 1
        return (counter - 1) % period == CODECS[name].schedule.sync_phase % period

    # -- one SYNC, step by step ------------------------------------------------------------------
    def valves_on_sync(self, operational) -> list[tuple[int, Emergency]]:
        """Each OPERATIONAL leg's valve applies its latched command and checks its spool; the
        EMCYs they raise, as (leg index, emergency)."""
        raised = []
        for i, valve in enumerate(self.valves):
            if not operational[i]:
                continue
            emergency = valve.on_sync()
            if emergency is None:
                emergency = valve.check_spool(float(self.rig.state[i, hy.S_SPOOL]), float(self.spool_demand[i]))
            if emergency is not None:
                raised.append((i, emergency))
        return raised

    def sample(self, counter: int, operational, imu_operational: bool) -> None:
        """What the sensors report at this SYNC (t_k): the IMU's when due, then each OPERATIONAL
        leg's, in the order the noise is drawn."""
        rig, sensors, faults = self.rig, self.sensors, self.faults
        self.attitude_due = self.has_imu and imu_operational and self.due("IMU_ATTITUDE", "IMU_ATTITUDE", counter)
        self.rate_due = self.has_imu and imu_operational and self.due("IMU_RATE", "IMU_RATE", counter)
        if self.attitude_due:
            sensors.attitude(rig, self.attitude_rad)
        if self.rate_due:
            sensors.rate(rig, self.rate_rad_s)
        for i, node in enumerate(self.nodes):
            self.sampled[i] = operational[i]
            if not operational[i]:
                self.pressure_due[i] = self.status_due[i] = False
                continue
            stroke = rig.stroke_m[i] + encoder_drift_m(faults, node, rig.time_s)
            position, force = sensors.encoder(stroke), sensors.load_cell(float(rig.rod_force_n[i]))
            self.position_m[i], self.force_n[i] = substitute(faults, node, position, force)
            self.pressure_due[i] = self.has_pressure and self.due("LEG_PRESSURE", f"LEG_PRESSURE_{node}", counter)
            if self.pressure_due[i]:
                sensors.pressures(rig, i, self.pressure[i])
            self.status_due[i] = self.due("VALVE_STATUS", f"VALVE_STATUS_{node}", counter)

    def spool_actual(self, leg: int) -> float:
        return float(self.rig.state[leg, hy.S_SPOOL])

    def apply_valves(self) -> None:
        """Spool setpoints to the rig (SPOOL_STUCK: the spool goes there whatever its demand),
        and the load-holding valves open only while the valve is ACTIVE."""
        blocks = self.cfg.nodes.hold_blocks_ports
        for i, valve in enumerate(self.valves):
            stuck = self.faults.param(self.nodes[i], EmuFault.SPOOL_STUCK)
            self.spool_demand[i] = valve.spool_command
            self.rig.command[i] = valve.spool_command if stuck is None else stuck / 100.0
            self.rig.ports_open[i] = 0.0 if blocks and valve.state is not ValveState.ACTIVE else 1.0

    def advance(self) -> None:
        """One SYNC period of physics."""
        self.rig.advance(self.period_s)

    def end_sync(self) -> list[tuple[int, EmuFault]]:
        """The timed faults count one SYNC; the ones that ended now (their physics undone)."""
        ended = self.faults.count_down()
        for target, kind in ended:
            self._apply(target, kind, False)
        return ended

    # -- faults --------------------------------------------------------------------------------
    def inject(self, target: int, kind: EmuFault, param: int) -> None:
        self.faults.inject(target, kind, param)
        self._apply(target, kind, True)

    def clear(self, target: int, kind: EmuFault) -> bool:
        if not self.faults.clear(target, kind):
            return False
        self._apply(target, kind, False)
        return True

    def clear_all(self) -> list[tuple[int, EmuFault]]:
        keys = self.faults.keys()
        for target, kind in keys:
            self.clear(target, kind)
        return keys

    def _apply(self, target: int, kind: EmuFault, on: bool) -> None:
        """A physical fault's effect on the rig (the others act on samples or frames)."""
        rig, leg = self.rig, target - 1
        if kind not in PHYSICAL_FAULTS:
            return
        if kind == EmuFault.VALVE_JAM and 0 <= leg < self.n:
            rig.jammed[leg] = on
        elif kind == EmuFault.LEG_JAM and 0 <= leg < self.n:
            rig.set_rod_seized(leg, on)
        elif kind == EmuFault.SEAL_LEAK and 0 <= leg < self.n:
            rig.set_seal_leak(leg, float(self.faults.param(target, kind)) if on else 0.0)
        elif kind in (EmuFault.SUPPLY_LOSS, EmuFault.SUPPLY_DROP):
            rig.set_supply_fraction(self.supply_fraction())

    def supply_fraction(self) -> float:
        """The power unit's share of its nominal pressure under the supply faults injected:
        none with SUPPLY_LOSS (it stops), SUPPLY_DROP's percentage, else all."""
        if self.faults.of_kind(EmuFault.SUPPLY_LOSS):
            return 0.0
        drops = self.faults.of_kind(EmuFault.SUPPLY_DROP)
        return min(drops) / 100.0 if drops else 1.0

    def silent(self, node: int) -> bool:
        """The node sends nothing (SILENT, DROP)."""
        faults = self.faults
        return bool(faults.get(node, EmuFault.SILENT) or faults.get(node, EmuFault.DROP))

    # -- the in-process hardware interface ----------------------------------------------------------
    def read(self, meas: Measurements) -> None:
        """One SYNC: the valves apply what `write` latched, the sensors sample (what their
        nodes would send, through the wire's codecs) into `meas`, the rig runs one period. A
        silent node's frames do not come; a CORRUPT one's are rejected."""
        self.counter = self.counter % self._overflow + 1
        every = (True,) * self.n
        raised = self.valves_on_sync(every)
        meas.emergency = any(emergency.error_code for _, emergency in raised)     # an EMCY with an error
        self.sample(self.counter, every, True)
        faults = self.faults
        meas.pressure_fresh[:] = False
        meas.attitude_fresh = meas.rate_fresh = False
        for i, node in enumerate(self.nodes):
            silent = self.silent(node)
            corrupt = bool(faults.get(node, EmuFault.CORRUPT))
            meas.fresh[i] = not (silent or corrupt)
            meas.rejected[i] = corrupt and not silent
            if not meas.fresh[i]:
                continue
            valve = self.valves[i]
            decoded = self._through_wire(f"LEG_STATE_{i + 1}", leg_state_values, self.position_m[i],
                                         self.force_n[i], self.spool_actual(i), int(valve.state), False)
            leg_state_into(decoded, meas, i)
            if self.pressure_due[i]:
                decoded = self._through_wire(f"LEG_PRESSURE_{i + 1}", leg_pressure_values, *self.pressure[i])
                meas.pressure_valid[i] = leg_pressure_into(decoded, self._pressures, i)
                if meas.pressure_valid[i]:
                    meas.pa_pa[i], meas.pb_pa[i], meas.ps_pa[i] = self._pressures[i]
                    meas.pressure_fresh[i] = True
        if self.attitude_due and not self.silent(IMU_NODE):
            decoded = self._through_wire("IMU_ATTITUDE", attitude_values, self.attitude_rad)
            meas.attitude_fresh = attitude_into(decoded, meas.attitude_rad)
        if self.rate_due and not self.silent(IMU_NODE):
            decoded = self._through_wire("IMU_RATE", rate_values, self.rate_rad_s)
            meas.rate_fresh = rate_into(decoded, meas.rate_rad_s)
        self.apply_valves()
        self.advance()
        self.end_sync()

    def write(self, cmd: ValveCommands) -> None:
        """The valve commands, latched by each valve for the next SYNC (through the wire's
        codec: the setpoint at its resolution). DROP on the controller's node: ignored."""
        if self.faults.get(CONTROLLER_NODE, EmuFault.DROP):
            return
        for i, valve in enumerate(self.valves):
            decoded = self._through_wire(f"VALVE_CMD_{i + 1}", valve_command_values, cmd, i)
            valve.receive(*valve_command_of(decoded))

    def boot(self) -> None:
        """Power-on: every valve INIT -> DISABLED."""
        for valve in self.valves:
            valve.boot()

    def _through_wire(self, name: str, fill, *args):
        """Fill frame `name`'s values; what a receiver would decode from them (the codec's
        steps and ranges; a frame with a value not finite leaves the last one's)."""
        codec, values, decoded = self._wire[name]
        fill(values, *args)
        codec.quantize_into(values, decoded)
        return decoded
