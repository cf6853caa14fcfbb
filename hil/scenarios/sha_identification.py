"""sha-identification: thesis 5.4.1 (experiment) and 5.2 (identification) on the recorded log.

The actuator runs under proportional position control (the `pi` controller with Ki = 0,
restarted for each gain) around set points with 0-6 kg. Around each set point the host
queues a pseudo-random multilevel reference (PRMS: levels of -10 ... +10 mm held 0.3-0.6 s,
step waypoints). The analysis (log only) takes the 150 ms after every level change and
identifies K, Gcl(s), G(s) = k01 b0 / (s (s^2 + b1 s + b0)) (eq. 5.5) and m, sigma, Fe
(eq. 5.7): `hil/identification.py`. For each set point and load it keeps the G(s) whose
closed loops fit every window of that point best (mean eq. 5.12), as the thesis does, and
compares it with the emulator's linearisation (`hil.design.calibration`) and Table A.3.
From that G(s) and the point's m, sigma: Kx, Kd, Kp (eq. 5.8-5.10) and the load's path of
eq. 5.11 (k02, z0), beside the linearisation and Table A.2; m, sigma, Fe as quadratics in
the position per load (chapter 5.2.3), beside Table A.1. Then, as chapter 5.2.4 does, Kx,
Kd, Kp refined to maximise eq. 5.12 of the complete model over the point's windows, each
window's load change the residual of eq. 5.6 (A PL - m y'' - sigma y', less its value at
rest before the change), and each window's fit beside G(s)'s alone.

Deviations: levels are held 0.3-0.6 s, not 1-6 s (only the first 150 ms are used); the
derivatives use a 50 Hz zero-phase filter, not 200 Hz (the loop samples at 500 Hz, not the
DS1103's rate); PL comes from LEG_PRESSURE sent every SYNC for this experiment.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from firmware_py.config import load_config as load_controller_config
from hil import identification as ident
from hil.design.calibration import LOADS_KG, linearise, moving_mass_kg, table_a3
from hil.design.thesis import thesis_data
from hil.logdata import LogData
from hil.plotting import colour_for_load, plt, save
from hil.reference_rebuild import rebuild
from hil.scenario import Analysis, Check, Figure, Scenario
from hil.scenarios.common import VALVE_FULL_SCALE_V, load_at, move_stroke, run_emulator_config
from physics.constants import MM
from protocol.enums import WaypointFlag

LEVELS_MM = (-10.0, -5.0, 0.0, 5.0, 10.0)
HOLD_S = (0.3, 0.6)
WINDOW_S = 0.15                     # chapter 5.4.1: 150 ms after each change
PRE_S = 0.02                        # rest before the change (y0, and anchors Fe)
MIN_STEP_MM = 3.0
END_MARGIN_MM = 10.0                # levels stay this far inside the stroke: a 15 mm step overshoots up to
                                    # ~6 mm, and the controller faults within 1 mm of an end
FILTER_HZ = 50.0
DELAY_PERIODS = 1                   # the command latency: VALVE_CMD k is applied at SYNC k+1 (2 tried: worse fits)
SEED = 5
# Asserted: the windows' models fit like the thesis's (eq. 5.12: 0.85-0.94), and eq. 5.7
# finds the emulator's moving mass. That the method recovers a linear plant exactly is
# tests/hil/test_identification.py's job; the emulator is not linear (below), so b0, b1, k01
# are compared with its linearisation and with Table A.3 and reported.
FIT_MIN = 0.85                      # the thesis's range is 0.85-0.94: the median window must be in it
FIT_FLOOR = 0.80                    # and no point's median below this (near the end stops, with 3 kg,
                                    # the steps are at most 10 mm and friction shows most: 0.84 there)
MASS_TOLERANCE = 0.20
# P-control steps of 20 mm ask up to ~1 m/s for a moment; the operator guard is 600 mm/s
OVERRIDES = {"limits": {"velocity_max_mm_s": 2500.0, "tracking_error_max_mm": 40.0}}
KPA = 1e3
TABLE_COLUMN = {0.0: 1, 3.0: 4, 6.0: 7}              # the tables' first column per load


def prms(rng: np.random.Generator, n: int, levels=LEVELS_MM) -> list[tuple[float, float]]:
    """n (level mm, hold s) pairs; consecutive levels 5-15 mm apart (a transient each, inside
    the 20 mm step guard)."""
    out, last = [], 0.0
    for _ in range(n):
        level = float(rng.choice([v for v in levels if 5.0 <= abs(v - last) <= 15.0]))
        out.append((level, 2e-3 * round(float(rng.uniform(*HOLD_S)) / 2e-3)))   # whole ms, ta = hold / 2 too
        last = level
    return out


class ShaIdentification(Scenario):
    name = "sha-identification"
    title = "closed-loop P-control PRMS experiment and identification of G(s), m, sigma, Fe"
    chapter = "5.4.1, 5.2 (Table A.3)"
    rig = "testbench"
    controllers = ("pi",)
    pacings = ("lockstep",)
    controller_overrides = OVERRIDES
    emulator_overrides = {"nodes": {"leg_pressure_divisor": 1}}
    thesis = {"pole_region": "Re in [-65, -45] 1/s, Im in [75, 125] 1/s",
              "fit_index": "0.85-0.94 (eq. 5.12)", "table": "A.3 (b0, b1, k01) and A.1 (m, sigma, Fe)"}

    def plan(self, short: bool):
        if short:
            return (60.0, 210.0), (0.0, 6.0), (0.25, 0.3), 10
        return (10.0, 30.0, 60.0, 90.0, 120.0, 150.0, 180.0, 210.0, 240.0, 270.0, 290.0), LOADS_KG, \
            (0.2, 0.25, 0.3), 12

    def script(self, run) -> None:
        positions, loads, gains, changes = self.plan(run.short)
        rng = np.random.default_rng(SEED)
        stroke_mm = load_controller_config(None).actuator.stroke_m / MM
        here = 0.150
        for gain in gains:
            run.stop_controller()
            run.start_controller("pi", {"pi": {"kp_v_mm": gain, "ki_v_mm_s": 0.0}})
            for load in loads:
                run.host.set_load(load)
                for position in positions:
                    move_stroke(run, position * MM, settle_s=0.5, from_m=here)
                    here = position * MM
                    total = 0.0
                    # the thesis's 10 and 290 mm points reach its end stops; ours stay END_MARGIN_MM inside
                    levels = [v for v in LEVELS_MM if END_MARGIN_MM <= position + v <= stroke_mm - END_MARGIN_MM]
                    for level, hold in prms(rng, changes, levels):
                        here = (position + level) * MM
                        run.host.waypoint((0.0, 0.0, here), segment_time_s=hold, accel_time_s=hold / 2,
                                          flags=WaypointFlag.LAST | WaypointFlag.START | WaypointFlag.STEP)
                        total += hold
                    run.wait_s(total + 0.3)

    # -- analysis ---------------------------------------------------------------------------
    def windows(self, log: LogData, period: float) -> list[dict]:
        """Every reference change of a PRMS sequence: its window's data and identification."""
        ccfg = load_controller_config(None)
        guess = tuple(table_a3()[5, 1:4] * (1.0, 1.0, MM))               # 150 mm, 0 kg: the fits' start
        ref = rebuild(log, "testbench", period)
        y = log.leg_positions(1)[:, 0]
        u = log.get("VALVE_CMD_1").per_cycle(log.n_cycles, "SPOOL_SETPOINT") * VALVE_FULL_SCALE_V
        pressure = log.get("LEG_PRESSURE_1")
        pl = pressure.per_cycle(log.n_cycles, "PA") - ccfg.actuator.area_ratio * pressure.per_cycle(log.n_cycles, "PB")
        u_applied = np.roll(u, DELAY_PERIODS)          # the input each cycle acts under
        u_applied[:DELAY_PERIODS] = np.nan
        n, pre = int(round(WINDOW_S / period)), int(round(PRE_S / period))
        sequence, previous_step, set_point_mm, out = -1, False, float("nan"), []
        for motion in ref.motions:
            if not motion.step:
                previous_step = False
                continue
            k0 = motion.start
            if not previous_step:             # a PRMS sequence starts at rest on its set point
                sequence += 1
                set_point_mm = float(np.round(ref.yr[k0 - 1, 0] / MM)) if k0 > 0 else float("nan")
            previous_step = True
            if k0 < pre or k0 + n >= log.n_cycles or motion.end_cycle - k0 < n:
                continue
            before, target = ref.yr[k0 - 1, 0], motion.trajectory.segments[0, 0, 0]
            step = target - before
            cycles = np.arange(k0, k0 + n + 1)
            if abs(step) < MIN_STEP_MM * MM or not np.all(np.isfinite(y[k0 - pre:k0 + n + 1])):
                continue
            k, _ = ident.proportional_gain(u[cycles], ref.yr[cycles, 0] - y[cycles])
            if not (np.isfinite(k) and k > 0.0):
                continue                      # not a P loop here (valves held, saturated, faulted)
            y0 = float(np.mean(y[k0 - pre:k0]))
            t = (cycles - k0) * period
            gcl = ident.fit_closed_loop(t, y[cycles] - y0, step, DELAY_PERIODS * period, k, guess)
            plant = ident.open_loop_from_closed(gcl, k)
            around = slice(k0 - pre, k0 + n + 1)
            terms = ident.force_terms(y[around], pl[around], ccfg.actuator.piston_area_m2, period, FILTER_HZ)
            pressure_signals = None
            if np.all(np.isfinite(pl[around])) and np.all(np.isfinite(u_applied[around])):
                pressure_signals = ident.load_pressure_signals(u_applied[around], y[around], pl[around], period,
                                                               FILTER_HZ)
            out.append({"sequence": sequence, "cycle": k0, "before_m": float(before), "step_m": float(step),
                        "load_kg": load_at(log, k0), "k_v_m": k, "gcl": gcl, "plant": plant,
                        "motion": ident.motion_parameters(terms), "force_terms": terms, "t": t,
                        "dy": y[cycles] - y0, "set_point_mm": set_point_mm, "pressure_signals": pressure_signals})
        return out

    def analyze(self, log: LogData, out: Path | None, rate_hz: float = 500.0) -> Analysis:
        period = 1.0 / rate_hz
        windows = self.windows(log, period)
        ecfg = run_emulator_config(log)
        area = load_controller_config(None).actuator.piston_area_m2
        a3 = table_a3()
        points = sorted({(w["set_point_mm"], w["load_kg"]) for w in windows}, key=lambda p: (p[1], p[0]))
        rows = []
        for set_point, load in points:
            mine = [w for w in windows if (w["set_point_mm"], w["load_kg"]) == (set_point, load)]
            candidates = [w["plant"] for w in mine if w["plant"] is not None]
            best, best_fit = None, -np.inf
            for plant in candidates:          # thesis: the model that fits every register best
                fit = model_fit(plant, mine, period)
                if fit > best_fit:
                    best, best_fit = plant, fit
            by_direction = {}
            for name, sign in (("up", 1.0), ("down", -1.0)):
                own = [w for w in mine if w["plant"] is not None and np.sign(w["step_m"]) == sign]
                if own:
                    by_direction[name] = {"windows": len(own),
                                          "fit_median": float(np.median([w["gcl"]["fit"] for w in own])),
                                          **{k: float(np.median([w["plant"][k] for w in own]))
                                             * (1.0 / MM if k == "k01" else 1.0) for k in ("b0", "b1", "k01")}}
            motion = [w["motion"] for w in mine if w["motion"] is not None]
            emu = linearise(ecfg, set_point, load or 0.0)
            column = TABLE_COLUMN.get(load)
            thesis = None if column is None else {
                key: float(np.interp(set_point, a3[:, 0], a3[:, column + i]))
                for i, key in enumerate(("b0", "b1", "k01"))}
            row = {"set_point_mm": set_point, "load_kg": load, "windows": len(mine),
                   "gains_v_mm": sorted({round(w["k_v_m"] * MM, 3) for w in mine}),
                   "window_fit_median": float(np.median([w["gcl"]["fit"] for w in mine])),
                   "window_fits": [round(w["gcl"]["fit"], 4) for w in mine],
                   "fit_best": best_fit, "by_direction": by_direction,
                   "identified": None if best is None else {"b0": best["b0"], "b1": best["b1"],
                                                             "k01": best["k01"] / MM, "pole": best["pole"]},
                   "emulator": {"b0": emu.b0, "b1": emu.b1, "k01": emu.k01, "m": moving_mass_kg(ecfg, load or 0.0)},
                   "table_a3": thesis}
            if motion:
                row["motion"] = {"m_kg": float(np.median([m["m"] for m in motion])),
                                 "sigma_ns_mm": float(np.median([m["sigma"] for m in motion])) * MM,
                                 "fe_n": float(np.median([m["fe"] for m in motion]))}
            row["emulator"] |= {"kx": emu.kx, "kd": emu.kd, "kp": emu.kp, "k02_mm_n": emu.k02_mm_n, "z0": emu.z0}
            row["table_a2"] = None if column is None else table_a2_at(set_point, column)
            if best is not None and motion:
                mass, sigma = row["motion"]["m_kg"], row["motion"]["sigma_ns_mm"] / MM
                kx, kd, kp = ident.sensibilities(best["b0"], best["b1"], best["k01"], mass, sigma, area)
                complete = ident.complete_model(kx, kd, kp, mass, sigma, area)
                row["sensibilities"] = {"kx": kx, "kd": kd, "kp": kp, "k02_mm_n": complete["k02"] / MM,
                                        "z0": complete["z0"]}
                row["complete"] = refined_chain(best, mine, mass, sigma, area, period)
            signals = [w["pressure_signals"] for w in mine if w["pressure_signals"] is not None]
            if signals:
                kx, kd, kp = ident.load_pressure_fit(signals)
                row["load_pressure"] = {"kx": kx, "kd": kd, "kp": kp}
            rows.append(row)
        checks = self._checks(rows)
        scheduled = scheduled_model(rows, windows, period)
        metrics = {"points": rows, "windows": len(windows), "motion_fits": motion_fits(rows), "scheduled": scheduled}
        figures = self._figures(windows, rows, out, period) if out is not None else []
        return Analysis(metrics, self.thesis, checks, figures,
                        [self._table(rows), self._sensibility_table(rows), scheduled_table(scheduled)])

    def _checks(self, rows: list[dict]) -> list[Check]:
        checks = [Check("identified points", len(rows) > 0 and all(r["identified"] for r in rows),
                        f"{sum(1 for r in rows if r['identified'])} of {len(rows)}", "every (set point, load)")]
        if not rows:
            return checks
        fits = [r["window_fit_median"] for r in rows]
        overall = float(np.median(np.concatenate([r["window_fits"] for r in rows])))
        checks.append(Check("window models' fit index (eq. 5.12), median of every window", overall >= FIT_MIN,
                            f"{overall:.3f}", f">= {FIT_MIN} (thesis 0.85-0.94)"))
        checks.append(Check("window models' fit index, median per point", min(fits) >= FIT_FLOOR,
                            f"{min(fits):.3f}-{max(fits):.3f}", f">= {FIT_FLOOR}"))
        low = [f"{r['set_point_mm']:.0f} mm {r['load_kg']:g} kg" for r in rows if r["window_fit_median"] < FIT_MIN]
        checks.append(Check("every point's median fit in the thesis's range", not low, ", ".join(low) or "all",
                            f">= {FIT_MIN}", required=False))
        with_mass = [r for r in rows if "motion" in r]
        ratios = [r["motion"]["m_kg"] / r["emulator"]["m"] for r in with_mass]
        checks.append(Check("m identified (eq. 5.7) / emulator's moving mass", len(with_mass) == len(rows) and all(
            abs(x - 1.0) <= MASS_TOLERANCE for x in ratios), f"{min(ratios):.2f}-{max(ratios):.2f}" if ratios else "-",
            f"1 +/- {MASS_TOLERANCE:.2f}"))
        best = [r["fit_best"] for r in rows]
        checks.append(Check("one model per point fits all its windows (mean eq. 5.12)", min(best) >= FIT_MIN,
                            f"{min(best):.3f}-{max(best):.3f}", f">= {FIT_MIN}", required=False))
        done = [r for r in rows if r["identified"]]
        for reference, name in (("emulator", "the emulator's linearisation"), ("table_a3", "Table A.3")):
            versus = [r for r in done if r[reference]]
            for key in ("b0", "b1", "k01"):
                ratios = [d[key] / r[reference][key] for r in versus for d in r["by_direction"].values()]
                checks.append(Check(f"{key} identified (up and down steps) / {name}", bool(ratios) and all(
                    0.8 <= x <= 1.25 for x in ratios), f"{min(ratios):.2f}-{max(ratios):.2f}" if ratios else "-",
                    "0.8-1.25", required=False))
        complete = [r["complete"] for r in rows if r.get("complete")]
        if complete:
            better, total = sum(c["at_least_g"] for c in complete), sum(c["windows"] for c in complete)
            checks.append(Check("the complete model (eq. 5.11, refined by eq. 5.12) fits each window at least as "
                                "well as G(s) alone", better == total, f"{better} of {total} windows",
                                "every window", required=False))
        linearisation = "the emulator's linearisation"
        references = (("sensibilities", "emulator", linearisation, ("kx", "kd", "kp", "k02_mm_n", "z0")),
                      ("sensibilities", "table_a2", "Table A.2", ("kx", "kd", "kp")),
                      ("complete", "emulator", linearisation, ("kx", "kd", "kp", "k02_mm_n", "z0")),
                      ("complete", "table_a2", "Table A.2", ("kx", "kd", "kp")),
                      ("load_pressure", "emulator", linearisation, ("kx", "kd", "kp")))
        labels = {"sensibilities": "eq. 5.8-5.11 on the identified G(s), m, sigma",
                  "complete": "refined by eq. 5.12 on the complete model",
                  "load_pressure": "least squares on eq. 4.50, the chamber pressures"}
        for source, reference, name, keys in references:
            versus = [r for r in rows if r.get(source) and r[reference]]
            for key in keys:
                ratios = [r[source][key] / r[reference][key] for r in versus]
                checks.append(Check(f"{key} ({labels[source]}) / {name}",
                                    bool(ratios) and all(0.8 <= x <= 1.2 for x in ratios),
                                    f"{min(ratios):.2f}-{max(ratios):.2f}" if ratios else "-", "0.8-1.2",
                                    required=False))
        inside = [r for r in done if -65 * 1.1 <= r["identified"]["pole"][0] <= -45 * 0.9
                  and 75 * 0.9 <= r["identified"]["pole"][1] <= 125 * 1.1]
        checks.append(Check("complex pole pair in the thesis's region (+/-10 %)", len(inside) == len(done),
                            f"{len(inside)} of {len(done)}", "Re [-65, -45], Im [75, 125] 1/s", required=False))
        return checks

    @staticmethod
    def _table(rows: list[dict]) -> str:
        lines = ["| Po mm | load kg | windows | K V/mm | fit (windows / one model) | b0 up / down / emu / A.3 | "
                 "b1 up / down / emu / A.3 | k01 (mm/s)/V up / down / emu / A.3 | m kg id / emu | "
                 "sigma N s/mm | Fe N |",
                 "|" + "---|" * 11]
        for r in rows:
            up, down = r["by_direction"].get("up", {}), r["by_direction"].get("down", {})
            e, t = r["emulator"], r["table_a3"] or {}

            def four(key, fmt, up=up, down=down, e=e, t=t):
                return " / ".join(format(v, fmt) if v is not None else "-"
                                  for v in (up.get(key), down.get(key), e[key], t.get(key)))
            m = r.get("motion", {})
            lines.append(f"| {r['set_point_mm']:.0f} | {r['load_kg']:g} | {r['windows']} | "
                         f"{', '.join(str(g) for g in r['gains_v_mm'])} | {r['window_fit_median']:.3f} / "
                         f"{r['fit_best']:.3f} | {four('b0', '.0f')} | {four('b1', '.1f')} | {four('k01', '.1f')} | "
                         f"{m.get('m_kg', float('nan')):.2f} / {e['m']:.2f} | "
                         f"{m.get('sigma_ns_mm', float('nan')):.3f} | "
                         f"{m.get('fe_n', float('nan')):.1f} |")
        return "\n".join(lines)

    @staticmethod
    def _sensibility_table(rows: list[dict]) -> str:
        lines = ["| Po mm | load kg | Kx kPa/(s V) id / refined / eq. 4.50 / emu / A.2 | "
                 "Kd kPa/mm id / refined / eq. 4.50 / emu / A.2 | Kp 1/s id / refined / eq. 4.50 / emu / A.2 | "
                 "k02 mm/N id / refined / emu | z0 1/s id / refined / emu | complete model's fit (G(s)'s) |",
                 "|" + "---|" * 8]
        for r in rows:
            k, c, q = r.get("sensibilities"), r.get("complete"), r.get("load_pressure")
            e, t = r["emulator"], r["table_a2"] or {}

            def cells(key, unit, fmt, k=k, c=c, q=q, e=e, t=t, table=True):
                values = (((k or {}).get(key), (c or {}).get(key), (q or {}).get(key), e[key], t.get(key)) if table
                          else ((k or {}).get(key), (c or {}).get(key), e[key]))
                return " / ".join("-" if v is None else format(v / unit, fmt) for v in values)
            lines.append(f"| {r['set_point_mm']:.0f} | {r['load_kg']:g} | {cells('kx', KPA, '.0f')} | "
                         f"{cells('kd', KPA / MM, '.0f')} | {cells('kp', 1.0, '.0f')} | "
                         f"{cells('k02_mm_n', 1.0, '.4f', table=False)} | {cells('z0', 1.0, '.0f', table=False)} | "
                         + (f"{c['fit_mean']:.3f} ({c['g_fit_mean']:.3f}), >= at {c['at_least_g']} of {c['windows']} |"
                            if c else "- |"))
        return "\n".join(lines)

    def _figures(self, windows, rows, out: Path, period: float) -> list[Figure]:
        figures = []
        if windows:
            first = [w for w in windows if w["sequence"] == windows[0]["sequence"]]
            fig, ax = plt.subplots(figsize=(8, 3.5))
            for w in first:
                t0 = w["cycle"] * period
                ax.plot(t0 + w["t"], (w["before_m"] + w["step_m"]) * 1e3 + 0 * w["t"], color="tab:blue", lw=1)
                ax.plot(t0 + w["t"], (w["dy"] + w["before_m"]) * 1e3, color="tab:red", lw=1)
            ax.set_xlabel("t [s]")
            ax.set_ylabel("y [mm]")
            ax.set_title("PRMS windows: reference (blue), encoder (red)")
            path = out / "sha_identification_prms.png"
            save(fig, path)
            figures.append(Figure(path.name, "the 150 ms windows of one PRMS sequence", "thesis Fig. 5.3"))
        done = [r for r in rows if r["identified"]]
        if done:
            fig, axes = plt.subplots(1, 3, figsize=(12, 3.5))
            for ax, key in zip(axes, ("b0", "b1", "k01")):
                for load in sorted({r["load_kg"] for r in done}):
                    mine = [r for r in done if r["load_kg"] == load]
                    x = [r["set_point_mm"] for r in mine]
                    c = colour_for_load(load)
                    ax.plot(x, [r["identified"][key] for r in mine], "o", color=c, label=f"identified {load:g} kg")
                    ax.plot(x, [r["emulator"][key] for r in mine], "-", color=c, label=f"emulator {load:g} kg")
                    if all(r["table_a3"] for r in mine):
                        ax.plot(x, [r["table_a3"][key] for r in mine], "--", color=c, label=f"Table A.3 {load:g} kg")
                ax.set_xlabel("set point [mm]")
                ax.set_title(key)
            axes[0].legend(fontsize=6)
            path = out / "sha_identification_plant.png"
            save(fig, path)
            figures.append(Figure(path.name, "b0, b1, k01: identified, emulator's linearisation, Table A.3",
                                  "thesis Table A.3"))
        figures += self._chain_figures(rows, out)
        figures += scheduled_figure(rows, out)
        return figures

    @staticmethod
    def _chain_figures(rows: list[dict], out: Path) -> list[Figure]:
        """Figs. 5.4-5.5 (m, sigma, Fe per position and load, their quadratics, Table A.1) and 5.7
        (Kx, Kd, Kp: identified, the linearisation, Table A.2)."""
        figures, fits = [], motion_fits(rows)
        a1 = np.asarray(thesis_data("chapter5")["table_A1"]["rows"], float)

        def quadratic(load, mine, key, unit, i):
            coeffs = fits.get(f"{load:g}", {}).get(key)
            if coeffs is None:
                return None
            x = np.array([r["set_point_mm"] for r in mine])
            grid = np.linspace(x.min(), x.max(), 50)
            return grid, np.polyval(coeffs, grid * MM) / unit, None

        def table_a1(load, mine, key, unit, i):
            column = TABLE_COLUMN.get(load)
            return None if column is None else (a1[:, 0], a1[:, column + i], f"Table A.1 {load:g} kg")

        def emulator(load, mine, key, unit, i):
            return [r["set_point_mm"] for r in mine], [r["emulator"][key] / unit for r in mine], f"emulator {load:g} kg"

        def table_a2(load, mine, key, unit, i):
            if not all(r["table_a2"] for r in mine):
                return None
            return ([r["set_point_mm"] for r in mine], [r["table_a2"][key] / unit for r in mine],
                    f"Table A.2 {load:g} kg")

        panels = (("motion", (("m_kg", 1.0, "m [kg]"), ("sigma_ns_mm", MM, "sigma [N s/m]"), ("fe_n", 1.0, "Fe [N]")),
                   quadratic, table_a1, "sha_identification_motion.png",
                   "m, sigma, Fe per set point and load (dots), their quadratics (lines), Table A.1 (dashed)",
                   "thesis Figs. 5.4-5.5"),
                  ("sensibilities", (("kx", KPA, "Kx [kPa/(s V)]"), ("kd", KPA / MM, "Kd [kPa/mm]"),
                                     ("kp", 1.0, "Kp [1/s]")),
                   emulator, table_a2, "sha_identification_sensibilities.png",
                   "Kx, Kd, Kp by eq. 5.8-5.10: identified (dots), refined by eq. 5.12 on the complete model "
                   "(crosses), emulator's linearisation, Table A.2", "thesis Fig. 5.7"))
        for section, keys, line, dashed, name, caption, thesis in panels:
            having = [r for r in rows if section in r]
            if not having:
                continue
            fig, axes = plt.subplots(1, 3, figsize=(12, 3.5))
            for i, (ax, (key, unit, title)) in enumerate(zip(axes, keys)):
                for load in sorted({r["load_kg"] for r in having}):
                    mine = [r for r in having if r["load_kg"] == load]
                    c = colour_for_load(load)
                    ax.plot([r["set_point_mm"] for r in mine], [r[section][key] / unit for r in mine], "o", color=c,
                            label=f"identified {load:g} kg")
                    refined = [r for r in mine if section == "sensibilities" and r.get("complete")]
                    if refined:
                        ax.plot([r["set_point_mm"] for r in refined], [r["complete"][key] / unit for r in refined],
                                "x", color=c, label=f"refined (eq. 5.12) {load:g} kg")
                    curves = ((line(load, mine, key, unit, i), "-"), (dashed(load, mine, key, unit, i), "--"))
                    for curve, style in curves:
                        if curve is not None:
                            ax.plot(curve[0], curve[1], style, color=c, label=curve[2])
                ax.set_xlabel("set point [mm]")
                ax.set_title(title)
            axes[0].legend(fontsize=6)
            save(fig, out / name)
            figures.append(Figure(name, caption, thesis))
        return figures


def table_a2_at(set_point_mm: float, column: int) -> dict:
    """Table A.2 at a set point (interpolated), SI: Kx Pa/(s V), Kd Pa/m, Kp 1/s."""
    a2 = np.asarray(thesis_data("chapter5")["table_A2"]["rows"], float)
    kx, kd, kp = (float(np.interp(set_point_mm, a2[:, 0], a2[:, column + i])) for i in range(3))
    return {"kx": kx * KPA, "kd": kd * KPA / MM, "kp": kp}


def motion_fits(rows: list[dict]) -> dict:
    """Per load: m, sigma, Fe as quadratics in the set point [m] (chapter 5.2.3; coefficients
    highest first, sigma in N s/mm as the rows); loads with fewer than three points left out."""
    fits = {}
    for load in sorted({r["load_kg"] for r in rows if "motion" in r}):
        mine = [r for r in rows if "motion" in r and r["load_kg"] == load]
        y = np.array([r["set_point_mm"] for r in mine]) * MM
        per = {key: ident.quadratic_fit(y, np.array([r["motion"][key] for r in mine]))
               for key in ("m_kg", "sigma_ns_mm", "fe_n")}
        if all(v is not None for v in per.values()):
            fits[f"{load:g}"] = {key: [float(c) for c in v] for key, v in per.items()}
    return fits


def window_fits(plant: dict, windows: list[dict], period: float) -> np.ndarray:
    """Eq. 5.12's fit index of G(s) = `plant` under each window's P loop."""
    return np.array([ident.fit_index(w["dy"], w["step_m"] * ident.closed_loop_step(
        *ident.closed_loop_of(plant, w["k_v_m"]), w["t"], DELAY_PERIODS * period)) for w in windows])


def model_fit(plant: dict, windows: list[dict], period: float) -> float:
    """`window_fits`' mean."""
    return float(np.mean(window_fits(plant, windows, period)))


def refined_chain(plant: dict, windows: list[dict], mass_kg: float, sigma_ns_m: float, area_m2: float,
                  period: float) -> dict | None:
    """Chapter 5.2.4 on one point: the complete model (eq. 5.11) from `plant` and m, sigma, each
    window's load change the residual of eq. 5.6 (what m, sigma and the chambers' force leave),
    Kx, Kd, Kp refined by eq. 5.12 over the point's windows; its constants and each window's
    fit against G(s) alone (None: no window with its force terms)."""
    rest = int(round(PRE_S / period))
    usable = [w | {"load_n": ident.load_change(w["force_terms"], mass_kg, sigma_ns_m, rest)}
              for w in windows if w["force_terms"] is not None]
    if not usable:
        return None
    alone = window_fits(plant, usable, period)
    refined = ident.refine_complete(plant, mass_kg, sigma_ns_m, area_m2, usable, DELAY_PERIODS * period)
    fits = ident.complete_fits(refined, mass_kg, sigma_ns_m, area_m2, usable, DELAY_PERIODS * period)
    kx, kd, kp = ident.sensibilities(refined["b0"], refined["b1"], refined["k01"], mass_kg, sigma_ns_m, area_m2)
    path = ident.complete_model(kx, kd, kp, mass_kg, sigma_ns_m, area_m2)
    return {"windows": len(usable), "at_least_g": int(np.sum(fits >= alone)), "fit_mean": float(np.mean(fits)),
            "g_fit_mean": float(np.mean(alone)), "kx": kx, "kd": kd, "kp": kp, "k02_mm_n": path["k02"] / MM,
            "z0": path["z0"], "refined": refined}


SCHEDULED = ("b0", "b1", "k01")


def scheduled_model(rows: list[dict], windows: list[dict], period: float) -> dict:
    """Fig. 5.10: G(s)'s b0, b1, k01 scheduled on the set point, per load (splines through the
    identified points). Each interior point judged by the table made without it: its
    parameters as the table reads them there, and eq. 5.12's fit on its own windows beside
    its own model's."""
    out = {"loads": {}, "left_out": []}
    for load in sorted({r["load_kg"] for r in rows if r["identified"]}):
        mine = [r for r in rows if r["identified"] and r["load_kg"] == load]
        x = np.array([r["set_point_mm"] for r in mine]) * MM
        values = {key: np.array([r["identified"][key] * (MM if key == "k01" else 1.0) for r in mine])
                  for key in SCHEDULED}
        out["loads"][f"{load:g}"] = {"set_points_mm": [r["set_point_mm"] for r in mine],
                                     **{key: [float(v) for v in values[key]] for key in SCHEDULED}}
        read = {key: ident.leave_one_out(x, values[key]) for key in SCHEDULED}
        for i, row in enumerate(mine):
            if not np.isfinite(read["b0"][i]):
                continue
            plant = {key: float(read[key][i]) for key in SCHEDULED}
            own = [w for w in windows if (w["set_point_mm"], w["load_kg"]) == (row["set_point_mm"], load)]
            out["left_out"].append({"set_point_mm": row["set_point_mm"], "load_kg": load,
                                    "b0": plant["b0"], "b1": plant["b1"], "k01": plant["k01"] / MM,
                                    "fit_scheduled": model_fit(plant, own, period), "fit_own": row["fit_best"]})
    fits = [p["fit_scheduled"] for p in out["left_out"]]
    out["fit_scheduled_median"] = float(np.median(fits)) if fits else None
    return out


def scheduled_table(scheduled: dict) -> str:
    rows = scheduled["left_out"]
    if not rows:
        return "scheduled model (Fig. 5.10): no interior point to leave out"
    lines = ["scheduled model (Fig. 5.10), each interior point read from the others' splines: eq. 5.12 fit "
             "on its windows, scheduled vs its own G(s)",
             "| set point mm | load kg | b0 1/s2 | b1 1/s | k01 mm/(s V) | fit scheduled | fit own |",
             "|---|---|---|---|---|---|---|"]
    lines += [f"| {r['set_point_mm']:g} | {r['load_kg']:g} | {r['b0']:.0f} | {r['b1']:.1f} | {r['k01']:.1f} | "
              f"{r['fit_scheduled']:.3f} | {r['fit_own']:.3f} |" for r in rows]
    return "\n".join(lines)


def scheduled_figure(rows: list[dict], out: Path) -> list[Figure]:
    """Fig. 5.10's table: b0, b1, k01 over the set point per load, the splines between the
    identified points."""
    done = [r for r in rows if r["identified"]]
    if not done:
        return []
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.5))
    for ax, key in zip(axes, SCHEDULED):
        for load in sorted({r["load_kg"] for r in done}):
            mine = [r for r in done if r["load_kg"] == load]
            x = np.array([r["set_point_mm"] for r in mine])
            values = np.array([r["identified"][key] for r in mine])
            c = colour_for_load(load)
            ax.plot(x, values, "o", color=c, label=f"identified {load:g} kg")
            grid = np.linspace(x.min(), x.max(), 100)
            ax.plot(grid, [ident.scheduled_parameter(x, values, g) for g in grid], "-", color=c,
                    label=f"scheduled {load:g} kg")
        ax.set_xlabel("set point [mm]")
        ax.set_title(key)
    axes[0].legend(fontsize=6)
    name = "sha_identification_scheduled.png"
    save(fig, out / name)
    return [Figure(name, "G(s) scheduled on the set point per load: the identified points and the splines "
                         "the model reads between them", "thesis Fig. 5.10")]
