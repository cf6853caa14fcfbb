"""A log of a run on stock CANopen devices (`--devices canopen`), read as the DBC's messages
its PDOs stand for, so every scenario's analysis reads both profiles alike: a leg's valve,
encoder and measuring-device TPDOs of a cycle as its LEG_STATE (and VALVE_STATUS,
LEG_PRESSURE), the IMU's as IMU_ATTITUDE and IMU_RATE, a valve's RPDO as its VALVE_CMD.

The PDOs are compiled as `hydrapod protocol configure` leaves the devices (the layout's
mapping, `firmware_py/runtime/configure.node_writes`), each object scaled as the profile
says (`protocol.canopen_profile`). No E2E: a PDO shorter than its mapping is counted
rejected, as the controller counts it.
"""

from __future__ import annotations

import numpy as np

from firmware_py.runtime.configure import node_writes
from protocol import canopen_profile as cp
from protocol.canopen_layout import load_layout
from protocol.codec import CODECS
from protocol.devices import object_dictionary
from protocol.enums import ImuStatus
from protocol.pdo import RPDO, TPDO, PdoCodec, pdo_maps

N_LEGS = 6                         # the layout's legs; a test bench's log has leg 1's frames only

# what each object of a leg's device stands for: (message prefix, signal, SI per count)
_LEG_SIGNALS = {
    cp.POSITION: (("LEG_STATE", "POSITION", cp.POSITION_STEP_M),),
    cp.LEG_FORCE: (("LEG_STATE", "FORCE", cp.FORCE_STEP_N),),
    cp.SPOOL_ACTUAL: (("LEG_STATE", "SPOOL", 1.0 / cp.SPOOL_FULL_SCALE),
                      ("VALVE_STATUS", "SPOOL_ACTUAL", 1.0 / cp.SPOOL_FULL_SCALE)),
    cp.STATUS_WORD: (("LEG_STATE", "VALVE_STATE", 0.0), ("VALVE_STATUS", "VALVE_STATE", 0.0)),   # 0: a state
    cp.LEG_PA: (("LEG_PRESSURE", "PA", cp.PRESSURE_STEP_PA),),
    cp.LEG_PB: (("LEG_PRESSURE", "PB", cp.PRESSURE_STEP_PA),),
    cp.LEG_PS: (("LEG_PRESSURE", "PS", cp.PRESSURE_STEP_PA),),
    cp.CONTROL_WORD: (("VALVE_CMD", "CONTROL_WORD", 0.0),),
    cp.SPOOL_SETPOINT: (("VALVE_CMD", "SPOOL_SETPOINT", 1.0 / cp.SPOOL_FULL_SCALE),),
}
_IMU_SIGNALS = {**{e: (("IMU_ATTITUDE", axis, cp.ANGLE_STEP_RAD),) for e, axis in
                   zip(cp.IMU_ATTITUDE, ("ROLL", "PITCH", "YAW"))},
                **{e: (("IMU_RATE", axis, cp.RATE_STEP_RAD_S),) for e, axis in
                   zip(cp.IMU_RATE, ("RATE_X", "RATE_Y", "RATE_Z"))}}
_CONTROL_BITS = ("CW_D", "CW_H", "CW_M", "CW_R")


class _Pdo:
    """A PDO's codec and, per mapped object, the DBC messages and signals it stands for
    (resolved once: `messages` are the ones every frame of it writes into)."""

    def __init__(self, codec: PdoCodec, leg: int | None):
        self.codec = codec
        table = _IMU_SIGNALS if leg is None else _LEG_SIGNALS
        self.targets = []                      # (object's slot, message, signal, its index, SI per count)
        for k, entry in enumerate(codec.pdo.entries()):
            for prefix, signal, step in table.get(entry, ()):
                name = prefix if leg is None else f"{prefix}_{leg}"
                index = CODECS[name].index
                slot = [index[b] for b in _CONTROL_BITS] if signal == "CONTROL_WORD" else index[signal]
                self.targets.append((k, name, signal, slot, step))
        self.messages = list(dict.fromkeys(name for _, name, _, _, _ in self.targets))
        self.values = np.zeros(len(codec.pdo.entries()))


class PdoReader:
    """Each PDO frame of the layout's devices decoded into the DBC messages it stands for
    (`read`); per PDO name and status the frames taken (`counts`). The log's reader and the
    monitor's live view both read through it."""

    def __init__(self, values_of):
        """`values_of(name)`: the values array of DBC message `name` to write into."""
        self.values_of = values_of
        self.pdos: dict[int, _Pdo] = {}
        self.tpdo_ids: set[int] = set()                     # the devices' own: answers to a SYNC
        for device in load_layout(N_LEGS):
            written = {(w.index, w.subindex): w.value for w in node_writes(device)}
            od = object_dictionary(device.eds, device.node)
            for kind in (TPDO, RPDO):
                for pdo in pdo_maps(od, kind, device.name, written):
                    self.pdos[pdo.cob_id] = _Pdo(PdoCodec(pdo), device.leg)
                    if kind == TPDO:
                        self.tpdo_ids.add(pdo.cob_id)
        self.counts: dict[str, dict[str, int]] = {}         # PDO name -> status -> frames

    @property
    def ids(self) -> set[int]:
        return set(self.pdos)

    def read(self, frame_id: int, data: bytes) -> list[str] | None:
        """The DBC messages frame `frame_id` wrote into, or None: shorter than its mapping."""
        pdo = self.pdos[frame_id]
        counts = self.counts.setdefault(pdo.codec.name, {})
        if not pdo.codec.decode_into(data, pdo.values):
            counts["BAD_LENGTH"] = counts.get("BAD_LENGTH", 0) + 1
            return None
        counts["OK"] = counts.get("OK", 0) + 1
        for k, name, signal, slot, step in pdo.targets:
            values, raw = self.values_of(name), pdo.values[k]
            if signal == "VALVE_STATE":
                values[slot] = cp.valve_state(int(raw))
            elif signal == "CONTROL_WORD":
                for bit_slot, on in zip(slot, cp.control_bits(int(raw))):
                    values[bit_slot] = on
            else:
                values[slot] = raw * step
        return pdo.messages


def imu_valid(name: str, values: np.ndarray) -> None:
    """A stock inclinometer has no status signal: its IMU messages read VALID."""
    if name.startswith("IMU_"):
        values[CODECS[name].index["STATUS"]] = int(ImuStatus.VALID)


class CanopenLog:
    """Takes a log's PDO frames in cycle order (`take`), gives the DBC messages' rows (`rows`)."""

    def __init__(self):
        self.reader = PdoReader(self._values)
        self.latest: dict[str, np.ndarray] = {}            # message -> its values as last taken
        self._touched: dict[str, float] = {}                # message -> time of its latest PDO this cycle
        self._cycle = None
        self.rejected: dict[str, list[int]] = {}            # message -> cycles of short PDOs

    def take(self, frame_id: int, data: bytes, cycle: int, time_s: float, rows: dict) -> None:
        if cycle != self._cycle:
            self.flush(rows)
            self._cycle = cycle
        touched = self.reader.read(frame_id, data)
        if touched is None:
            self.rejected.setdefault(self.reader.pdos[frame_id].codec.name, []).append(cycle)
            return
        for name in touched:
            self._touched[name] = time_s

    def _values(self, name: str) -> np.ndarray:
        if name not in self.latest:
            self.latest[name] = CODECS[name].new_values()
            imu_valid(name, self.latest[name])
        return self.latest[name]

    def flush(self, rows: dict) -> None:
        """The cycle's messages (each one some PDO of this cycle touched) into `rows`."""
        for name, time_s in self._touched.items():
            rows[name].append((self._cycle, time_s, *self.latest[name]))
        self._touched.clear()
