"""sha-stick-slip: thesis 6.2 (Figs. 6.1-6.2), the limit cycles friction produces.

The PI drives the test bench up slow constant-velocity ramps, each from rest at START_M,
at several speeds and loads. Where the seals' friction falls with speed (the Stribeck
region, below ~vs = 10 mm/s here) it sticks and slips: the tracking error on the emulator's
ground truth (EMU_TRUTH) saws at a period of its own. The analysis (log only) measures each
ramp's cycle (`hil.design.stick_slip.limit_cycle`: the error's 5-95 % spread, its dominant
period) and sets it beside the LuGre model's prediction for the same ramp
(`hil.design.stick_slip.predict`: the linearised actuator loaded by the LuGre seals and
guide under the same PI).

Deviation: the thesis shows its limit cycle under force control (a 10 N, 0.04 Hz force
sine); here the classic drive of the friction literature it cites (Olsson and Astrom),
slow ramps under position PI, where the cycle's amplitude and period can be predicted.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from firmware_py.config import load_config as load_controller_config
from hil.design import stick_slip
from hil.logdata import LogData
from hil.plotting import colour_for_load, plt, save
from hil.reference_rebuild import rebuild
from hil.scenario import Analysis, Check, Figure, Scenario
from hil.scenarios.common import each_controller_and_load, load_at, move_stroke, run_emulator_config
from physics.constants import MM
from protocol.enums import WaypointFlag

THESIS = {"figure": "Figs. 6.1-6.2", "what": "a burst of oscillation at low velocity that grows to a "
          "given amplitude and frequency (force control, 10 N at 0.04 Hz; piston force and position "
          "oscillate)", "cause": "friction at zero velocity above that at a small velocity (6.2)"}
START_M = 0.060
RAMP_ACCEL_S = 0.05
RAMP_MAX_M_S = 0.030                # motions up to this speed are the ramps (the moves between: 100 mm/s)
TOLERANCE = 0.20                    # the cycle's spread and period against the model's
PLOT_S = 1.0                        # of each cycling ramp, after the settling


class ShaStickSlip(Scenario):
    name = "sha-stick-slip"
    title = "stick-slip: PI ramps at constant velocity, the limit cycle beside the LuGre model's"
    chapter = "6.2 (Figs. 6.1-6.2)"
    controllers = ("pi",)
    pacings = ("lockstep",)
    sweeps_loads = True

    def plan(self, short: bool):
        """(speeds m/s, loads kg, each ramp's duration s)."""
        if short:
            return (0.008, 0.020), (6.0,), 3.0
        return (0.002, 0.005, 0.008, 0.012, 0.020), (0.0, 3.0, 6.0), 5.0

    def script(self, run) -> None:
        speeds, loads, ramp_s = self.plan(run.short)
        here = 0.150
        for _ in each_controller_and_load(run, loads):
            for speed in speeds:
                move_stroke(run, START_M, settle_s=1.0, from_m=here)
                here = START_M + speed * (ramp_s - RAMP_ACCEL_S)
                run.host.waypoint((0.0, 0.0, here), segment_time_s=ramp_s, accel_time_s=RAMP_ACCEL_S,
                                  flags=WaypointFlag.LAST | WaypointFlag.START)
                run.wait_s(ramp_s + 0.3)

    # -- analysis ---------------------------------------------------------------------------
    def ramps(self, log: LogData, period: float) -> list[dict]:
        ref = rebuild(log, "testbench", period)
        truth = log.get("EMU_TRUTH").per_cycle(log.n_cycles, "Z")
        force = log.get("LEG_STATE_1").per_cycle(log.n_cycles, "FORCE")
        settle, blend = int(round(stick_slip.SETTLE_S / period)), int(round(RAMP_ACCEL_S / period)) + 1
        rows = []
        for motion in ref.motions:
            if motion.step:
                continue
            k0, k1 = motion.start, motion.end_cycle
            if k1 - blend - (k0 + settle) < int(1.0 / period):
                continue
            window = slice(k0 + settle, k1 - blend)
            speed = float(np.median(np.diff(ref.yr[window, 0]))) / period
            if not 0.0 < speed <= RAMP_MAX_M_S:
                continue
            error = ref.yr[k0:k1 - blend, 0] - truth[k0:k1 - blend]
            rows.append({"cycle": k0, "load_kg": load_at(log, k0), "speed_mm_s": round(speed / MM, 2),
                         "position_mm": float(np.mean(ref.yr[window, 0])) / MM,
                         "seconds": (k1 - blend - k0) * period,
                         **stick_slip.limit_cycle(error[settle:], period),
                         "_error": error, "_force": force[k0:k1 - blend]})
        return rows

    def analyze(self, log: LogData, out: Path | None, rate_hz: float = 500.0) -> Analysis:
        period = 1.0 / rate_hz
        rows = self.ramps(log, period)
        ecfg, ccfg = run_emulator_config(log), load_controller_config(None)
        for r in rows:
            model = stick_slip.predict(ecfg, ccfg, r["speed_mm_s"] * MM, r["load_kg"] or 0.0, r["position_mm"] * MM,
                                       r["seconds"], period)
            r["model"] = {k: model[k] for k in ("spread_m", "period_s", "cycling")}
            r["_model_error"] = model["error_m"]
        checks = self._checks(rows)
        figures = [self._plot(rows, out, period)] if out is not None and any(r["cycling"] for r in rows) else []
        metrics = {"ramps": [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows]}
        return Analysis(metrics, THESIS, checks, figures, [self._table(rows)])

    @staticmethod
    def _checks(rows: list[dict]) -> list[Check]:
        checks = [Check("ramps found in the log", bool(rows), str(len(rows)), ">= 1")]
        if not rows:
            return checks
        cycling = [r for r in rows if r["cycling"]]
        agree = [r for r in rows if r["cycling"] == r["model"]["cycling"]]
        speeds = ", ".join(f"{v:g}" for v in sorted({r["speed_mm_s"] for r in cycling})) or "none"
        checks.append(Check("a limit cycle where the LuGre model predicts one, none elsewhere", len(agree) == len(rows),
                            f"{len(agree)} of {len(rows)} ramps (cycling at {speeds} mm/s)", "every ramp"))
        checks.append(Check("the seals stick and slip somewhere in the Stribeck region", bool(cycling),
                            f"{len(cycling)} ramps", ">= 1 (thesis 6.2)"))
        both = [r for r in cycling if r["model"]["cycling"]]
        for key, what in (("spread_m", "spread (5-95 %)"), ("period_s", "period")):
            ratios = [r[key] / r["model"][key] for r in both]
            checks.append(Check(f"the cycle's {what} / the model's", bool(ratios) and all(
                abs(x - 1.0) <= TOLERANCE for x in ratios), f"{min(ratios):.2f}-{max(ratios):.2f}" if ratios else "-",
                f"1 +/- {TOLERANCE:g}"))
        return checks

    @staticmethod
    def _table(rows: list[dict]) -> str:
        lines = ["| load kg | speed mm/s | spread mm (model) | period s (model) | cycling (model) |",
                 "|---|---|---|---|---|"]
        for r in rows:
            m = r["model"]
            period = f"{r['period_s']:.3f} ({m['period_s']:.3f})" if r["cycling"] or m["cycling"] else "-"
            yes = {True: "yes", False: "no"}
            lines.append(f"| {r['load_kg']} | {r['speed_mm_s']:g} | {r['spread_m'] / MM:.3f} "
                         f"({m['spread_m'] / MM:.3f}) | {period} | {yes[r['cycling']]} ({yes[m['cycling']]}) |")
        return "\n".join(lines)

    @staticmethod
    def _plot(rows: list[dict], out: Path, period: float) -> Figure:
        """A grid of loads x speeds: one second of each cycling ramp's error beside the model's,
        the rod's load cell on the right axis."""
        shown = [r for r in rows if r["cycling"]]
        loads = sorted({r["load_kg"] or 0.0 for r in shown})
        speeds = sorted({r["speed_mm_s"] for r in shown})
        fig, axes = plt.subplots(len(loads), len(speeds), figsize=(3.6 * len(speeds), 2.6 * len(loads)),
                                 squeeze=False, sharex=True)
        n, start = int(round(PLOT_S / period)), int(round(stick_slip.SETTLE_S / period))
        t = np.arange(n) * period
        for r in shown:
            ax = axes[loads.index(r["load_kg"] or 0.0), speeds.index(r["speed_mm_s"])]
            part = slice(start, start + n)
            colour = colour_for_load(r["load_kg"] or 0.0)
            ax.plot(t, r["_error"][part] / MM, color=colour, lw=1, label="HIL")
            ax.plot(t, r["_model_error"][part] / MM, "k--", lw=0.8, label="LuGre model")
            right = ax.twinx()
            right.plot(t, r["_force"][part], color="0.6", lw=0.5)
            right.tick_params(labelsize=6)
            ax.set_title(f"{r['speed_mm_s']:g} mm/s, {r['load_kg']:g} kg", fontsize=8)
        for ax in axes[-1]:
            ax.set_xlabel("t [s]")
        for ax in axes[:, 0]:
            ax.set_ylabel("y_r - y [mm]")
        axes[0, 0].legend(fontsize=7)
        path = out / "sha_stick_slip.png"
        save(fig, path)
        return Figure(path.name, "one second of each cycling ramp: the tracking error (emulator ground truth) "
                                 "beside the LuGre model's; grey, the rod's load cell (N, right axis)",
                      "thesis Figs. 6.1-6.2: the piston force and position fall into a limit cycle at low velocity")
