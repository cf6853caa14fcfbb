"""An in-process stand-in for the bus and the rig, for allocation and supervisor tests.

It answers like the emulator's nodes, in plain Python floats (no NumPy, so whatever NumPy
allocates in a test is the controller's): NMT start -> heartbeats OPERATIONAL; on SYNC k
every leg applies the command latched in cycle k-1 (CiA 408: DISABLED/HOLD/ACTIVE) and
sends LEG_STATE_n with its encoder position, load-cell force and the spool its valve's
first-order lag reached (the controller's spool check); each leg is the identified actuator
of Table A.3 (150 mm, 0 kg) integrated by forward-Euler sub-steps.
"""

from __future__ import annotations

import collections
import math
import random
import time

import can

from protocol.codec import CODECS

LOAD_CELL_NOISE_N = 0.3        # the emulated hexapod's load cells, as the controller's [residuals] assumes
HEARTBEAT_S = 0.05             # wall clock, as the nodes' timers (the controller checks on its clock)


def emulated_spool_tau_s() -> float:
    """The emulated valves' spool time constant (their [valve] table)."""
    from physics.hydraulics import HP_TAU_SPOOL
    from plant_emulator.params import load_config
    return float(load_config().hp[HP_TAU_SPOOL])


class FakeBus:
    def __init__(self, n_legs: int, strokes_m, period_s: float = 0.002, b0=11425.0, b1=106.0, k01=0.236,
                 load_kg: float = 1.35, resolution_m: float = 0.125e-3, nodes=None, spool_tau_s: float | None = None):
        self.n = n_legs
        self.period = period_s
        self.b0, self.b1, self.k01 = b0, b1, k01                     # k01 in (m/s)/V
        self.mass = load_kg
        self.res = resolution_m
        self.y = [float(s) for s in strokes_m]
        self.v = [0.0] * n_legs
        self.a = [0.0] * n_legs
        self.spool = [0.0] * n_legs
        self.spool_reached = [0.0] * n_legs                         # the valve's lag toward `spool`
        self.spool_decay = math.exp(-period_s / (spool_tau_s or emulated_spool_tau_s()))
        self.latched = [None] * n_legs
        self.valve = [1] * n_legs                                   # DISABLED
        self.queue = collections.deque()
        self.nodes = nodes or list(range(1, n_legs + 1))
        self.operational = False
        self.syncs = 0
        self._last_heartbeat = 0.0
        self.silent = set()           # legs whose LEG_STATE is not sent
        self.corrupt = set()          # legs whose LEG_STATE has a bad CRC
        self.stuck = {}               # leg -> the encoder reading it is frozen at
        self.imu_rpy = None           # [roll, pitch, yaw]: sent as IMU_ATTITUDE every SYNC when set
        self._imu = (CODECS["IMU_ATTITUDE"], can.Message(arbitration_id=CODECS["IMU_ATTITUDE"].frame_id,
                                                         data=bytearray(8), is_extended_id=False),
                     CODECS["IMU_ATTITUDE"].new_values())
        self.sent = collections.Counter()
        self.last_sent: dict[int, bytes] = {}      # frame id -> the data of its last frame
        codecs = [CODECS[f"LEG_STATE_{i}"] for i in range(1, n_legs + 1)]
        self._state = [(c, can.Message(arbitration_id=c.frame_id, data=c.new_buffer(), is_extended_id=False),
                        c.new_values()) for c in codecs]
        self._hb = {node: can.Message(arbitration_id=0x700 + node, data=bytearray([5]), is_extended_id=False)
                    for node in self.nodes}
        self._cmd_codec = CODECS["VALVE_CMD_1"]
        self._cmd_values = self._cmd_codec.new_values()
        self._cmd_ids = {CODECS[f"VALVE_CMD_{i}"].frame_id: i - 1 for i in range(1, n_legs + 1)}
        self._cmd_codecs = {CODECS[f"VALVE_CMD_{i}"].frame_id: CODECS[f"VALVE_CMD_{i}"] for i in range(1, n_legs + 1)}

    # python-can bus interface ------------------------------------------------------------
    def send(self, msg, timeout=None) -> None:
        frame_id = msg.arbitration_id
        self.sent[frame_id] += 1
        self.last_sent[frame_id] = bytes(msg.data)
        if frame_id == 0x000 and msg.data[0] == 1:
            self.operational = True
            self._heartbeats()
        elif frame_id == 0x080:
            self._sync()
        elif frame_id in self._cmd_ids:
            leg = self._cmd_ids[frame_id]
            self._cmd_codecs[frame_id].decode_into(msg.data, self._cmd_values)
            _, _, d, h, m, r, setpoint = self._cmd_values
            self.latched[leg] = (d > 0.5, h > 0.5, m > 0.5, float(setpoint))

    def recv(self, timeout=None):
        if self.queue:
            return self.queue.popleft()
        return None

    def shutdown(self) -> None:
        pass

    # nodes -------------------------------------------------------------------------------
    def _heartbeats(self) -> None:
        self._last_heartbeat = time.monotonic()
        for msg in self._hb.values():
            self.queue.append(msg)

    def _sync(self) -> None:
        self.syncs += 1
        if not self.operational:
            return
        now = time.monotonic()
        if now - self._last_heartbeat >= HEARTBEAT_S:
            self._heartbeats()
        for leg in range(self.n):
            latched, self.latched[leg] = self.latched[leg], None
            if latched is not None:
                d, h, m, setpoint = latched
                if not (d and h):
                    self.valve[leg] = 1
                elif m and self.valve[leg] in (2, 3):
                    self.valve[leg] = 3
                else:
                    self.valve[leg] = 2
                self.spool[leg] = setpoint if self.valve[leg] == 3 else 0.0
            if leg in self.silent:
                continue
            codec, msg, values = self._state[leg]
            values[2] = self.valve[leg]
            values[3] = 0.0
            values[4] = self.stuck.get(leg, round(self.y[leg] / self.res) * self.res)
            values[5] = self.force_n(leg)
            values[6] = self.spool_actual(leg)
            codec.encode_into(values, msg.data)
            if leg in self.corrupt:
                msg.data[0] ^= 0xFF
            self.queue.append(msg)
        if self.imu_rpy is not None:
            codec, msg, values = self._imu
            values[3], values[4], values[5] = self.imu_rpy
            codec.encode_into(values, msg.data)
            self.queue.append(msg)
        self._advance()

    def force_n(self, leg: int) -> float:
        """The load cell: the leg's own mass accelerated, against gravity (noiseless: the
        controller's frozen load-cell check is off for it, `rig_loop.make_loop`)."""
        return self.mass * (self.a[leg] + 9.81)

    def spool_actual(self, leg: int) -> float:
        return self.spool_reached[leg]

    def _advance(self) -> None:
        for leg in range(self.n):
            target = min(max(self.spool[leg], -1.0), 1.0)
            self.spool_reached[leg] = target + (self.spool_reached[leg] - target) * self.spool_decay
        steps = 20
        h = self.period / steps
        for leg in range(self.n):
            y, v, a = self.y[leg], self.v[leg], self.a[leg]
            u_volts = self.spool[leg] * 10.0
            for _ in range(steps):        # y''' = b0 (k01 u - y') - b1 y''
                jerk = self.b0 * (self.k01 * u_volts - v) - self.b1 * a
                a += h * jerk
                v += h * a
                y += h * v
            self.y[leg], self.v[leg], self.a[leg] = y, v, a



class EmulatedHexapodBus(FakeBus):
    """As FakeBus, with the emulator's hexapod behind the legs (MuJoCo and the hydraulics):
    for a controller that needs the platform's dynamics (computed torque). The rig allocates
    while it steps; what it frees again leaves no growth for the allocation probe to see."""

    def __init__(self, rig, strokes_m, **kwargs):
        from physics.hydraulics import S_SPOOL
        from plant_emulator.emulator import attitude_rpy
        self._spool_column = S_SPOOL
        super().__init__(6, strokes_m, **kwargs)
        self.rig = rig
        self._noise = random.Random(7)              # the load cells' noise, the same every run
        self._attitude_rpy = attitude_rpy
        self.y = [float(s) for s in rig.stroke_m]
        self.imu_rpy = [0.0, 0.0, 0.0]

    def force_n(self, leg: int) -> float:
        return float(self.rig.rod_force_n[leg]) + self._noise.gauss(0.0, LOAD_CELL_NOISE_N)    # as the emulator

    def spool_actual(self, leg: int) -> float:
        return float(self.rig.state[leg, self._spool_column])

    def _advance(self) -> None:
        for leg in range(6):
            self.rig.command[leg] = self.spool[leg]
            self.rig.ports_open[leg] = 1.0 if self.valve[leg] == 3 else 0.0
        self.rig.advance(self.period)
        for leg in range(6):
            self.y[leg] = float(self.rig.stroke_m[leg])
        self.imu_rpy = [float(v) for v in self._attitude_rpy(self.rig.platform_pose()[1])]
