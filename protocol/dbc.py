"""Load `hydrapod.dbc` once and expose the schedule the protocol rules derive from it.

The DBC carries, besides frames and signals, custom attributes that make it the single
source of truth for timing and protection:
- `SyncPeriod` n > 0: the frame belongs to the SYNC cycle and is sent on every n-th SYNC,
  namely when (SYNC counter - 1) mod n == `SyncPhase`;
- `GenMsgCycleTime` > 0: sent on its own timer (ms), independent of SYNC (heartbeats);
- neither: sent on event;
- `E2EProfile` P01 with `E2EDataID`: AUTOSAR E2E profile 1 protection;
- network attribute `SyncCounterOverflow`: the SYNC counter runs 1..overflow.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import cantools

DBC_NAME = "hydrapod.dbc"
CONTROLLER_NODE = "CONTROLLER"


def dbc_path() -> Path:
    """Path of the packaged DBC (works for editable and regular installs)."""
    return Path(str(resources.files(__package__).joinpath(DBC_NAME)))


@functools.cache
def load_database() -> cantools.database.can.Database:
    """The packaged DBC, parsed once per process (strict: overlapping signals fail)."""
    return cantools.database.load_file(str(dbc_path()), database_format="dbc", strict=True)


def _attr(owner, name: str, default=None):
    attrs = owner.dbc.attributes if owner.dbc is not None else {}
    return attrs[name].value if name in attrs else default


@dataclass(frozen=True)
class Schedule:
    """When and how one message is sent, read from its DBC attributes."""

    name: str
    frame_id: int
    dlc: int
    sender: str
    sync_period: int      # 0 = not SYNC-driven
    sync_phase: int
    cycle_time_ms: int    # 0 = not timer-driven
    e2e_data_id: int | None

    @property
    def kind(self) -> str:
        if self.sync_period == 1:
            return "cyclic"
        if self.sync_period > 1:
            return "every_nth_sync"
        if self.cycle_time_ms > 0:
            return "timer"
        return "event"

    def due(self, sync_counter: int) -> bool:
        """Whether a SYNC-driven frame is sent on the SYNC carrying `sync_counter` (1-based)."""
        return self.sync_period > 0 and (sync_counter - 1) % self.sync_period == self.sync_phase


TRUTH_PHASES = 16          # EMU_TRUTH's SYNC_PHASE: 4 bits


def truth_phase(sync_counter: int) -> int:
    """EMU_TRUTH's SYNC_PHASE for the SYNC with this counter: what ties a truth to its SYNC."""
    return sync_counter % TRUTH_PHASES


def sync_counter_overflow(db=None) -> int:
    db = db or load_database()
    return int(_attr(db, "SyncCounterOverflow", 240))


def schedule_of(message) -> Schedule:
    profile_attr = message.dbc.attributes.get("E2EProfile") if message.dbc else None
    protected = False
    if profile_attr is not None:
        choices = profile_attr.definition.choices
        value = profile_attr.value
        protected = (choices[value] if isinstance(value, int) else value) == "P01"
    return Schedule(
        name=message.name,
        frame_id=message.frame_id,
        dlc=message.length,
        sender=message.senders[0] if message.senders else "",
        sync_period=int(_attr(message, "SyncPeriod", 0)),
        sync_phase=int(_attr(message, "SyncPhase", 0)),
        cycle_time_ms=int(_attr(message, "GenMsgCycleTime", 0)),
        e2e_data_id=int(_attr(message, "E2EDataID")) if protected else None,
    )


@functools.cache
def schedules() -> tuple[Schedule, ...]:
    """Schedules of every message, sorted by CAN id (= arbitration priority)."""
    return tuple(schedule_of(m) for m in sorted(load_database().messages, key=lambda m: m.frame_id))


def signal_scale(message: str, signal: str) -> float:
    """A signal's resolution on the wire (its DBC scale), e.g. the load cell's 0.1 N."""
    return float(load_database().get_message_by_name(message).get_signal_by_name(signal).scale)
