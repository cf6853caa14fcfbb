"""Codecs compiled once from the DBC for the hot path.

cantools parses the DBC and is the oracle in the tests; the loop uses these codecs, which
precompute every signal's shift, mask, sign, scale, offset and unit conversion at import
and then only do integer and float arithmetic on preallocated buffers:

- `MessageCodec.encode_into(values_si, buf)` packs SI values into a frame's bytearray and
  applies E2E protection in place (alive counter + CRC);
- `MessageCodec.decode_into(data, out_si)` unpacks a frame into a preallocated array;
- `FrameDecoder.receive(frame_id, data)` dispatches by id, checks length, CRC and counter,
  decodes only fresh valid frames and returns an `RxStatus`; it never raises on bus input.

Units: the DBC uses engineering units (mm, bar, %, ...) so CAN traces read naturally;
codecs convert to SI at this edge (mm -> m, bar -> Pa, % -> fraction of full valve input).

Out-of-range physical values on encode are saturated to the DBC's [minimum, maximum] and
reported as `EncodeStatus.SATURATED`; a non-finite value rejects the whole frame
(`EncodeStatus.REJECTED`) and leaves the buffer, including its alive counter, untouched,
so a NaN can never reach a valve. Decoding is faithful to the bits (as cantools is):
range and plausibility checks on received data belong to the supervisor.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numba import njit

from protocol import e2e
from protocol.dbc import Schedule, load_database, schedule_of, schedules
from protocol.e2e import RxStatus

STANDARD_ID_MASK = 0x7FF          # the protocol uses 11-bit ids only

# Engineering unit in the DBC -> factor to SI. A unit not listed here fails at import,
# so a DBC edit cannot silently introduce an unconverted unit.
UNIT_TO_SI = {
    "": 1.0,
    "mm": 1e-3,
    "N": 1.0,
    "bar": 1e5,
    "%": 1e-2,
    "rad": 1.0,
    "rad/s": 1.0,
    "s": 1.0,
    "kg": 1.0,
    "V": 1.0,
}

E2E_SIGNALS = ("E2E_CRC", "E2E_COUNTER")


class EncodeStatus(IntEnum):
    OK = 0
    SATURATED = 1   # at least one value was clamped to the DBC range; frame sent
    REJECTED = 2    # a value was NaN or infinite; buffer untouched, nothing to send


@dataclass(frozen=True)
class SignalSpec:
    name: str
    start: int
    length: int
    signed: bool
    scale: float
    offset: float
    unit: str
    to_si: float
    minimum: float     # DBC units
    maximum: float
    raw_min: int       # the DBC range in raw counts, within the field's width
    raw_max: int
    comment: str

    @property
    def resolution_si(self) -> float:
        return self.scale * self.to_si


def _signal_spec(sig) -> SignalSpec:
    if sig.byte_order != "little_endian" or sig.is_float or sig.is_multiplexer or sig.multiplexer_ids:
        raise ValueError(f"signal {sig.name}: only plain little-endian integer signals are supported")
    unit = sig.unit or ""
    if unit not in UNIT_TO_SI:
        raise ValueError(f"signal {sig.name}: unit {unit!r} has no SI conversion in UNIT_TO_SI")
    type_min = -(1 << (sig.length - 1)) if sig.is_signed else 0
    type_max = (1 << (sig.length - 1)) - 1 if sig.is_signed else (1 << sig.length) - 1
    scale, offset = float(sig.scale), float(sig.offset)
    lo = sig.minimum if sig.minimum is not None else type_min * scale + offset
    hi = sig.maximum if sig.maximum is not None else type_max * scale + offset
    # 1e-9 guards the ceil/floor against representation error of e.g. 327.675 / 0.005.
    raw_min = max(type_min, math.ceil((lo - offset) / scale - 1e-9))
    raw_max = min(type_max, math.floor((hi - offset) / scale + 1e-9))
    return SignalSpec(
        name=sig.name, start=sig.start, length=sig.length, signed=sig.is_signed,
        scale=scale, offset=offset, unit=unit, to_si=UNIT_TO_SI[unit],
        minimum=float(lo), maximum=float(hi), raw_min=raw_min, raw_max=raw_max,
        comment=sig.comment or "",
    )


@njit(cache=True)
def quantize_kernel(table, values, out) -> bool:
    """`MessageCodec.quantize_into` on its signal table (rows: index, to_si, scale, offset,
    raw_min, raw_max): each value rounded half to even to its step, as `round` in
    `encode_into`, and saturated; False, `out` unchanged, when one is not finite."""
    for k in range(table.shape[0]):
        if not math.isfinite(values[int(table[k, 0])]):
            return False
    for k in range(table.shape[0]):
        i, to_si, scale, offset = int(table[k, 0]), table[k, 1], table[k, 2], table[k, 3]
        raw = min(max(np.rint((values[i] / to_si - offset) / scale), table[k, 4]), table[k, 5])
        out[i] = (raw * scale + offset) * to_si
    return True


class MessageCodec:
    """Encoder/decoder of one DBC message, compiled at construction."""

    def __init__(self, message, schedule: Schedule | None = None):
        self.schedule = schedule or schedule_of(message)
        self.name: str = message.name
        self.frame_id: int = message.frame_id
        self.dlc: int = message.length
        self.signals: tuple[SignalSpec, ...] = tuple(_signal_spec(s) for s in message.signals)
        self.signal_names: tuple[str, ...] = tuple(s.name for s in self.signals)
        self.index: dict[str, int] = {n: i for i, n in enumerate(self.signal_names)}
        self.data_id: int | None = self.schedule.e2e_data_id
        self.e2e: bool = self.data_id is not None
        if self.e2e and self.signal_names[:2] != E2E_SIGNALS:
            raise ValueError(f"{self.name}: E2E-protected messages start with E2E_CRC, E2E_COUNTER")
        # Per-signal constants as plain tuples: the loops below touch nothing else.
        self._dec_si = tuple(self._dec_field(s, s.to_si) for s in self.signals)
        self._dec_dbc = tuple(self._dec_field(s, 1.0) for s in self.signals)
        first = 2 if self.e2e else 0
        self._enc = tuple(
            (i, s.start, (1 << s.length) - 1, s.to_si, s.scale, s.offset, s.raw_min, s.raw_max)
            for i, s in enumerate(self.signals) if i >= first
        )
        # the same per payload signal for `quantize_kernel`: index, to_si, scale, offset, raw range
        self._quantize = np.array([(i, to_si, scale, offset, raw_min, raw_max)
                                   for i, _, _, to_si, scale, offset, raw_min, raw_max in self._enc], dtype=float)

    @staticmethod
    def _dec_field(s: SignalSpec, to_unit: float):
        sign_bit = 1 << (s.length - 1) if s.signed else 0
        return (s.start, (1 << s.length) - 1, sign_bit, s.scale, s.offset, to_unit)

    def new_values(self) -> np.ndarray:
        """A zeroed value vector in this message's signal order (allocate once, reuse)."""
        return np.zeros(len(self.signals))

    def new_buffer(self) -> bytearray:
        return bytearray(self.dlc)

    # -- hot path ---------------------------------------------------------------------
    def encode_into(self, values, buf: bytearray) -> EncodeStatus:
        """Pack SI `values` (signal order; E2E entries ignored) into `buf`, E2E-protect it.

        The alive counter lives in `buf` itself, so one buffer per message and sender must
        be reused for the whole session (as the AUTOSAR library expects).
        """
        if len(buf) < self.dlc:
            raise ValueError(f"{self.name}: buffer of {len(buf)} bytes, the frame needs {self.dlc}")
        if isinstance(values, np.ndarray):
            values = values.tolist()   # Python floats: NumPy scalar arithmetic is 3x slower here
        word = 0
        saturated = False
        for i, start, mask, to_si, scale, offset, raw_min, raw_max in self._enc:
            x = values[i]
            if not math.isfinite(x):
                return EncodeStatus.REJECTED
            raw = round((x / to_si - offset) / scale)
            if raw < raw_min:
                raw, saturated = raw_min, True
            elif raw > raw_max:
                raw, saturated = raw_max, True
            word |= (raw & mask) << start
        if self.e2e:
            word |= (buf[1] & 0x0F) << 8     # keep the alive counter; protect() advances it
        buf[0:self.dlc] = word.to_bytes(self.dlc, "little")
        if self.e2e:
            e2e.protect(buf, self.data_id, self.dlc)
        return EncodeStatus.SATURATED if saturated else EncodeStatus.OK

    def quantize_into(self, values, out) -> bool:
        """What a receiver decodes from a frame of SI `values` (signal order), without the
        bytes: each value rounded to its signal's step and saturated at its range, as
        `decode_into(encode_into(values))` gives (the E2E entries of `out` left as they are).
        False, `out` unchanged, when a value is not finite (no such frame is sent)."""
        if not isinstance(values, np.ndarray):
            values = np.asarray(values, dtype=float)
        return quantize_kernel(self._quantize, values, out)

    def decode_into(self, data, out) -> None:
        """Unpack `data` (exactly `dlc` bytes) into `out` in SI units, signal order."""
        self._unpack(data, out, self._dec_si)

    def decode_dbc_units_into(self, data, out) -> None:
        """Same as `decode_into` but in the DBC's units: equals cantools' decode."""
        self._unpack(data, out, self._dec_dbc)

    @staticmethod
    def _unpack(data, out, fields) -> None:
        word = int.from_bytes(data, "little")
        i = 0
        for start, mask, sign_bit, scale, offset, to_unit in fields:
            raw = (word >> start) & mask
            if raw & sign_bit:
                raw -= sign_bit << 1
            out[i] = (raw * scale + offset) * to_unit
            i += 1


def _compile_all() -> dict[str, MessageCodec]:
    db = load_database()
    return {s.name: MessageCodec(db.get_message_by_name(s.name), s) for s in schedules()}


#: Every message of the DBC, compiled once at import, keyed by name, in CAN-id order.
CODECS: dict[str, MessageCodec] = _compile_all()


class FrameDecoder:
    """Receive side of one node: dispatch by id, E2E-check, decode into preallocated arrays.

    Only frames classified OK overwrite `values[name]`; every outcome is counted in
    `counts[message, status]`. `begin_cycle` / `end_cycle(expected)` turn a SYNC window
    into NO_NEW_DATA for the frames that were due and did not arrive.

    After WRONG_SEQUENCE the receiver re-synchronises to the new counter (the offending
    frame is rejected, the next consecutive one is OK): a lost burst costs one frame,
    not a latch-up. Gaps up to `max_delta_counter` are OK and counted in `lost`.
    """

    def __init__(self, names: Iterable[str] | None = None, *,
                 max_delta_counter: int = e2e.DEFAULT_MAX_DELTA_COUNTER):
        if not 1 <= max_delta_counter < e2e.COUNTER_MODULO:
            raise ValueError(f"max_delta_counter must be in 1..{e2e.COUNTER_MODULO - 1}, got {max_delta_counter}")
        names = list(CODECS) if names is None else list(names)
        unknown = [n for n in names if n not in CODECS]
        if unknown:
            raise ValueError(f"not in the DBC: {', '.join(unknown)}")
        self.codecs: tuple[MessageCodec, ...] = tuple(CODECS[n] for n in names)
        self.names: tuple[str, ...] = tuple(names)
        self.slot: dict[str, int] = {n: i for i, n in enumerate(names)}
        self._slot_by_id: dict[int, int] = {c.frame_id: i for i, c in enumerate(self.codecs)}
        self.values: dict[str, np.ndarray] = {c.name: c.new_values() for c in self.codecs}
        self._values_by_slot: tuple[np.ndarray, ...] = tuple(self.values[n] for n in names)
        n = len(self.codecs)
        self.max_delta_counter = max_delta_counter
        self.counts = np.zeros((n, len(RxStatus)), dtype=np.int64)
        self.lost = np.zeros(n, dtype=np.int64)
        self.last_status = np.full(n, RxStatus.NO_NEW_DATA, dtype=np.int8)
        self.fresh = np.zeros(n, dtype=bool)
        self.unknown_frames = 0
        self._last_counter = [-1] * n
        self._missing = np.zeros(n, dtype=bool)
        # autosar-e2e checks only writable buffers; immutable input (bytes from a log) is
        # copied into one of these, one per length so decoding sees exactly dlc bytes.
        self._scratch = tuple(bytearray(length) for length in range(9))
        self._no_new_data = np.int8(RxStatus.NO_NEW_DATA)

    def can_filters(self) -> list[dict]:
        """python-can acceptance filters for exactly this decoder's messages (standard ids, as
        the protocol's): `bus.set_filters` keeps every other frame out of the node."""
        return [{"can_id": c.frame_id, "can_mask": STANDARD_ID_MASK, "extended": False} for c in self.codecs]

    def expected_mask(self, names: Iterable[str]) -> np.ndarray:
        """A boolean mask over this decoder's messages, for `end_cycle`."""
        mask = np.zeros(len(self.codecs), dtype=bool)
        for name in names:
            mask[self.slot[name]] = True
        return mask

    def receive(self, frame_id: int, data) -> RxStatus:
        slot = self._slot_by_id.get(frame_id)
        if slot is None:
            self.unknown_frames += 1
            return RxStatus.UNKNOWN_ID
        codec = self.codecs[slot]
        if len(data) != codec.dlc:
            status = RxStatus.BAD_LENGTH
        elif codec.e2e:
            if type(data) is not bytearray:
                self._scratch[codec.dlc][:] = data
                data = self._scratch[codec.dlc]
            if not e2e.crc_ok(data, codec.data_id, codec.dlc):
                status = RxStatus.CRC_ERROR
            else:
                counter = data[1] & 0x0F
                last = self._last_counter[slot]
                status = e2e.classify_counter(counter, last, self.max_delta_counter)
                if status is RxStatus.OK:
                    if last >= 0:
                        self.lost[slot] += (counter - last) % e2e.COUNTER_MODULO - 1
                    self._last_counter[slot] = counter
                elif status is RxStatus.WRONG_SEQUENCE and counter < e2e.COUNTER_MODULO:
                    self._last_counter[slot] = counter
        else:
            status = RxStatus.OK
        if status is RxStatus.OK:
            codec.decode_into(data, self._values_by_slot[slot])
            self.fresh[slot] = True
        self.counts[slot, status] += 1
        self.last_status[slot] = status
        return status

    def restart_sender(self, sender: str) -> None:
        """A node restarted (a new process, a power cycle): its alive counters start afresh,
        so the next frame of each of its messages is taken as the first, not as out of
        sequence. The NMT master restarting shows as an NMT start on the bus."""
        for slot, codec in enumerate(self.codecs):
            if codec.schedule.sender == sender:
                self._last_counter[slot] = -1

    def receive_message(self, msg) -> RxStatus:
        """`receive` for a `can.Message`; extended, remote, error and FD frames are not ours."""
        if msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame or msg.is_fd:
            self.unknown_frames += 1
            return RxStatus.UNKNOWN_ID
        return self.receive(msg.arbitration_id, msg.data)

    def begin_cycle(self) -> None:
        self.fresh.fill(False)

    def end_cycle(self, expected: np.ndarray) -> int:
        """Mark expected-but-missing frames NO_NEW_DATA; return how many were missing."""
        np.logical_not(self.fresh, out=self._missing)
        np.logical_and(self._missing, expected, out=self._missing)
        missing = int(np.count_nonzero(self._missing))
        if missing:
            np.add(self.counts[:, RxStatus.NO_NEW_DATA], self._missing, out=self.counts[:, RxStatus.NO_NEW_DATA])
            np.copyto(self.last_status, self._no_new_data, where=self._missing)
        return missing
