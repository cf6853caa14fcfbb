"""sha-step: thesis 7.6.1, 10 mm steps at 50/150/250 mm with 0/3/6 kg, PI and adaptive."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from firmware_py.config import load_config
from hil.logdata import LogData
from hil.metrics import step_response
from hil.plotting import colour_for_load, plt, save
from hil.reference_rebuild import rebuild
from hil.scenario import Analysis, Check, Figure, Scenario
from hil.scenarios.common import (
    NEW_CONTROLLER,
    TESTBENCH_CONTROLLERS,
    controller_at,
    each_controller_and_load,
    load_at,
    move_stroke,
    step_stroke,
)
from physics.constants import MM
from program.errors import UserInputError

THESIS = {"step_mm": 10, "pi_overshoot_pct": 25, "pi_settling_s": 0.5, "adaptive_overshoot_pct_max": 14,
          "adaptive_settling_s": 1.0, "figure": "Fig. 7.16"}
# Asserted: the thesis's PI figures with the spread of its Fig. 7.16, and settling. Reported
# beside them, not asserted: the adaptive controller's < 14 % (measured 5-29 %: with Table
# 7.2's Kp and its Ki x ki_scale 0.2 the scheduled gains are within ~1.5x of the PI's, so the
# responses are alike; with 3-6 kg it overshoots about as much as the PI).
PI_OVERSHOOT_BAND_PCT = (12.0, 35.0)
PI_SETTLING_MAX_S = 0.8
ADAPTIVE_OVERSHOOT_MAX_PCT = 14.0
ADAPTIVE_SETTLING_MAX_S = 1.5
PRE_STEP_S = 0.1
STEP_M = THESIS["step_mm"] * MM
# `--positions`: the square wave's least distance from the end stops: the largest overshoot
# measured on its steps (2.9 mm of 10) and the controller's 1 mm stroke margin (Table A.3's
# set points, 10-290 mm, are in range)
END_CLEARANCE_M = 4.0 * MM
# Beyond the thesis: the computed-torque controller on the same steps, held to the thesis's
# adaptive claim (< 14 %, settling <= 1 s) on every step
NEW_SETTLING_MAX_S = 1.0


class ShaStep(Scenario):
    name = "sha-step"
    title = "step response of the servo-hydraulic actuator, PI, adaptive and computed torque"
    chapter = "7.6.1 (Fig. 7.16)"
    sweeps_loads = True
    controllers = TESTBENCH_CONTROLLERS

    def plan(self, short: bool):
        positions_m = tuple(p * MM for p in ((50.0, 250.0) if short else (50.0, 150.0, 250.0)))
        loads = (0.0, 6.0) if short else (0.0, 3.0, 6.0)
        return positions_m, loads, (1.2 if short else 2.0)

    def check_positions(self, positions_m: tuple[float, ...]) -> None:
        """Each square wave stays END_CLEARANCE_M away from the bench cylinder's end stops."""
        stroke_m = load_config().actuator.stroke_m
        lo, hi = END_CLEARANCE_M, stroke_m - STEP_M - END_CLEARANCE_M
        for position_m in positions_m:
            if not lo <= position_m <= hi:
                raise UserInputError(f"--positions: {position_m / MM:g} mm is outside {lo / MM:g}..{hi / MM:g} mm "
                                     f"(a {STEP_M / MM:g} mm step on a {stroke_m / MM:g} mm stroke)")

    def script(self, run) -> None:
        # At each working position: move there, then a 10 mm square wave up, down, up. Only the
        # last up-step is measured: it alone starts from the same state everywhere.
        planned_m, loads, hold_s = self.plan(run.short)
        here_m = 0.150
        for _ in each_controller_and_load(run, loads):
            for position_m in run.options.positions_m or planned_m:
                move_stroke(run, position_m, settle_s=1.0, from_m=here_m)
                for target_m in (position_m + STEP_M, position_m, position_m + STEP_M):
                    step_stroke(run, target_m, hold_s)
                here_m = position_m + STEP_M

    def analyze(self, log: LogData, out: Path | None, rate_hz: float = 500.0) -> Analysis:
        period = 1.0 / rate_hz
        ref = rebuild(log, "testbench", period)
        y = log.leg_positions(1)[:, 0]
        rows = []
        previous = None                  # the step before this one, if it came straight before
        for motion in ref.motions:
            if not motion.step:
                previous = None
                continue
            k0 = motion.start
            before = ref.yr[k0 - 1, 0] if k0 > 0 else np.nan
            target = motion.trajectory.segments[0, 0, 0]
            window = slice(k0, motion.end_cycle + 1)
            pre = y[max(k0 - int(PRE_STEP_S / period), 0):k0]
            y0 = float(np.nanmean(pre))
            step = target - before
            t = (np.arange(window.start, window.stop) - k0) * period
            m = step_response(t, y[window], y0, step)
            # measured: an up-step straight after a down-step of the same size (see script())
            measured = bool(step > 0 and previous is not None and abs(previous + step) < 1e-6)
            previous = step
            rows.append({"controller": controller_at(log, k0), "load_kg": load_at(log, k0),
                         "position_mm": round(before * 1e3, 1), "step_mm": round(step * 1e3, 2),
                         "measured": measured,
                         "bias_mm": round((y0 - before) * 1e3, 3), **{k: round(v, 4) for k, v in m.items()},
                         "_t": t, "_y": (y[window] - y0) * 1e3})
        checks = []
        summary = {}
        for controller in TESTBENCH_CONTROLLERS:
            mine = [r for r in rows if r["controller"] == controller and r["measured"]]
            if not mine:
                continue
            os_ = np.array([r["overshoot_pct"] for r in mine])
            ts = np.array([r["settling_s"] for r in mine])
            ts = np.where(np.isnan(ts), np.inf, ts)          # never settled inside the window
            summary[controller] = {"steps": len(mine), "overshoot_pct_mean": float(os_.mean()),
                                   "overshoot_pct_min": float(os_.min()), "overshoot_pct_max": float(os_.max()),
                                   "settling_s_median": float(np.median(ts)), "settling_s_max": float(np.max(ts))}
        if "pi" in summary:
            s = summary["pi"]
            lo, hi = PI_OVERSHOOT_BAND_PCT
            checks.append(Check("PI overshoot (mean over the steps)", lo <= s["overshoot_pct_mean"] <= hi,
                                f"{s['overshoot_pct_mean']:.1f} % (range {s['overshoot_pct_min']:.1f}-"
                                f"{s['overshoot_pct_max']:.1f})",
                                f"thesis ~{THESIS['pi_overshoot_pct']} %; band {lo:g}-{hi:g} %"))
            checks.append(Check("PI settling (5 %), median step", s["settling_s_median"] <= PI_SETTLING_MAX_S,
                                f"{s['settling_s_median']:.2f} s (max {s['settling_s_max']:.2f})",
                                f"thesis ~{THESIS['pi_settling_s']} s; <= {PI_SETTLING_MAX_S} s"))
            checks.append(Check("PI settling (5 %), every step", s["settling_s_max"] <= PI_SETTLING_MAX_S,
                                f"max {s['settling_s_max']:.2f} s", f"<= {PI_SETTLING_MAX_S} s", required=False))
            checks.append(Check("PI overshoot similar at every set point", s["overshoot_pct_max"] <= hi,
                                f"max {s['overshoot_pct_max']:.1f} %", f"thesis: ~25 % at every set point, <= {hi:g} %",
                                required=False))
        if "adaptive" in summary:
            s = summary["adaptive"]
            checks.append(Check("adaptive settling (5 %), median step",
                                s["settling_s_median"] <= ADAPTIVE_SETTLING_MAX_S,
                                f"{s['settling_s_median']:.2f} s (max {s['settling_s_max']:.2f})",
                                f"thesis ~{THESIS['adaptive_settling_s']} s; <= {ADAPTIVE_SETTLING_MAX_S} s"))
            checks.append(Check("adaptive overshoot, every step", s["overshoot_pct_max"] < ADAPTIVE_OVERSHOOT_MAX_PCT,
                                f"max {s['overshoot_pct_max']:.1f} % (mean {s['overshoot_pct_mean']:.1f})",
                                f"thesis < {THESIS['adaptive_overshoot_pct_max']} %", required=False))
        if NEW_CONTROLLER in summary:
            s = summary[NEW_CONTROLLER]
            checks.append(Check(f"{NEW_CONTROLLER}: overshoot, every step",
                                s["overshoot_pct_max"] < ADAPTIVE_OVERSHOOT_MAX_PCT,
                                f"max {s['overshoot_pct_max']:.1f} % (mean {s['overshoot_pct_mean']:.1f})",
                                f"< {ADAPTIVE_OVERSHOOT_MAX_PCT:g} % (the thesis's adaptive claim)"))
            checks.append(Check(f"{NEW_CONTROLLER}: settling (5 %), every step",
                                s["settling_s_max"] <= NEW_SETTLING_MAX_S,
                                f"max {s['settling_s_max']:.2f} s (median {s['settling_s_median']:.2f})",
                                f"<= {NEW_SETTLING_MAX_S:g} s (the thesis's adaptive claim)"))
        if "pi" in summary and "adaptive" in summary:
            checks.append(Check("adaptive overshoots less than PI (mean)",
                                summary["adaptive"]["overshoot_pct_mean"] < summary["pi"]["overshoot_pct_mean"],
                                f"{summary['adaptive']['overshoot_pct_mean']:.1f} vs "
                                f"{summary['pi']['overshoot_pct_mean']:.1f} %",
                                "thesis: adaptive < PI", required=False))
        if not rows:
            checks.append(Check("steps found in the log", False, "0", ">= 1"))
        elif not summary:
            checks.append(Check("measured steps (up after down) in the log", False, "0", ">= 1"))
        figures = []
        if out is not None and rows:
            figures.append(self._plot(rows, out))
        table = ["| controller | load kg | from mm | step mm | measured | overshoot % | settling s | rise s |",
                 "|---|---|---|---|---|---|---|---|"]
        table += [f"| {r['controller']} | {r['load_kg']} | {r['position_mm']} | {r['step_mm']:+g} | "
                  f"{'yes' if r['measured'] else 'no'} | {r['overshoot_pct']:.1f} | {r['settling_s']:.3f} | "
                  f"{r['rise_s']:.3f} |" for r in rows]
        metrics = {"steps": [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows],
                   "summary": summary}
        return Analysis(metrics, THESIS, checks, figures, ["\n".join(table)])

    def _plot(self, rows, out: Path) -> Figure:
        controllers = [c for c in TESTBENCH_CONTROLLERS if any(r["controller"] == c for r in rows)]
        fig, axes = plt.subplots(1, len(controllers), figsize=(5.5 * len(controllers), 4), squeeze=False)
        for ax, controller in zip(axes[0], controllers):
            for r in rows:
                if r["controller"] == controller and r["measured"]:
                    ax.plot(r["_t"], r["_y"], color=colour_for_load(r["load_kg"] or 0.0), lw=1,
                            label=f"{r['load_kg']} kg @ {r['position_mm']:.0f} mm")
            ax.axhline(THESIS["step_mm"], color="k", lw=0.5, ls="--")
            ax.set_title(f"{controller}: 10 mm steps")
            ax.set_xlabel("t [s]")
            ax.set_ylabel("y - y0 [mm]")
            ax.legend(fontsize=6)
            ax.grid(alpha=0.3)
        path = out / "sha_step.png"
        save(fig, path)
        return Figure(path.name, "Step responses (bias removed, synchronised with the step)",
                      "thesis Fig. 7.16: (a) PI, ~25 % overshoot, settles ~0.5 s; (b) adaptive, < 14 %, ~1 s; "
                      "computed torque: beyond the thesis")
