"""What the monitor knows of the bus, frame by frame: decoded with the project's codecs
(E2E-checked), nothing rendered here, nothing sent. The terminal app reads a `Snapshot` of it
ten times a second; the live or replayed source feeds it from its own thread.

Times are the frames' timestamps (the bus's receive time live, the log's on replay), so a
replay shows exactly what a live view would have shown at that instant.
"""

from __future__ import annotations

import csv
import threading
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hil.logdata_canopen import PdoReader, imu_valid
from protocol.busload import frame_bits_nominal
from protocol.canopen_layout import load_layout
from protocol.codec import CODECS, FrameDecoder
from protocol.devices import HEARTBEAT_BASE
from protocol.e2e import E2E_REJECTED, RxStatus
from protocol.enums import (
    Ack,
    AckKind,
    Command,
    ControllerKind,
    EmcyCode,
    Fault,
    ImuStatus,
    NmtCommand,
    NmtState,
    State,
    ValveFaultReason,
    ValveState,
)
from protocol.nodes import CONTROLLER_NODE, LEG_NODES, SENDER_OF_NODE

N_LEGS = len(LEG_NODES)
BITRATE_BIT_S = 1_000_000          # the DBC's bus (1 Mbit/s classic CAN)
HISTORY_S = 60.0                   # scroll-back kept per leg
RATE_WINDOW_S = 1.0                # frames per second and bus load over this window
SYNC_PERIODS_KEPT = 2048           # SYNC period statistics over the last this many
EVENTS_KEPT = 200                  # EMCY, host commands, acks, NMT
VELOCITY_SPAN = 10                 # cycles the legs' velocity is differenced over
# per leg, per SYNC: the columns of the history and of the CSV export (thesis units at this edge)
COLUMNS = ("position_mm", "force_n", "spool_cmd_pct", "pa_bar", "pb_bar")
_SCALE = {"position_mm": 1e3, "force_n": 1.0, "spool_cmd_pct": 1e2, "pa_bar": 1e-5, "pb_bar": 1e-5}


def _ring_order(written: int, size: int) -> np.ndarray:
    """Indices of a ring buffer's rows, oldest first, after `written` writes."""
    n = min(written, size)
    return (written - n + np.arange(n)) % size


def _name(enum, value: float) -> str:
    try:
        return enum(int(value)).name
    except ValueError:
        return f"{int(value)}?"


@dataclass
class Event:
    time_s: float
    text: str


@dataclass
class Leg:
    """The latest of one leg's frames (SI), with the log time each came."""
    position_m: float = float("nan")
    force_n: float = float("nan")
    velocity_m_s: float = float("nan")
    valve_state: str = "-"
    sensor_fault: bool = False
    seen_s: float = float("nan")              # last LEG_STATE
    status_state: str = "-"                   # VALVE_STATUS: state, spool, fault reason
    spool_actual: float = float("nan")
    fault_reason: str = "-"
    control_bits: str = "----"                # VALVE_CMD: D H M R
    spool_cmd: float = float("nan")
    pa_pa: float = float("nan")
    pb_pa: float = float("nan")
    pressure_seen_s: float = float("nan")
    load_mass_kg: float = float("nan")        # CTRL_LOAD: the RLS mass, the indirect load pressure
    load_pressure_pa: float = float("nan")
    rejected: int = 0                         # LEG_STATE frames the E2E check rejected
    lost: int = 0                             # gaps in its counter


@dataclass
class Snapshot:
    """A consistent copy for one redraw."""
    now_s: float
    state: str
    fault: str
    fault_leg: int
    controller: str
    active_waypoint: int
    overruns: int
    compute_max_us: float
    period_error_max_us: float
    status_seen_s: float
    legs: list[Leg]
    n_legs: int
    attitude_rad: tuple[float, float, float] | None
    imu_status: str
    truth_m: tuple[float, float, float] | None
    host: list[Event]
    acks: list[Event]
    emcy: list[Event]
    nmt: list[Event]
    states: list[Event]
    heartbeats: dict[str, tuple[str, float]]
    rates: dict[str, float]
    load: float
    sync_period_us: float
    sync_jitter_p99_us: float
    sync_jitter_max_us: float
    frames: int
    unknown: int
    rejected: int
    lost: int
    positions_m: np.ndarray = field(repr=False)   # the legs' strokes for a DK
    payload_kg: float = float("nan")              # CTRL_PAYLOAD's MASS
    payload_estimated: bool = False               # ... ESTIMATING (else the declared payload)
    clock_rate: float = float("nan")              # CTRL_CLOCK's RATE while a trajectory plays (NaN: none)


class BusView:
    """Every frame through `feed`; `snapshot` and `history` for the screen."""

    def __init__(self, period_s: float = 0.002, history_s: float = HISTORY_S, devices: str = "hydrapod"):
        """`devices`: the nodes' profile (`canopen`: stock devices' PDOs read as the DBC's
        messages they stand for, their heartbeats by device name)."""
        self.lock = threading.Lock()
        self.decoder = FrameDecoder()
        self.period_s = period_s
        self.now_s = float("nan")
        self.frames = 0
        self.bits = 0
        self.legs = [Leg() for _ in range(N_LEGS)]
        self.n_legs = 0
        self.state, self.fault, self.fault_leg, self.controller = "-", "-", 0, "-"
        self.active_waypoint = self.overruns = 0
        self.payload_kg, self.payload_estimated, self.clock_rate = float("nan"), False, float("nan")
        self.compute_max_us = self.period_error_max_us = float("nan")
        self.status_seen_s = float("nan")
        self.attitude_rad: tuple[float, float, float] | None = None
        self.imu_status = "-"
        self.truth_m: tuple[float, float, float] | None = None
        self.host: deque[Event] = deque(maxlen=EVENTS_KEPT)
        self.acks: deque[Event] = deque(maxlen=EVENTS_KEPT)
        self.emcy: deque[Event] = deque(maxlen=EVENTS_KEPT)
        self.nmt: deque[Event] = deque(maxlen=EVENTS_KEPT)
        self.states: deque[Event] = deque(maxlen=EVENTS_KEPT)     # the controller's state changes
        self.heartbeats: dict[str, tuple[str, float]] = {}
        self.last_host_cmd_counter = -1          # for a sender joining the host's HOST_CMD sequence
        self.last_host_cmd_seq = 0
        self._sync_times = np.full(SYNC_PERIODS_KEPT + 1, np.nan)
        self._sync_n = 0
        # per-SYNC history: time, then each column for every leg
        self.rows = max(16, int(history_s / period_s))
        self._hist = np.full((self.rows, 1 + len(COLUMNS) * N_LEGS), np.nan)
        self._hist_n = 0
        self._rate_counts = np.zeros(len(self.decoder.names), dtype=np.int64)
        self._rate_bits = 0
        self._rate_t = float("nan")
        self.rates: dict[str, float] = {}
        self.load = 0.0
        self._handlers = self._make_handlers()
        self.pdo: PdoReader | None = None
        self._stock_heartbeats: dict[int, str] = {}
        self._pdo_rate_counts: dict[str, int] = {}
        if devices == "canopen":
            self.pdo = PdoReader(lambda name: self.decoder.values[name])
            for name in ("IMU_ATTITUDE", "IMU_RATE"):
                imu_valid(name, self.decoder.values[name])
            dbc_heartbeats = {c.frame_id for n, c in CODECS.items() if n.startswith("HEARTBEAT_")}
            self._stock_heartbeats = {HEARTBEAT_BASE + d.node: d.name for d in load_layout(N_LEGS)
                                      if HEARTBEAT_BASE + d.node not in dbc_heartbeats}

    # -- frames ------------------------------------------------------------------------
    def feed(self, time_s: float, frame_id: int, data, is_extended: bool = False) -> RxStatus:
        """One frame off the bus or the log."""
        with self.lock:
            self.frames += 1
            self.bits += frame_bits_nominal(len(data))
            self.now_s = time_s
            if is_extended:
                self.decoder.unknown_frames += 1
                return RxStatus.UNKNOWN_ID
            if self.pdo is not None and frame_id in self.pdo.pdos:
                return self._feed_pdo(time_s, frame_id, data)
            if frame_id in self._stock_heartbeats and len(data) >= 1:
                self.heartbeats[self._stock_heartbeats[frame_id]] = (_name(NmtState, data[0] & 0x7F), time_s)
                self._roll_rates(time_s)
                return RxStatus.OK
            status = self.decoder.receive(frame_id, data)
            handler = self._handlers.get(frame_id)
            if handler is not None:
                handler(time_s, status)
            self._roll_rates(time_s)
            return status

    def _feed_pdo(self, time_s: float, frame_id: int, data) -> RxStatus:
        """A stock device's PDO: each DBC message it wrote into handled as if received."""
        touched = self.pdo.read(frame_id, data)
        if touched is not None:
            for name in touched:
                handler = self._handlers.get(CODECS[name].frame_id)
                if handler is not None:
                    handler(time_s, RxStatus.OK)
        self._roll_rates(time_s)
        return RxStatus.OK if touched is not None else RxStatus.BAD_LENGTH

    def _pdo_counts(self, status: str) -> dict[str, int]:
        if self.pdo is None:
            return {}
        return {name: c[status] for name, c in self.pdo.counts.items() if c.get(status)}

    def _make_handlers(self) -> dict:
        h = {CODECS["SYNC"].frame_id: self._sync, CODECS["CTRL_STATUS"].frame_id: self._status,
             CODECS["CTRL_ACK"].frame_id: self._ack, CODECS["HOST_CMD"].frame_id: self._host_cmd,
             CODECS["HOST_WAYPOINT_TIME"].frame_id: self._waypoint, CODECS["NMT"].frame_id: self._nmt,
             CODECS["IMU_ATTITUDE"].frame_id: self._imu, CODECS["EMU_TRUTH"].frame_id: self._truth,
             CODECS["CTRL_PAYLOAD"].frame_id: self._payload, CODECS["CTRL_CLOCK"].frame_id: self._clock,
             CODECS["CTRL_LOAD"].frame_id: self._load}
        for leg in range(N_LEGS):
            n = leg + 1
            h[CODECS[f"LEG_STATE_{n}"].frame_id] = lambda t, s, leg=leg: self._leg_state(t, s, leg)
            h[CODECS[f"VALVE_STATUS_{n}"].frame_id] = lambda t, s, leg=leg: self._valve_status(t, s, leg)
            h[CODECS[f"VALVE_CMD_{n}"].frame_id] = lambda t, s, leg=leg: self._valve_cmd(t, s, leg)
            h[CODECS[f"LEG_PRESSURE_{n}"].frame_id] = lambda t, s, leg=leg: self._pressure(t, s, leg)
        for name, codec in CODECS.items():
            if name.startswith("EMCY_"):
                h[codec.frame_id] = lambda t, s, name=name: self._emcy(t, s, name)
            elif name.startswith("HEARTBEAT_"):
                h[codec.frame_id] = lambda t, s, name=name: self._heartbeat(t, s, name)
        return h

    def _values(self, name: str) -> tuple[np.ndarray, dict[str, int]]:
        return self.decoder.values[name], CODECS[name].index

    def _sync(self, t: float, status: RxStatus) -> None:
        self._sync_times[self._sync_n % len(self._sync_times)] = t
        self._sync_n += 1
        row = self._hist[self._hist_n % self.rows]
        row[0] = t
        for leg, s in enumerate(self.legs):
            base = 1 + leg * len(COLUMNS)
            row[base:base + len(COLUMNS)] = (s.position_m, s.force_n, s.spool_cmd, s.pa_pa, s.pb_pa)
        self._hist_n += 1

    def _status(self, t: float, status: RxStatus) -> None:
        if status is not RxStatus.OK:
            return
        v, i = self._values("CTRL_STATUS")
        state, fault = _name(State, v[i["STATE"]]), _name(Fault, v[i["FAULT_CODE"]])
        if (state, fault) != (self.state, self.fault):
            self.states.append(Event(t, f"{state}" + (f" {fault}" if fault != "NONE" else "")))
        self.state, self.fault = state, fault
        self.controller = _name(ControllerKind, v[i["CONTROLLER"]])
        self.compute_max_us = v[i["COMPUTE_TIME_MAX"]] * 1e6
        self.period_error_max_us = v[i["PERIOD_ERROR_MAX"]] * 1e6
        self.overruns = int(v[i["OVERRUNS"]])
        self.active_waypoint = int(v[i["ACTIVE_WAYPOINT"]])
        self.status_seen_s = t

    def _payload(self, t: float, status: RxStatus) -> None:
        if status is RxStatus.OK:
            v, i = self._values("CTRL_PAYLOAD")
            self.payload_kg, self.payload_estimated = float(v[i["MASS"]]), bool(v[i["ESTIMATING"]])

    def _load(self, t: float, status: RxStatus) -> None:
        if status is RxStatus.OK:
            v, i = self._values("CTRL_LOAD")
            leg = int(v[i["LEG"]]) - 1
            if 0 <= leg < N_LEGS:
                self.legs[leg].load_mass_kg = float(v[i["MASS"]])
                self.legs[leg].load_pressure_pa = float(v[i["LOAD_PRESSURE"]])

    def _clock(self, t: float, status: RxStatus) -> None:
        if status is RxStatus.OK:
            v, i = self._values("CTRL_CLOCK")
            self.clock_rate = float(v[i["RATE"]]) if v[i["MOVING"]] else float("nan")

    def _ack(self, t: float, status: RxStatus) -> None:
        if status is RxStatus.OK:
            v, i = self._values("CTRL_ACK")
            self.acks.append(Event(t, f"{_name(AckKind, v[i['KIND']])} {int(v[i['SEQ']])}: "
                                      f"{_name(Ack, v[i['RESULT']])} (free {int(v[i['QUEUE_FREE']])})"))

    def _host_cmd(self, t: float, status: RxStatus) -> None:
        if status is RxStatus.OK:
            v, i = self._values("HOST_CMD")
            self.last_host_cmd_seq = int(v[i["SEQ"]])
            self.last_host_cmd_counter = int(v[i["E2E_COUNTER"]])
            self.host.append(Event(t, f"CMD {self.last_host_cmd_seq} {_name(Command, v[i['COMMAND']])} "
                                      f"{int(v[i['ARGUMENT']])}"))

    def _waypoint(self, t: float, status: RxStatus) -> None:
        if status is RxStatus.OK:
            v, i = self._values("HOST_WAYPOINT_TIME")
            p, j = self._values("HOST_WAYPOINT_POS")
            self.host.append(Event(t, f"WP {int(v[i['SEQ']])} {p[j['X']] * 1e3:.1f} {p[j['Y']] * 1e3:.1f} "
                                      f"{p[j['Z']] * 1e3:.1f} mm {v[i['SEGMENT_TIME']]:.2f} s "
                                      f"f{int(v[i['FLAGS']])}"))

    def _nmt(self, t: float, status: RxStatus) -> None:
        # the NMT master (the controller) starting nodes: it may be a new process whose
        # alive counters start afresh, so its next frames are not out of sequence
        self.decoder.restart_sender(CODECS["NMT"].schedule.sender)
        v, i = self._values("NMT")
        node = int(v[i["NODE_ID"]])
        self.nmt.append(Event(t, f"{_name(NmtCommand, v[i['COMMAND']])} -> "
                                 f"{SENDER_OF_NODE.get(node, 'all' if node == 0 else str(node))}"))

    def _heartbeat(self, t: float, status: RxStatus, name: str) -> None:
        v, i = self._values(name)
        sender = CODECS[name].schedule.sender
        if int(v[i["STATE"]]) == NmtState.BOOTUP:          # the node restarted: so did its counters
            self.decoder.restart_sender(sender)
        self.heartbeats[sender] = (_name(NmtState, v[i["STATE"]]), t)

    def _emcy(self, t: float, status: RxStatus, name: str) -> None:
        v, i = self._values(name)
        sender = CODECS[name].schedule.sender
        controller = sender == SENDER_OF_NODE[CONTROLLER_NODE]
        detail = _name(Fault if controller else ValveFaultReason, v[i["DETAIL"]])
        info = int(v[i["INFO"]])
        text = f"{sender} {_name(EmcyCode, v[i['ERROR_CODE']])} {detail}"
        if controller and info:
            text += f" leg {info}"
            self.fault_leg = info
        elif not controller and info:
            text += f" ({info})"
        if controller and int(v[i["ERROR_CODE"]]) == 0:
            self.fault_leg = 0
        self.emcy.append(Event(t, text))

    def _imu(self, t: float, status: RxStatus) -> None:
        if status is RxStatus.OK:
            v, i = self._values("IMU_ATTITUDE")
            self.attitude_rad = (v[i["ROLL"]], v[i["PITCH"]], v[i["YAW"]])
            self.imu_status = _name(ImuStatus, v[i["STATUS"]])

    def _truth(self, t: float, status: RxStatus) -> None:
        if status is RxStatus.OK:
            v, i = self._values("EMU_TRUTH")
            self.truth_m = (v[i["X"]], v[i["Y"]], v[i["Z"]])

    def _leg_state(self, t: float, status: RxStatus, leg: int) -> None:
        s = self.legs[leg]
        if status in E2E_REJECTED:
            s.rejected += 1
            return
        v, i = self._values(f"LEG_STATE_{leg + 1}")
        s.position_m, s.force_n = v[i["POSITION"]], v[i["FORCE"]]
        s.valve_state = _name(ValveState, v[i["VALVE_STATE"]])
        s.sensor_fault = bool(v[i["SENSOR_FAULT"]])
        s.seen_s = t
        s.lost = int(self.decoder.lost[self.decoder.slot[f"LEG_STATE_{leg + 1}"]])
        self.n_legs = max(self.n_legs, leg + 1)

    def _valve_status(self, t: float, status: RxStatus, leg: int) -> None:
        if status is RxStatus.OK:
            v, i = self._values(f"VALVE_STATUS_{leg + 1}")
            s = self.legs[leg]
            s.status_state = _name(ValveState, v[i["VALVE_STATE"]])
            s.spool_actual = v[i["SPOOL_ACTUAL"]]
            s.fault_reason = _name(ValveFaultReason, v[i["FAULT_REASON"]])

    def _valve_cmd(self, t: float, status: RxStatus, leg: int) -> None:
        if status is RxStatus.OK:
            v, i = self._values(f"VALVE_CMD_{leg + 1}")
            s = self.legs[leg]
            s.control_bits = "".join(c if v[i[f"CW_{c}"]] else "-" for c in "DHMR")
            s.spool_cmd = v[i["SPOOL_SETPOINT"]]

    def _pressure(self, t: float, status: RxStatus, leg: int) -> None:
        if status is RxStatus.OK:
            v, i = self._values(f"LEG_PRESSURE_{leg + 1}")
            s = self.legs[leg]
            s.pa_pa, s.pb_pa, s.pressure_seen_s = v[i["PA"]], v[i["PB"]], t

    def _roll_rates(self, t: float) -> None:
        if not self._rate_t == self._rate_t:          # NaN: the first frame
            self._rate_t = t
            return
        dt = t - self._rate_t
        if dt < RATE_WINDOW_S:
            return
        counts = self.decoder.counts.sum(axis=1)
        per_s = (counts - self._rate_counts) / dt
        self.rates = {n: float(r) for n, r in zip(self.decoder.names, per_s, strict=True) if r > 0}
        pdo = self._pdo_counts("OK")
        self.rates.update({n: (c - self._pdo_rate_counts.get(n, 0)) / dt for n, c in pdo.items()})
        self._pdo_rate_counts = pdo
        self.load = (self.bits - self._rate_bits) / dt / BITRATE_BIT_S
        self._rate_counts[:] = counts
        self._rate_bits, self._rate_t = self.bits, t

    # -- reading -----------------------------------------------------------------------
    def _sync_stats(self) -> tuple[float, float, float]:
        order = _ring_order(self._sync_n, len(self._sync_times))
        if len(order) < 3:
            return float("nan"), float("nan"), float("nan")
        periods = np.diff(self._sync_times[order])
        nominal = float(np.median(periods))
        error = np.abs(periods - nominal)
        return nominal * 1e6, float(np.percentile(error, 99)) * 1e6, float(error.max()) * 1e6

    def _velocities(self) -> None:
        n = min(self._hist_n, self.rows)
        if n <= VELOCITY_SPAN:
            return
        last = self._hist[(self._hist_n - 1) % self.rows]
        first = self._hist[(self._hist_n - 1 - VELOCITY_SPAN) % self.rows]
        dt = last[0] - first[0]
        for leg, s in enumerate(self.legs):
            col = 1 + leg * len(COLUMNS)
            s.velocity_m_s = (last[col] - first[col]) / dt if dt > 0 else float("nan")

    def snapshot(self) -> Snapshot:
        with self.lock:
            self._velocities()
            period, p99, worst = self._sync_stats()
            counts = self.decoder.counts
            rejected = int(sum(counts[:, s].sum() for s in E2E_REJECTED)) + sum(self._pdo_counts("BAD_LENGTH").values())
            return Snapshot(
                now_s=self.now_s, state=self.state, fault=self.fault, fault_leg=self.fault_leg,
                controller=self.controller, active_waypoint=self.active_waypoint, overruns=self.overruns,
                compute_max_us=self.compute_max_us, period_error_max_us=self.period_error_max_us,
                status_seen_s=self.status_seen_s, legs=[Leg(**vars(s)) for s in self.legs], n_legs=self.n_legs,
                attitude_rad=self.attitude_rad, imu_status=self.imu_status, truth_m=self.truth_m,
                host=list(self.host)[-8:], acks=list(self.acks)[-8:], emcy=list(self.emcy)[-10:],
                nmt=list(self.nmt)[-4:], states=list(self.states)[-4:], heartbeats=dict(self.heartbeats),
                rates=dict(self.rates), load=self.load,
                sync_period_us=period, sync_jitter_p99_us=p99, sync_jitter_max_us=worst, frames=self.frames,
                unknown=self.decoder.unknown_frames, rejected=rejected, lost=int(self.decoder.lost.sum()),
                positions_m=np.array([s.position_m for s in self.legs]), payload_kg=self.payload_kg,
                payload_estimated=self.payload_estimated, clock_rate=self.clock_rate)

    def history(self, end_s: float, window_s: float) -> np.ndarray:
        """The per-SYNC rows with end_s - window_s < time <= end_s, oldest first (a copy of
        those rows only: the ring holds a minute)."""
        with self.lock:
            order = _ring_order(self._hist_n, self.rows)
            times = self._hist[order, 0]
            lo = np.searchsorted(times, end_s - window_s, side="right")
            hi = np.searchsorted(times, end_s, side="right")
            return self._hist[order[lo:hi]]

    def oldest_s(self) -> float:
        with self.lock:
            n = min(self._hist_n, self.rows)
            return float(self._hist[(self._hist_n - n) % self.rows, 0]) if n else float("nan")

    def export_csv(self, path: str | Path, end_s: float, window_s: float) -> int:
        """The visible window as CSV (time in the frames' clock, thesis units); rows written."""
        rows = self.history(end_s, window_s)
        n_legs = max(self.n_legs, 1)
        header = ["time_s"] + [f"leg{leg + 1}_{c}" for leg in range(n_legs) for c in COLUMNS]
        scale = np.array([1.0] + [_SCALE[c] for _ in range(n_legs) for c in COLUMNS])
        with open(path, "w", newline="") as f:
            out = csv.writer(f)
            out.writerow(header)
            for row in rows[:, :1 + n_legs * len(COLUMNS)] * scale:
                out.writerow([f"{row[0]:.6f}"] + [f"{x:.4f}" for x in row[1:]])
        return len(rows)

    def rejected_by_message(self) -> dict[str, int]:
        with self.lock:
            counts = self.decoder.counts
            return {n: int(sum(counts[k, s] for s in E2E_REJECTED)) for k, n in enumerate(self.decoder.names)
                    if any(counts[k, s] for s in E2E_REJECTED)} | self._pdo_counts("BAD_LENGTH")

    def ok_by_message(self) -> dict[str, int]:
        with self.lock:
            return {n: int(self.decoder.counts[k, RxStatus.OK]) for k, n in enumerate(self.decoder.names)
                    if self.decoder.counts[k, RxStatus.OK]} | self._pdo_counts("OK")
