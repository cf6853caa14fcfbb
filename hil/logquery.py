"""Queries on a decoded log, in the log's own times and cycles: when the controller faulted
and how it reacted (its VALVE_CMD bits), what the emulator's ground truth (EMU_TRUTH) did,
which frames came or were rejected. The fault matrix and the soak judge from these."""

from __future__ import annotations

import numpy as np

from hil.logdata import LogData
from protocol.enums import AckKind, Command, Fault, State


class LogView:
    """A log read for reaction times and excursions (times are the log's)."""

    def __init__(self, log: LogData, period_s: float, n_legs: int):
        self.log, self.period_s, self.n_legs = log, period_s, n_legs
        self.sync_t = log.sync_time_s
        truth = log.get("EMU_TRUTH")
        self.truth_t = truth.time_s
        self.truth_cycle = truth.cycle
        self.truth = np.column_stack([truth["X"], truth["Y"], truth["Z"]]) if n_legs == 6 else truth["Z"][:, None]
        self.status = log.get("CTRL_STATUS")
        self.cmds = [log.get(f"VALVE_CMD_{leg}") for leg in range(1, n_legs + 1)]
        self.legs = log.leg_positions(n_legs)          # (cycles, legs), NaN where a frame is missing

    def cycle_at(self, t: float) -> int | None:
        """The first cycle whose SYNC is at or after `t`."""
        valid = np.isfinite(self.sync_t)
        k = np.flatnonzero(valid & (self.sync_t >= t))
        return int(k[0]) if len(k) else None

    def cycle_of_sync(self, counter: int, t: float) -> int | None:
        """The cycle of the SYNC with this counter nearest to time `t` (counters wrap)."""
        sync = self.log.get("SYNC")
        k = np.flatnonzero(sync["COUNTER"] == counter)
        return int(sync.cycle[k[np.argmin(np.abs(sync.time_s[k] - t))]]) if len(k) else None

    def faults_between(self, t0: float, t1: float) -> list[str]:
        s = self.status
        ok = (s.time_s >= t0) & (s.time_s <= t1) & (s["FAULT_CODE"] != 0)
        return sorted({Fault(int(c)).name for c in s["FAULT_CODE"][ok]})

    def states_between(self, t0: float, t1: float) -> list[str]:
        s = self.status
        ok = (s.time_s >= t0) & (s.time_s <= t1)
        return sorted({State(int(c)).name for c in s["STATE"][ok]})

    def fault_code_after(self, k0: int | None) -> str | None:
        if k0 is None:
            return None
        s = self.status
        idx = np.flatnonzero((s.cycle >= k0) & (s["FAULT_CODE"] != 0))
        return Fault(int(s["FAULT_CODE"][idx[0]])).name if len(idx) else None

    def reaction_cycle(self, k0: int | None, bit: str) -> int | None:
        """The first cycle >= k0 in which the controller wrote `bit` = 0 to a valve."""
        if k0 is None:
            return None
        first = [c.cycle[np.flatnonzero((c.cycle >= k0) & (c[bit] == 0))] for c in self.cmds]
        first = [int(f[0]) for f in first if len(f)]
        return min(first) if first else None

    def all_held_cycle(self, k0: int | None) -> int | None:
        """The first cycle >= k0 in which every leg's VALVE_CMD had M = 0 (after a controlled
        stop, its end)."""
        if k0 is None:
            return None
        for k in range(k0, self.log.n_cycles):
            if all(np.all(c["CW_M"][c.cycle == k] == 0) and np.any(c.cycle == k) for c in self.cmds):
                return k
        return None

    def controller_fault_leg(self, t0: float, t1: float) -> int:
        """The leg the controller's first EMCY with an error code in [t0, t1] named (INFO), 0: none."""
        for e in self.log.events_named("EMCY_16"):
            if t0 <= e.time_s <= t1 and e.values["ERROR_CODE"] != 0:
                return int(e.values["INFO"])
        return 0

    def held_after(self, k: int | None, until: float | None = None) -> bool:
        """From cycle k on, every cycle has every leg's VALVE_CMD with M = 0 (until a RESET
        or `until`): the controller held and never resumed motion by itself."""
        if k is None:
            return False
        end = self.log.n_cycles if until is None else (self.cycle_at(until) or self.log.n_cycles)
        reset = self._first_command_cycle(Command.RESET, k)
        if reset is not None:
            end = min(end, reset)
        for c in self.cmds:
            sel = (c.cycle >= k) & (c.cycle < end)
            if np.any(c["CW_M"][sel] != 0) or len(np.unique(c.cycle[sel])) < (end - k) * 0.98:
                return False
        return True

    def _first_command_cycle(self, command: Command, k0: int) -> int | None:
        for e in self.log.events_named("HOST_CMD"):
            if e.cycle >= k0 and int(e.values["COMMAND"]) == command:
                return e.cycle
        return None

    def resumed_without_reset(self, t0: float, t1: float) -> bool:
        k0 = self.cycle_at(t0)
        if k0 is None:
            return False
        reset = self._first_command_cycle(Command.RESET, k0) or self.log.n_cycles
        fault = self.reaction_cycle(k0, "CW_M")
        if fault is None:
            return True
        return any(np.any((c.cycle > fault) & (c.cycle < reset) & (c["CW_M"] != 0)) for c in self.cmds)

    def ack_cycle(self, command: Command, t0: float) -> int | None:
        seqs = {int(e.values["SEQ"]) for e in self.log.events_named("HOST_CMD")
                if e.time_s >= t0 - 0.01 and int(e.values["COMMAND"]) == command}
        for e in self.log.events_named("CTRL_ACK"):
            if e.time_s >= t0 - 0.01 and int(e.values["KIND"]) == AckKind.HOST_CMD and int(e.values["SEQ"]) in seqs:
                return e.cycle
        return None

    def valve_state_from(self, k: int | None, state: int) -> int | None:
        """Cycles after k until every leg reports valve `state` in LEG_STATE."""
        if k is None:
            return None
        latest = 0
        for leg in range(1, self.n_legs + 1):
            s = self.log.get(f"LEG_STATE_{leg}")
            idx = np.flatnonzero((s.cycle >= k) & (s["VALVE_STATE"] == state))
            if not len(idx):
                return None
            latest = max(latest, int(s.cycle[idx[0]]) - k)
        return latest

    def last_valid_frame_cycle(self, leg: int, k: int) -> int | None:
        """The last cycle up to k in which leg's LEG_STATE was accepted."""
        s = self.log.get(f"LEG_STATE_{leg}")
        idx = np.flatnonzero(s.cycle <= k)
        return int(s.cycle[idx[-1]]) if len(idx) else None

    def rejected_between(self, leg: int, t0: float, t1: float) -> dict:
        k0, k1 = self.cycle_at(t0), self.cycle_at(t1) or self.log.n_cycles
        if k0 is None:
            return {"missing": 0, "rejected": 0}
        s = self.log.get(f"LEG_STATE_{leg}")
        present = np.unique(s.cycle[(s.cycle >= k0) & (s.cycle < k1)])
        rejected = self.log.rejected.get(f"LEG_STATE_{leg}", np.zeros(0, dtype=np.int64))
        return {"missing": int((k1 - k0) - len(present)),
                "rejected": int(np.count_nonzero((rejected >= k0) & (rejected < k1)))}

    def leg_range(self, k0: int | None, k1: int | None) -> float | None:
        """The largest range (max - min) of any leg's encoder over cycles [k0, k1)."""
        if k0 is None or k1 is None or k1 <= k0:
            return None
        window = self.legs[k0:k1]
        if not np.isfinite(window).any():
            return None
        return float(np.nanmax(np.nanmax(window, axis=0) - np.nanmin(window, axis=0)))

    def truth_range(self, t0: float, t1: float) -> float | None:
        """The size of the box the platform (or slide) stayed in between t0 and t1 (truth)."""
        sel = (self.truth_t >= t0) & (self.truth_t <= t1)
        if not sel.any():
            return None
        return float(np.linalg.norm(self.truth[sel].max(axis=0) - self.truth[sel].min(axis=0)))

    def truth_window(self, k0: int | None, span: float):
        """Truth per cycle from cycle k0 on, `span` seconds (NaN rows where it is missing);
        None when under 90 % of them came."""
        if k0 is None:
            return None
        n = int(round(span / self.period_s))
        rows = np.full((n, self.truth.shape[1]), np.nan)
        sel = (self.truth_cycle >= k0) & (self.truth_cycle < k0 + n)
        rows[self.truth_cycle[sel] - k0] = self.truth[sel]
        keep = np.all(np.isfinite(rows), axis=1)
        return rows if keep.mean() > 0.9 else None

    def swing_after(self, k0: int | None, settle_s: float, span_s: float) -> float | None:
        """What is left of the platform's (or slide's) motion `settle_s` after cycle k0: its
        largest distance from its mean position over the next `span_s` (truth); None without
        truth there."""
        window = None if k0 is None else self.truth_window(k0 + int(round(settle_s / self.period_s)), span_s)
        if window is None:
            return None
        window = window[np.all(np.isfinite(window), axis=1)]
        return float(np.max(np.linalg.norm(window - window.mean(axis=0), axis=1)))

    def excursion(self, t0: float, span: float) -> float | None:
        sel = (self.truth_t >= t0) & (self.truth_t <= t0 + span)
        before = np.flatnonzero(self.truth_t < t0)
        if not sel.any() or not len(before):
            return None
        start = self.truth[before[-1]]
        return float(np.max(np.linalg.norm(self.truth[sel] - start, axis=1)))

    def emergencies_after(self, t0: float, t1: float) -> list[tuple[int, float, int]]:
        """The legs' EMCYs with an error code in [t0, t1]: (leg, time, DETAIL); not the IMU's
        or the controller's own."""
        out = []
        for e in self.log.events:
            if e.name.startswith("EMCY_") and t0 <= e.time_s <= t1 and e.values["ERROR_CODE"] != 0:
                node = int(e.name.split("_")[1])
                if 1 <= node <= self.n_legs:
                    out.append((node, e.time_s, int(e.values["DETAIL"])))
        return out

    def last_sync_before(self, t: float) -> float | None:
        earlier = self.sync_t[np.isfinite(self.sync_t) & (self.sync_t <= t)]
        return float(earlier.max()) if len(earlier) else None

    def last_command_before(self, t: float) -> float | None:
        times = [c.time_s[c.time_s <= t] for c in self.cmds]
        times = [float(x[-1]) for x in times if len(x)]
        return max(times) if times else None

    def last_leg_state_cycle_before(self, t: float) -> int | None:
        last = None
        for leg in range(1, self.n_legs + 1):
            s = self.log.get(f"LEG_STATE_{leg}")
            c = s.cycle[s.time_s <= t]
            if len(c):
                last = max(last or 0, int(c[-1]))
        return last

    def period_error_us(self, t0: float, t1: float) -> dict:
        s = self.status
        sel = (s.time_s >= t0) & (s.time_s <= t1)
        values = s["PERIOD_ERROR_MAX"][sel] * 1e6
        if not len(values):
            return {}
        return {"p50": round(float(np.percentile(values, 50)), 1), "p99": round(float(np.percentile(values, 99)), 1),
                "max": round(float(values.max()), 1)}
