"""guide-free-fall: thesis Appendix D (Fig. D.1, Table D.1), the linear guide's friction from
free falls of its slide, through the bus.

Per load and fall: the PI lifts the slide to TOP_M, the host unbolts the slide from the rod
(EMU_CTRL UNBOLT_SLIDE: on the rig, a hand on the bolt), and a VALVE_STEP test pulls the rod
down faster than the slide can fall, so the slide falls free on its guide while the guide's
encoder records it; the test ends at the stroke guard, the loop holds, the slide lands on
the rod and is bolted again (EMU_CTRL BOLT_SLIDE). The analysis (log only, `hil.design.
guide_fit`) fits eq. D.4 (Fc, sigma_v common to every load) to the falls' records and eq.
D.3's Stribeck part (Fs, vs) per load, and draws eq. D.2's force-velocity cloud beside Fig.
D.1. Judged against the emulator's guide (`[guide]`), beside Table D.1.

Deviations: the falls are fitted on the record itself (output error), not read off eq. D.2's
cloud: at 500 Hz the 0.125 mm encoder's counts give s'' ~4 m/s^2 of noise behind the thesis's
100 Hz filter. Table D.1's Fs column equals each load's weight to 0.1 N: eq. D.2 at the
release, where the filtered s'' is still ~0 (shown as such here).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hil.design import guide_fit
from hil.design.thesis import thesis_data
from hil.logdata import LogData
from hil.plotting import plt, save
from hil.scenario import Analysis, Check, Figure, Scenario
from hil.scenarios.common import each_controller_and_load, load_at, move_stroke, run_emulator_config
from physics.constants import GRAVITY_M_S2, MM
from protocol.enums import AckKind, EmuCommand, TestMode


def appendix_d() -> dict:
    return thesis_data("appendix_d")


TOP_M = 0.270                       # where each fall starts
DROP_VALVE_V = -6.0                 # the rod retracts faster than a 6 kg slide falls (2.2 m/s at the bottom)
TEST_S = 3.0                        # the valve step's longest: a 0 kg slide falls 250 mm in ~1.2 s
PRE_S = 0.02                        # at rest before the step: the slide's start
END_ABOVE_M = 0.030                 # a fall's record ends here, before the stroke guard's hold meets it
FILTER_HZ = float(appendix_d()["experiment"]["filter_hz"])   # eq. D.2's Butterworth
# Tolerances on the emulator's guide: the pooled fit of 2-16 falls of 0.125 mm counts
COULOMB_TOLERANCE = 0.10
VISCOUS_TOLERANCE = 0.20
STATIC_TOLERANCE_N = 1.0            # where the guide has no Stribeck hump (Fs = Fc): Fs - Fc found below this
FIT_MIN = 0.995                     # eq. 5.12 on the distance fallen
# a 6 kg slide reaches 2.2 m/s; the rod carries nothing while the slide falls, which the
# actuator residuals (chamber model against the load cell) rightly call a fault; the slide
# lands on the guide's end (the thesis's falls did), inside the limits' end-stop margin
OVERRIDES = {"limits": {"velocity_max_mm_s": 3000.0, "stroke_margin_mm": 0.0}, "residuals": {"enabled": False}}


def _colour(load_kg: float):
    return plt.cm.viridis(min(load_kg / 6.0, 1.0) * 0.9)


def peak_velocity(s_m: np.ndarray, period: float) -> float:
    """A fall's fastest, over 20 ms (one encoder count in 2 ms is up to 62 mm/s)."""
    n = max(int(round(0.02 / period)), 1)
    return float(np.max(s_m[n:] - s_m[:-n])) / (n * period) if len(s_m) > n else 0.0


class GuideFreeFall(Scenario):
    name = "guide-free-fall"
    title = "free falls of the guide's slide: eq. D.4 and D.3 fitted, Fig. D.1"
    chapter = "Appendix D (Table D.1, Fig. D.1)"
    rig = "testbench"
    controllers = ("pi",)
    pacings = ("lockstep",)
    sweeps_loads = True
    controller_overrides = OVERRIDES

    def plan(self, short: bool) -> tuple[tuple[float, ...], int]:
        """(loads kg, falls per load)."""
        if short:
            return (0.0, 6.0), 1
        return tuple(appendix_d()["experiment"]["loads_kg"]), 2

    def script(self, run) -> None:
        loads, falls = self.plan(run.short)
        here = 0.150
        for _ in each_controller_and_load(run, loads):
            for _ in range(falls):
                move_stroke(run, TOP_M, settle_s=0.5, from_m=here)
                run.host.emulator(EmuCommand.UNBOLT_SLIDE)
                run.wait_s(0.05)
                run.host.test(TestMode.VALVE_STEP, valve_v=DROP_VALVE_V, duration_s=TEST_S)
                run.wait_motion_done(TEST_S + 1.0)
                run.wait_s(0.5)                 # the slide has landed on the holding rod
                run.host.emulator(EmuCommand.BOLT_SLIDE)
                run.wait_s(0.1)
                here = run.host.leg1_track[-1][1] if run.host.leg1_track else 0.030

    # -- analysis ---------------------------------------------------------------------------
    def falls(self, log: LogData, period: float) -> list[guide_fit.Fall]:
        """Each accepted VALVE_STEP after an UNBOLT_SLIDE: the record from PRE_S before it until
        the slide is END_ABOVE_M over the rod's bottom, as distance fallen."""
        ecfg = run_emulator_config(log)
        y = log.leg_positions(1)[:, 0]
        accepted = {int(e.values["SEQ"]) for e in log.events_named("CTRL_ACK")
                    if int(e.values["KIND"]) == AckKind.TEST and int(e.values["RESULT"]) == 0}
        slide = [(e.cycle, int(e.values["COMMAND"])) for e in log.events_named("EMU_CTRL")]
        unbolted = [c for c, command in slide if command == EmuCommand.UNBOLT_SLIDE]
        bolted = [c for c, command in slide if command == EmuCommand.BOLT_SLIDE]
        pre = int(round(PRE_S / period))
        out = []
        for e in log.events_named("HOST_TEST"):
            if int(e.values["MODE"]) != TestMode.VALVE_STEP or int(e.values["SEQ"]) not in accepted:
                continue
            k0 = e.cycle
            last_unbolt = max((c for c in unbolted if c <= k0), default=None)
            if last_unbolt is None or any(last_unbolt < c <= k0 for c in bolted) or k0 < pre:
                continue
            before = y[k0 - pre:k0]
            if not np.all(np.isfinite(before)):
                continue
            y0 = float(np.mean(before))
            below = np.nonzero(y[k0:] <= END_ABOVE_M)[0]
            if len(below) == 0:
                continue
            k1 = k0 + int(below[0])
            record = y[k0 - pre:k1]
            ok = np.isfinite(record)
            t = (np.arange(k0 - pre, k1) - k0) * period
            load = load_at(log, k0) or 0.0
            out.append(guide_fit.Fall(load, ecfg.guide.slide_mass_kg + load, t[ok], y0 - record[ok]))
        return out

    def analyze(self, log: LogData, out: Path | None, rate_hz: float = 500.0) -> Analysis:
        period = 1.0 / rate_hz
        falls = self.falls(log, period)
        guide = run_emulator_config(log).guide
        table = appendix_d()
        metrics: dict = {"falls": len(falls)}
        if not falls:
            return Analysis(metrics, self._thesis(table), [Check("free falls found in the log", False, "0", ">= 1")])
        viscous = guide_fit.fit_viscous(falls)
        exponent = float(table["table_D1"]["delta_s"])
        loads = sorted({f.load_kg for f in falls})
        per_load = []
        for load in loads:
            mine = [i for i, f in enumerate(falls) if f.load_kg == load]
            stribeck = guide_fit.fit_stribeck([falls[i] for i in mine], [viscous["release_s"][i] for i in mine],
                                              viscous["coulomb_n"], viscous["viscous_ns_m"], exponent)
            fs_emu = float(np.interp(load, guide.table_mass_kg, guide.table_static_n))
            vs_emu = float(np.interp(load, guide.table_mass_kg, guide.table_stribeck_m_s))
            per_load.append({"load_kg": load, "falls": len(mine), "weight_n": falls[mine[0]].mass_kg * GRAVITY_M_S2,
                             "peak_velocity_mm_s": max(peak_velocity(falls[i].s_m, period) for i in mine) / MM,
                             "fit": [viscous["fit"][i] for i in mine], **stribeck,
                             "emulator": {"static_n": fs_emu, "stribeck_m_s": vs_emu},
                             "table_d1": self._table_d1_row(table, load)})
        metrics |= {"coulomb_n": viscous["coulomb_n"], "viscous_ns_m": viscous["viscous_ns_m"],
                    "emulator": {"coulomb_n": guide.coulomb_n, "viscous_ns_m": guide.viscous_ns_m,
                                 "stribeck_exponent": guide.exponent},
                    "table_d1": {"coulomb_n": float(table["table_D1"]["coulomb_n"]),
                                 "viscous_ns_m": float(table["table_D1"]["viscous_ns_mm"]) / MM},
                    "loads": per_load}
        checks = self._checks(metrics, loads, guide)
        figures = [self._plot(falls, viscous, per_load, guide, out, period)] if out is not None else []
        return Analysis(metrics, self._thesis(table), checks, figures, [self._table(metrics)])

    @staticmethod
    def _table_d1_row(table: dict, load: float) -> dict | None:
        rows = {round(r[0], 3): r for r in table["table_D1"]["rows"]}
        row = rows.get(round(load, 3))
        return None if row is None else {"stribeck_mm_s": row[1], "static_n": row[2]}

    @staticmethod
    def _thesis(table: dict) -> dict:
        d1 = table["table_D1"]
        return {"table": "D.1", "coulomb_n": d1["coulomb_n"], "viscous_ns_mm": d1["viscous_ns_mm"],
                "delta_s": d1["delta_s"], "figure": "Fig. D.1: force-velocity cloud of eq. D.2, 0-6 kg"}

    @staticmethod
    def _checks(m: dict, loads: list[float], guide) -> list[Check]:
        planned = [f"{row['load_kg']:g} kg" for row in m["loads"]]
        checks = [Check("free falls found in the log, every load", len(loads) == len(m["loads"]) and m["falls"] > 0,
                        f"{m['falls']} falls at {', '.join(planned)}", ">= 1 per load")]
        e = m["emulator"]
        fc, sv = m["coulomb_n"] / e["coulomb_n"], m["viscous_ns_m"] / e["viscous_ns_m"]
        checks.append(Check("Fc (eq. D.4, every fall) / the emulator's guide", abs(fc - 1.0) <= COULOMB_TOLERANCE,
                            f"{m['coulomb_n']:.2f} N ({fc:.3f})", f"1 +/- {COULOMB_TOLERANCE:g}"))
        checks.append(Check("sigma_v (eq. D.4, every fall) / the emulator's guide", abs(sv - 1.0) <= VISCOUS_TOLERANCE,
                            f"{m['viscous_ns_m'] * MM:.4f} N s/mm ({sv:.3f})", f"1 +/- {VISCOUS_TOLERANCE:g}"))
        fits = [x for row in m["loads"] for x in row["fit"]]
        checks.append(Check("each fall's fit index (eq. 5.12 on the distance fallen)", min(fits) >= FIT_MIN,
                            f"{min(fits):.4f}-{max(fits):.4f}", f">= {FIT_MIN}"))
        wrong = []
        for row in m["loads"]:
            emu = row["emulator"]["static_n"] - e["coulomb_n"]
            found = row["static_n"] - m["coulomb_n"]
            if emu < STATIC_TOLERANCE_N:        # no Stribeck hump: none found
                ok = found < STATIC_TOLERANCE_N
            else:
                ok = row["identifiable"] and abs(found - emu) <= max(STATIC_TOLERANCE_N, 0.2 * emu)
            if not ok:
                wrong.append(f"{row['load_kg']:g} kg: Fs - Fc {found:.2f} N (emulator {emu:.2f})")
        checks.append(Check("Fs - Fc (eq. D.3) per load against the emulator's guide", not wrong,
                            "; ".join(wrong) or "every load", f"within {STATIC_TOLERANCE_N:g} N or 20 %"))
        t = m["table_d1"]
        checks.append(Check("Fc, sigma_v beside Table D.1",
                            abs(m["coulomb_n"] / t["coulomb_n"] - 1.0) <= COULOMB_TOLERANCE
                            and abs(m["viscous_ns_m"] / t["viscous_ns_m"] - 1.0) <= VISCOUS_TOLERANCE,
                            f"{m['coulomb_n']:.2f} N, {m['viscous_ns_m'] * MM:.4f} N s/mm",
                            f"{t['coulomb_n']:g} N, {t['viscous_ns_m'] * MM:g} N s/mm", required=False))
        return checks

    @staticmethod
    def _table(m: dict) -> str:
        lines = [f"eq. D.4 over every fall: Fc {m['coulomb_n']:.2f} N (emulator {m['emulator']['coulomb_n']:g}, "
                 f"Table D.1 {m['table_d1']['coulomb_n']:g}), sigma_v {m['viscous_ns_m'] * MM:.4f} N s/mm "
                 f"(emulator {m['emulator']['viscous_ns_m'] * MM:g}, Table D.1 {m['table_d1']['viscous_ns_m'] * MM:g})",
                 "",
                 "| load kg | falls | peak v mm/s | fit (eq. 5.12) | Fs N (emulator / Table D.1) | vs mm/s (emulator / "
                 "Table D.1) |",
                 "|---|---|---|---|---|---|"]
        for row in m["loads"]:
            d1 = row["table_d1"] or {}
            vs = f"{row['stribeck_m_s'] / MM:.0f}" if row["identifiable"] else "-"
            lines.append(f"| {row['load_kg']:g} | {row['falls']} | {row['peak_velocity_mm_s']:.0f} | "
                         f"{min(row['fit']):.4f} | {row['static_n']:.2f} ({row['emulator']['static_n']:.2f} / "
                         f"{d1.get('static_n', '-')}) | {vs} ({row['emulator']['stribeck_m_s'] / MM:.0f} / "
                         f"{d1.get('stribeck_mm_s', '-')}) |")
        return "\n".join(lines)

    @staticmethod
    def _plot(falls, viscous, per_load, guide, out: Path, period: float) -> Figure:
        fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4))
        for i, f in enumerate(falls):
            colour = _colour(f.load_kg)
            v, force = guide_fit.friction_d2(f.s_m, f.mass_kg, period, FILTER_HZ)
            moving = f.t_s >= viscous["release_s"][i]
            left.plot(v[moving] / MM, force[moving], ".", ms=1.5, color=colour)
            right.plot(f.t_s, f.s_m / MM, ".", ms=1.5, color=colour)
            right.plot(f.t_s, guide_fit.fall_d4(f.t_s, viscous["release_s"][i], f.mass_kg, viscous["coulomb_n"],
                                                viscous["viscous_ns_m"]) / MM, "k-", lw=0.6)
        for row in per_load:
            top = row["peak_velocity_mm_s"] * MM
            v = np.linspace(0.0, top, 100)
            fitted = [guide_fit.stribeck_friction(x, viscous["coulomb_n"], row["static_n"], row["stribeck_m_s"],
                                                  guide.exponent, viscous["viscous_ns_m"]) for x in v]
            left.plot(v / MM, fitted, "-", color=_colour(row["load_kg"]), lw=1.2,
                      label=f"{row['load_kg']:g} kg: eq. D.3 fitted")
        v = np.linspace(0.0, max(r["peak_velocity_mm_s"] for r in per_load) * MM, 100)
        left.plot(v / MM, guide.coulomb_n + guide.viscous_ns_m * v, "k--", lw=0.8, label="emulator's guide (eq. D.4)")
        left.set_xlabel("v [mm/s]")
        left.set_ylabel("F_f [N] (eq. D.2, 100 Hz)")
        left.legend(fontsize=6)
        right.set_xlabel("t from the valve step [s]")
        right.set_ylabel("fallen [mm]: encoder (dots), eq. D.4 fitted (line)")
        path = out / "guide_free_fall.png"
        save(fig, path)
        return Figure(path.name, "left: eq. D.2's force-velocity cloud of every fall and eq. D.3 as fitted per load; "
                                 "right: each fall's record and eq. D.4's fit",
                      "thesis Fig. D.1: the force-velocity characteristic of the free falls, 0-6 kg")
