"""A recorded bus log (BLF or ASC, python-can's readers) decoded with the DBC, per cycle.

Every scenario's metrics come from this alone, so a log recorded on the real rig is
analysed exactly like one from the emulator. Cycle k starts at the k-th SYNC (k = 0 for the
first; gaps in the SYNC counter count); a frame belongs to the cycle whose SYNC it answers
(see `_assign_cycles` for the on-host bus). Frames before the first SYNC get cycle -1. Values
are SI (the codecs' units).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from pathlib import Path

import can
import numpy as np

from hil.logdata_canopen import CanopenLog
from program.errors import UserInputError
from protocol.codec import CODECS, FrameDecoder
from protocol.dbc import sync_counter_overflow, truth_phase
from protocol.devices import SDO_REQUEST_BASE, SDO_RESPONSE_BASE
from protocol.e2e import E2E_REJECTED, RxStatus
from protocol.enums import NmtCommand
from protocol.nodes import NODE_IDS

LOG_SUFFIXES = (".blf", ".asc")
# the emulator sends EMU_TRUTH right after the frames of the same SYNC; its stalls have been
# 100 ms at most here (between two truths, or a truth and its frames), a restart takes 0.8 s+
TRUTH_AFTER_FRAMES_MAX_S = 0.25


@dataclass
class Series:
    """Every OK frame of one message: the cycle it came in, its log time, its signals."""
    name: str
    cycle: np.ndarray           # (n,) int
    time_s: np.ndarray          # (n,) log timestamps
    values: np.ndarray          # (n, n_signals) SI
    index: dict[str, int]

    def __getitem__(self, signal: str) -> np.ndarray:
        return self.values[:, self.index[signal]]

    def __len__(self) -> int:
        return len(self.cycle)

    def per_cycle(self, n_cycles: int, signal: str) -> np.ndarray:
        """The signal on the cycle grid (NaN where the frame is missing; the last one wins)."""
        out = np.full(n_cycles, np.nan)
        ok = (self.cycle >= 0) & (self.cycle < n_cycles)
        out[self.cycle[ok]] = self[signal][ok]
        return out


@dataclass
class Event:
    """One event frame (host commands, waypoints, acknowledgements, emulator control, EMCY)."""
    cycle: int
    time_s: float
    name: str
    values: dict[str, float]


@dataclass
class LogData:
    path: str
    n_cycles: int
    sync_time_s: np.ndarray                    # (n_cycles,) log time of each SYNC (NaN: not in the log)
    series: dict[str, Series]
    events: list[Event]
    frames: int
    rx_counts: dict[str, dict[str, int]]       # message -> status -> frames
    lost: dict[str, int]                       # message -> frames missing from the counter sequence
    unknown_frames: int
    rejected: dict[str, np.ndarray] = field(default_factory=dict)   # message -> cycles of E2E-rejected frames

    @property
    def e2e_errors(self) -> int:
        """Frames the E2E check rejects (CRC, repeated, wrong sequence, length)."""
        rejected = {s.name for s in E2E_REJECTED}
        return sum(n for counts in self.rx_counts.values() for s, n in counts.items() if s in rejected)

    @property
    def lost_frames(self) -> int:
        return sum(self.lost.values())

    def get(self, name: str) -> Series:
        return self.series.get(name) or _empty(name)

    def leg_positions(self, n_legs: int) -> np.ndarray:
        """(n_cycles, n_legs) encoder strokes, m (NaN where a frame is missing)."""
        return np.column_stack([self.get(f"LEG_STATE_{leg + 1}").per_cycle(self.n_cycles, "POSITION")
                                for leg in range(n_legs)])

    def events_named(self, *names: str) -> list[Event]:
        return [e for e in self.events if e.name in names]


EVENT_MESSAGES = ("NMT", "HOST_CMD", "HOST_TEST", "HOST_WAYPOINT_POS", "HOST_WAYPOINT_ROT", "HOST_WAYPOINT_TIME",
                  "CTRL_ACK", "EMU_CTRL", "EMU_KICK") + tuple(n for n in CODECS if n.startswith("EMCY_"))


def _empty(name: str) -> Series:
    codec = CODECS[name]
    return Series(name, np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros((0, len(codec.signals))),
                  dict(codec.index))


EMULATOR_SENDERS = {"LEG1", "LEG2", "LEG3", "LEG4", "LEG5", "LEG6", "IMU", "EMULATOR"}


SENDER_GROUPS = ("controller", "emulator", "host", "not in the DBC")


def frames_by_sender(path: str | Path) -> dict[str, int]:
    """Frames in a log per sender group (the DBC's sender of each id): controller, emulator
    (its leg, IMU and emulator nodes), host, and ids the DBC does not know. SDO (CiA 301,
    not in the DBC): requests are the controller's, answers the nodes'."""
    sender = {c.frame_id: c.schedule.sender for c in CODECS.values()}
    for node in NODE_IDS.values():
        sender[SDO_REQUEST_BASE + node], sender[SDO_RESPONSE_BASE + node] = "CONTROLLER", "EMULATOR"
    counts = dict.fromkeys(SENDER_GROUPS, 0)
    for frame_id, _, _ in _read_frames(Path(path)):
        name = sender.get(frame_id)
        counts["not in the DBC" if name is None else "controller" if name == "CONTROLLER"
               else "host" if name == "HOST" else "emulator"] += 1
    return counts


def frames_counted_by_senders(children: dict[str, dict], host_frames_sent: int) -> dict[str, int]:
    """What the senders counted sending: every controller's `frames_sent` and every
    emulator's `frames_out` (restarted ones included, from their summaries), the host's own."""
    counts = dict.fromkeys(SENDER_GROUPS, 0)
    counts["host"] = host_frames_sent
    for name, summary in children.items():
        group, key = ("controller", "frames_sent") if name.startswith("controller") else ("emulator", "frames_out")
        counts[group] += int(summary[key])
    return counts


def _read_frames(path: Path) -> list[tuple]:
    frames = []
    try:
        with can.LogReader(str(path)) as reader:
            for msg in reader:
                if msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id or msg.is_fd:
                    frames.append((None, b"", msg.timestamp))
                else:
                    frames.append((msg.arbitration_id, bytes(msg.data), msg.timestamp))
    except (OSError, ValueError, EOFError, struct.error) as error:
        raise UserInputError(f"{path}: cannot read the log ({error})") from None
    return frames


def _assign_cycles(frames: list[tuple], device_ids: frozenset = frozenset()) -> np.ndarray:
    """The cycle of every frame (see the module docstring).

    On a real bus, log order is bus order. On the on-host multicast bus the kernel can hand
    the recorder frames of different senders out of order (per-CPU queues), while each
    sender's own frames stay in order. So: SYNC counters number the cycles; the
    controller's frames follow their SYNC; the emulator's cyclic frames (and `device_ids`,
    stock devices' TPDOs) belong to the cycle of the EMU_TRUTH that closes them (it carries
    the SYNC counter's low 4 bits).
    """
    sync_id = CODECS["SYNC"].frame_id
    truth_id = CODECS["EMU_TRUTH"].frame_id
    overflow = sync_counter_overflow()
    n = len(frames)
    by_order = np.full(n, -1, dtype=np.int64)
    counter_of_cycle: dict[int, int] = {}
    cycle, last_counter = -1, None
    for i, (frame_id, data, _) in enumerate(frames):
        if frame_id == sync_id and len(data) == 1 and 1 <= data[0] <= overflow:
            counter = data[0]
            cycle += 1 if last_counter is None else ((counter - last_counter) % overflow or overflow)
            last_counter = counter
            counter_of_cycle[cycle] = counter
        by_order[i] = cycle
    truths = [i for i, f in enumerate(frames) if f[0] == truth_id and len(f[1]) == 8]
    if not truths:
        return by_order
    out = by_order.copy()
    emulator_ids = {c.frame_id for c in CODECS.values()
                    if c.schedule.sender in EMULATOR_SENDERS and c.schedule.sync_period > 0} | device_ids
    truth_cycle = {}
    previous, previous_t = None, -math.inf
    for i in truths:
        guess, phase, t = by_order[i], frames[i][1][1] >> 4, frames[i][2]
        # only cycles that had a SYNC (a default of -1 would match phase 15: -1 % 16 == 15)
        matches = [k for k in range(guess - 8, guess + 8) if k in counter_of_cycle
                   and truth_phase(counter_of_cycle[k]) == phase]
        if previous is not None and t - previous_t <= TRUTH_AFTER_FRAMES_MAX_S:
            # the same process, answering its SYNCs in order: after a stall its backlog
            # comes in a burst, each answer to the first SYNC of its phase after the last
            behind = [k for k in range(previous + 1, guess + 8) if k in counter_of_cycle
                      and truth_phase(counter_of_cycle[k]) == phase]
            matches = behind[:1] or matches
        truth_cycle[i] = min(matches, key=lambda k: abs(k - guess)) if matches else guess
        previous, previous_t = truth_cycle[i], t
    # walk backwards: an emulator cyclic frame belongs to the next EMU_TRUTH's cycle, if that
    # comes right after it (an emulator killed between its frames and their EMU_TRUTH left
    # them to the next process's first truth, seconds later: they keep their SYNC's cycle)
    following, following_t = None, math.inf
    for i in range(n - 1, -1, -1):
        if i in truth_cycle:
            following, following_t = truth_cycle[i], frames[i][2]
            out[i] = following
        elif frames[i][0] in emulator_ids and following is not None \
                and following_t - frames[i][2] <= TRUTH_AFTER_FRAMES_MAX_S:
            out[i] = following
    return out


def read_log(path: str | Path, devices: str = "hydrapod") -> LogData:
    """Read and decode a BLF or ASC log of a run on `devices` (stock CANopen devices' PDOs read
    as the DBC messages they stand for, `logdata_canopen`); a missing or unreadable file is
    one line (UserInputError)."""
    path = Path(path)
    if path.suffix.lower() not in LOG_SUFFIXES:
        raise UserInputError(f"{path}: not a log this reads (expected {' or '.join(LOG_SUFFIXES)})")
    if not path.is_file():
        raise UserInputError(f"{path}: no such log file")
    frames = _read_frames(path)
    canopen = CanopenLog() if devices == "canopen" else None
    pdo_ids = frozenset(canopen.reader.ids) if canopen is not None else frozenset()
    cycles = _assign_cycles(frames, frozenset(canopen.reader.tpdo_ids) if canopen is not None else frozenset())
    order = np.argsort(cycles, kind="stable")       # each sender's own order is kept
    decoder = FrameDecoder()
    rows: dict[str, list] = {name: [] for name in CODECS}
    events: list[Event] = []
    sync_times: list[tuple] = []
    sync_id, nmt_id = CODECS["SYNC"].frame_id, CODECS["NMT"].frame_id
    event_ids = {CODECS[n].frame_id for n in EVENT_MESSAGES}
    name_of_id = {codec.frame_id: name for name, codec in CODECS.items()}
    rejected: dict[str, list[int]] = {}
    cycle = -1
    for i in order:
        frame_id, data, timestamp = frames[i]
        if frame_id is None:
            continue
        if frame_id in pdo_ids:
            canopen.take(frame_id, data, int(cycles[i]), timestamp, rows)
            continue
        status = decoder.receive(frame_id, data)
        if status is not RxStatus.OK:
            if status in E2E_REJECTED:
                rejected.setdefault(name_of_id[frame_id], []).append(int(cycles[i]))
            continue
        cycle = int(cycles[i])
        if frame_id == nmt_id and decoder.values["NMT"][0] == NmtCommand.START:
            decoder.restart_sender(CODECS["NMT"].schedule.sender)     # a (re)started controller
        if frame_id == sync_id:
            sync_times.append((cycle, timestamp))
        name = name_of_id[frame_id]
        values = decoder.values[name]
        if frame_id in event_ids:
            codec = CODECS[name]
            events.append(Event(cycle, timestamp, name, {s: float(values[k]) for s, k in codec.index.items()}))
        else:
            rows[name].append((cycle, timestamp, *values))
    if canopen is not None:
        canopen.flush(rows)
        for name, cycles_rejected in canopen.rejected.items():
            rejected.setdefault(name, []).extend(cycles_rejected)
    cycle = int(cycles.max()) if len(cycles) else -1
    series = {}
    for name, data in rows.items():
        if not data:
            continue
        array = np.array(data, dtype=float)
        series[name] = Series(name, array[:, 0].astype(np.int64), array[:, 1], array[:, 2:],
                              dict(CODECS[name].index))
    rx_counts = {name: {s.name: int(decoder.counts[i, s]) for s in RxStatus if decoder.counts[i, s]}
                 for i, name in enumerate(decoder.names) if decoder.counts[i].any()}
    if canopen is not None:
        rx_counts.update(canopen.reader.counts)
    lost = {name: int(decoder.lost[i]) for i, name in enumerate(decoder.names) if decoder.lost[i]}
    sync_time_s = np.full(cycle + 1, np.nan)
    for k, t in sync_times:
        sync_time_s[k] = t
    return LogData(str(path), cycle + 1, sync_time_s, series, events, len(frames), rx_counts, lost,
                   decoder.unknown_frames, {name: np.array(c, dtype=np.int64) for name, c in rejected.items()})
