"""The faults injected into the emulated rig (EMU_CTRL): which are active on which node,
with what parameter, for how long; and what a sensor fault took at its onset.

FAULT_PARAM is the fault's value for the kinds in VALUE_PARAM_FAULTS (until cleared) and
its duration in SYNCs for the others (0: until cleared). The kinds (the DBC's EMU_CTRL.FAULT
table) act in three places: the rig's physics (`simulated_rig.py`: VALVE_JAM, LEG_JAM,
SEAL_LEAK, SPOOL_STUCK, SUPPLY_LOSS, SUPPLY_DROP), what its sensors report
(`sensor_faults.py`: STUCK, ENCODER_DRIFT, FORCE_STUCK, FORCE_ZERO, OUT_OF_RANGE) and the
frames on the bus (`emulator.py`: SILENT, DROP, FRAME_LOSS, REPEAT, CORRUPT, DELAY, REORDER,
DUPLICATE, BABBLE).
"""

from __future__ import annotations

from protocol.enums import EmuFault

VALUE_PARAM_FAULTS = (EmuFault.BABBLE, EmuFault.OUT_OF_RANGE, EmuFault.ENCODER_DRIFT, EmuFault.SPOOL_STUCK,
                      EmuFault.SUPPLY_DROP, EmuFault.FRAME_LOSS, EmuFault.SEAL_LEAK)
KNOWN_FAULTS = frozenset(int(kind) for kind in EmuFault if kind is not EmuFault.NONE)


class InjectedFaults:
    def __init__(self):
        self.active: dict[tuple[int, EmuFault], list] = {}    # (target, kind) -> [remaining SYNCs or -1, param]
        self.onset_values: dict[tuple[int, EmuFault], object] = {}   # what a sensor fault froze at its onset
        self.injected: dict[str, int] = {}                    # count per kind (the summary)

    def __bool__(self) -> bool:
        return bool(self.active)

    def get(self, target: int, kind: EmuFault):
        """The active fault `kind` on `target` as [remaining, param], or None."""
        return self.active.get((target, kind))

    def param(self, target: int, kind: EmuFault) -> int | None:
        entry = self.active.get((target, kind))
        return None if entry is None else entry[1]

    def inject(self, target: int, kind: EmuFault, param: int) -> None:
        lasts = param if param > 0 and kind not in VALUE_PARAM_FAULTS else -1
        self.active[(target, kind)] = [lasts, param]
        self.injected[kind.name] = self.injected.get(kind.name, 0) + 1

    def clear(self, target: int, kind) -> bool:
        """False when it was not active."""
        self.onset_values.pop((target, kind), None)
        return self.active.pop((target, kind), None) is not None

    def keys(self) -> list[tuple[int, EmuFault]]:
        return list(self.active)

    def count_down(self) -> list[tuple[int, EmuFault]]:
        """One SYNC of every timed fault; the ones that ended now (already removed)."""
        ended = []
        for key, entry in list(self.active.items()):
            if entry[0] > 0:
                entry[0] -= 1
                if entry[0] == 0:
                    self.clear(*key)
                    ended.append(key)
        return ended

    def of_kind(self, kind: EmuFault) -> list[int]:
        """The params of every active fault of `kind`."""
        return [entry[1] for (_, k), entry in self.active.items() if k == kind]
