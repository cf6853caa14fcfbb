"""`hydrapod design robustness` and `design schedule`: the analysis put together, beside the
thesis's numbers (data/chapter7.toml), as a JSON document, a markdown report and figures.
Thesis units (mm, V, N) appear here, at the edge; the computations are SI."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hil.design import robustness as rb
from hil.design.plants import MM, Plant, chapter7, select_nominal
from hil.design.schedule import KI_DETUNING, compare_with_table_7_2, tune, ziegler_nichols
from hil.plotting import colour_for_load, plt, save


def _poly_mm(p: np.ndarray, scale: float) -> list[float]:
    return [float(v) for v in np.asarray(p, float) * scale]


def _complex(values) -> list[list[float]]:
    return [[round(float(v.real), 4), round(float(v.imag), 4)] for v in values]


def thesis_plant() -> Plant:
    """Eq. 7.13 as printed: 1.722e6 / (s^3 + 90.31 s^2 + 7692 s) mm/V."""
    nominal = chapter7()["nominal_plant"]
    num, den = nominal["numerator"][0], nominal["denominator"]
    return Plant(nominal["position_mm"] * MM, nominal["load_kg"], den[2], den[1], num / den[2] * MM)


def find_plant(plants: list[Plant], position_mm: float, load_kg: float) -> int | None:
    for i, p in enumerate(plants):
        if abs(p.position_m / MM - position_mm) < 1e-6 and abs(p.load_kg - load_kg) < 1e-6:
            return i
    return None


def disturbance_paths(plants: list[Plant]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each plant's G2 = k02 b0 (s + z0) / (s (s^2 + b1 s + b0)) [m/N] (eq. 4.68, its magnitude:
    the position's response to an external force), from the packaged emulator's linearisation
    at the plant's set point: the thesis identified G1 only."""
    from hil.design.calibration import linearise
    from plant_emulator.params import load_config as load_emulator_config
    cfg = load_emulator_config()
    out = []
    for plant in plants:
        point = linearise(cfg, plant.position_m / MM, plant.load_kg)
        c1 = point.k02_mm_n * MM * point.b0
        out.append((np.array([c1, c1 * point.z0]), np.array([1.0, point.b1, point.b0, 0.0])))
    return out


def robustness_doc(plants: list[Plant], source: str, kp_v_mm: float, ki_v_mm_s: float,
                   nominal_at: tuple[float, float] | None = None) -> tuple[dict, dict]:
    """(the JSON document, the arrays the figure needs)."""
    thesis = chapter7()
    kp, ki = kp_v_mm / MM, ki_v_mm_s / MM
    best, scores = select_nominal(plants)
    totals = scores.sum(axis=1)
    order = np.argsort(-totals)
    chosen = best if nominal_at is None else find_plant(plants, *nominal_at)
    p0 = plants[chosen]
    thesis_index = find_plant(plants, thesis["nominal_plant"]["position_mm"], thesis["nominal_plant"]["load_kg"])
    nominal = {
        "criterion": "eq. 7.10-7.11 on synthesised registers (10 mm step, K = 0.25 V/mm, 0.3 s at 500 Hz)",
        "selected_by": "eq. 7.10" if nominal_at is None else "--nominal",
        "plant": p0.label, "b0": p0.b0, "b1": p0.b1, "k01_mm_s_v": p0.k01 / MM,
        "numerator_mm": _poly_mm(p0.num(), 1.0 / MM), "denominator": _poly_mm(p0.den(), 1.0),
        "sum_F": float(totals[chosen]), "best_by_eq_7_10": [(plants[i].label, round(float(totals[i]), 4))
                                                             for i in order[:3]],
        "thesis": "6 kg, 120 mm: 1.722e6 / (s^3 + 90.31 s^2 + 7692 s) (eq. 7.12-7.13)",
        "thesis_plant_rank": None if thesis_index is None else int(np.flatnonzero(order == thesis_index)[0]) + 1,
        "thesis_plant_sum_F": None if thesis_index is None else float(totals[thesis_index]),
        "plants": len(plants),
    }
    g2 = disturbance_paths(plants)                    # the emulator's eq. 4.68 Fe path at each set point
    w0 = g2[chosen]                                   # eq. 7.23: W0 is P0's G2, here derived, m/N
    printed_w0 = (np.array(thesis["weights"]["w0_numerator"]) * MM, np.array(thesis["weights"]["w0_denominator"]))
    table = rb.well_posedness(p0, w0[0])
    posed = {kind: {"maps": {m.name: f"{m.num_degree}/{m.den_degree}" for m in maps},
                    "well_posed": all(m.proper for m in maps)} for kind, maps in table.items()}

    poles = rb.closed_loop_poles(p0, kp, ki)
    thesis_poles = np.array([complex(*p) for p in thesis["pi"]["closed_loop_poles"]])
    implied = np.real(np.poly(thesis_poles))                 # s^4 + b1 s^3 + b0 s^2 + Kp kb s + Ki kb
    kb_mm = thesis["nominal_plant"]["numerator"][0]
    maps = {name: rb.hinf(n, d)[0] for name, (n, d) in rb.internal_stability_maps(p0, kp, ki).items()}
    worst = max(float(rb.closed_loop_poles(p, kp, ki).real.max()) for p in plants)
    pi = {"kp_v_mm": kp_v_mm, "ki_v_mm_s": ki_v_mm_s, "poles": _complex(poles),
          "internally_stable": rb.internally_stable(p0, kp, ki),
          "map_hinf": {k: v for k, v in maps.items()},           # SI: V/m, m/V or 1
          "poles_on_thesis_plant": _complex(rb.closed_loop_poles(thesis_plant(), kp, ki)),
          "thesis_poles": _complex(thesis_poles),
          "thesis_poles_imply": {"b1": float(implied[1]), "b0": float(implied[2]),
                                 "kp_v_mm": float(implied[3] / kb_mm), "ki_v_mm_s": float(implied[4] / kb_mm)},
          "every_plant_stabilised": worst < 0, "slowest_pole_real_over_set": worst,
          "steps_on_plants": rb.steps_on_plants(plants, kp, ki)}

    w = rb.grid()
    errors = rb.multiplicative_error(plants, p0, w)
    bound = errors.max(axis=0)
    w1 = rb.fit_weight(w, bound)
    printed_w1 = (np.array(thesis["weights"]["w1_numerator"]), np.array(thesis["weights"]["w1_denominator"]))
    wdm = (np.array(thesis["weights"]["wdm_numerator"]), np.array(thesis["weights"]["wdm_denominator"]))
    w1t, w1t_at = rb.small_gain(p0, kp, ki, w1)
    printed, printed_at = rb.small_gain(p0, kp, ki, printed_w1)
    printed_peak, printed_peak_at = rb.hinf(*printed_w1)
    uncertainty = {
        "range_rad_s": list(rb.W_RANGE_RAD_S), "max_error": float(bound.max()),
        "max_error_at_rad_s": float(w[np.argmax(bound)]),
        "w1_numerator": [float(v) for v in w1[0]], "w1_denominator": [float(v) for v in w1[1]],
        "w1_zeros": _complex(np.roots(w1[0])), "w1_poles": _complex(np.roots(w1[1])),
        "w1_over_bound_min": float(np.min(np.abs(rb.response(*w1, w)) / bound)),
        "w1t_hinf": w1t, "w1t_peak_rad_s": w1t_at, "robustly_stable": w1t <= 1.0,
        "thesis_w1t_hinf": thesis["weights"]["w1t_hinf"],
        "printed_w1": {"w1t_hinf": printed, "at_rad_s": printed_at, "w1_peak": printed_peak,
                       "w1_peak_at_rad_s": printed_peak_at,
                       "note": "eq. 7.15 as printed peaks far above Fig. 7.4's curve (<= ~3): its "
                               "coefficients do not reproduce the figure nor eq. 7.22"},
    }
    g2_errors = np.array([np.abs(rb.response(*g, w) / rb.response(*w0, w) - 1.0) for g in g2])
    wdm_derived = rb.fit_weight(w, g2_errors.max(axis=0))          # eq. 7.24 by W1's procedure
    nominal_disturbance, nd_at = rb.disturbance_response(p0, kp, ki, w0)
    printed_disturbance, _ = rb.disturbance_response(p0, kp, ki, printed_w0)
    steady = float(w0[0][-1] / w0[1][-2]) / MM                     # |W0| s -> 0: steady mm/s per N
    printed_steady = float(printed_w0[0][-1] / printed_w0[1][-2]) / MM
    performance = {"s_w0_hinf_mm_n": nominal_disturbance / MM, "at_rad_s": nd_at,
                   "worst_case_bound_mm_n": rb.robust_performance_bound(p0, kp, ki, w1, w0, wdm_derived) / MM,
                   "thesis_tyd_hinf": thesis["weights"]["tyd_hinf"],
                   "w0_numerator_mm": [float(v) / MM for v in w0[0]], "w0_denominator": [float(v) for v in w0[1]],
                   "w0_steady_mm_s_n": steady, "wdm_zeros": _complex(np.roots(wdm_derived[0])),
                   "wdm_poles": _complex(np.roots(wdm_derived[1])), "max_g2_error": float(g2_errors.max()),
                   "printed_w0": {"s_w0_hinf_mm_n": printed_disturbance / MM, "steady_mm_s_n": printed_steady,
                                  "worst_case_bound_mm_n":
                                      rb.robust_performance_bound(p0, kp, ki, w1, printed_w0, wdm) / MM},
                   "weights": "W0 = P0's G2 and Wdm over the set's G2, both from the emulator's linearisation "
                              "(eq. 4.68, `hydrapod emulator calibrate`); W1 the fitted one"}
    doc = {"plants": source, "nominal": nominal, "well_posedness": posed, "pi": pi,
           "uncertainty": uncertainty, "performance": performance}
    disks = nyquist_disks(p0, w1)
    uncertainty["nyquist"] = {"disks": len(disks["w"]), "w_rad_s": [float(disks["w"][0]), float(disks["w"][-1])],
                              "plants_inside_disks": int(np.sum(np.all(errors <= np.abs(rb.response(*w1, w)) + 1e-12,
                                                                         axis=1)))}
    arrays = {"w": w, "errors": errors, "bound": bound, "w1": w1, "printed_w1": printed_w1,
              "loads": [p.load_kg for p in plants], "p0": p0, "plants": plants, "disks": disks}
    return doc, arrays


def format_robustness(doc: dict) -> str:
    n, pi, u, perf = doc["nominal"], doc["pi"], doc["uncertainty"], doc["performance"]
    lines = [f"# Robustness of the position PI (chapters 7.3-7.4), plants: {doc['plants']}", "",
             "## Nominal plant (eq. 7.10-7.13)", "",
             f"- {n['plant']} ({n['selected_by']}; {n['plants']} plants): b0 {n['b0']:.0f} 1/s^2, "
             f"b1 {n['b1']:.2f} 1/s, k01 {n['k01_mm_s_v']:.1f} (mm/s)/V; "
             f"P0 = {n['numerator_mm'][0]:.4g} / (s^3 + {n['denominator'][1]:.2f} s^2 "
             f"+ {n['denominator'][2]:.0f} s) mm/V",
             f"- best by eq. 7.10: {n['best_by_eq_7_10']}; {n['criterion']}",
             f"- thesis: {n['thesis']}; in this set it ranks {n['thesis_plant_rank']} "
             f"(sum F {n['thesis_plant_sum_F']})", "",
             "## Well-posedness (Table 7.1 / B.1): degree of numerator / denominator", "",
             "| controller | K/(1+KG1) | KG1/(1+KG1) | KG2/(1+KG1) | well-posed |", "|---|---|---|---|---|"]
    for kind, row in doc["well_posedness"].items():
        m = row["maps"]
        lines.append(f"| {kind} | {m['K/(1+KG1)']} | {m['KG1/(1+KG1)']} | {m['KG2/(1+KG1)']} | "
                     f"{'yes' if row['well_posed'] else '**no** (improper)'} |")
    imp = pi["thesis_poles_imply"]
    lines += ["", f"## PI Kp = {pi['kp_v_mm']:g} V/mm, Ki = {pi['ki_v_mm_s']:g} V/(mm s) (eq. 7.16-7.21)", "",
              f"- closed-loop poles on the nominal plant: {pi['poles']}; internally stable: {pi['internally_stable']}",
              f"- on the thesis's P0 (eq. 7.13): {pi['poles_on_thesis_plant']}",
              f"- thesis (eq. 7.21): {pi['thesis_poles']}: their characteristic polynomial has b1 {imp['b1']:.2f}, "
              f"b0 {imp['b0']:.0f}, Kp {imp['kp_v_mm']:.4f}, Ki {imp['ki_v_mm_s']:.4f}: the thesis's poles are "
              "those of a smaller Ki than the one it states",
              "- ||map||inf of eq. 7.17-7.20 (SI): " + ", ".join(f"{k} {v:.4g}" for k, v in pi["map_hinf"].items()),
              f"- every plant of the set stabilised by this PI: {pi['every_plant_stabilised']} "
              f"(slowest pole over the set: Re {pi['slowest_pole_real_over_set']:.3f} 1/s)",
              f"- its 10 mm step on each plant of the set (linear): overshoot "
              f"{pi['steps_on_plants']['overshoot_pct_min']:.1f}-{pi['steps_on_plants']['overshoot_pct_max']:.1f} % "
              f"(worst {pi['steps_on_plants']['overshoot_worst_plant']}), settling (5 %) at most "
              f"{pi['steps_on_plants']['settling_s_max']:.2f} s ({pi['steps_on_plants']['settling_worst_plant']})", "",
              "## Multiplicative uncertainty and robust stability (eq. 7.14-7.15, 7.22)", "",
              f"- largest |P/P0 - 1| over w in {u['range_rad_s']} rad/s: {u['max_error']:.3f} at "
              f"{u['max_error_at_rad_s']:.1f} rad/s",
              f"- fitted W1 (stable, minimum phase, 3rd order): zeros {u['w1_zeros']}, poles {u['w1_poles']}, "
              f"high-frequency gain {u['w1_numerator'][0]:.3f}; |W1| / bound >= {u['w1_over_bound_min']:.3f}",
              f"- **||W1 T||inf = {u['w1t_hinf']:.4f}** at {u['w1t_peak_rad_s']:.1f} rad/s: robustly stable "
              f"{u['robustly_stable']} (thesis: {u['thesis_w1t_hinf']})",
              f"- with eq. 7.15 as printed: ||W1 T||inf = {u['printed_w1']['w1t_hinf']:.2f}; that W1 peaks at "
              f"{u['printed_w1']['w1_peak']:.1f} ({u['printed_w1']['w1_peak_at_rad_s']:.1f} rad/s): "
              + u["printed_w1"]["note"], "",
              "## Robust performance (eq. 7.23-7.27)", "",
              f"- W0 (P0's G2, eq. 4.68 from the emulator's linearisation) = ({perf['w0_numerator_mm'][0]:.4g} s + "
              f"{perf['w0_numerator_mm'][1]:.4g}) / (s^3 + {perf['w0_denominator'][1]:.2f} s^2 + "
              f"{perf['w0_denominator'][2]:.0f} s) mm/N: {perf['w0_steady_mm_s_n']:.3g} mm/s per N at a fixed valve; "
              f"Wdm over the set's G2 (largest |G2/W0 - 1| {perf['max_g2_error']:.3f}): zeros {perf['wdm_zeros']}, "
              f"poles {perf['wdm_poles']}",
              f"- nominal ||S W0||inf = {perf['s_w0_hinf_mm_n']:.4g} mm/N at {perf['at_rad_s']:.1f} rad/s",
              f"- worst case over both uncertainty sets (pointwise bound): {perf['worst_case_bound_mm_n']:.4g} mm/N "
              f"(thesis ||Tyd||inf = {perf['thesis_tyd_hinf']:.4g}); {perf['weights']}",
              f"- eq. 7.23 as printed, read in mm/N: {perf['printed_w0']['steady_mm_s_n']:.3g} mm/s per N at a fixed "
              f"valve, 1/{perf['w0_steady_mm_s_n'] / perf['printed_w0']['steady_mm_s_n']:.0f} of the linearisation's "
              f"(||S W0||inf {perf['printed_w0']['s_w0_hinf_mm_n']:.4g} mm/N, worst case "
              f"{perf['printed_w0']['worst_case_bound_mm_n']:.4g}); read in m/N, "
              f"{perf['printed_w0']['steady_mm_s_n'] * 1e3 / perf['w0_steady_mm_s_n']:.2f}x it"]
    return "\n".join(lines) + "\n"


def plot_uncertainty(arrays: dict, path: Path) -> None:
    """Like Fig. 7.4: every plant's |P/P0 - 1|, their maximum, the fitted W1 (and the printed one)."""
    w = arrays["w"]
    fig, ax = plt.subplots(figsize=(7, 4))
    for row, load in zip(arrays["errors"], arrays["loads"]):
        ax.semilogx(w, row, color=colour_for_load(load), lw=0.6, alpha=0.6)
    ax.semilogx(w, arrays["bound"], "r--", lw=1.2, label="maximum error")
    ax.semilogx(w, np.abs(rb.response(*arrays["w1"], w)), "k", lw=1.5, label="fitted W1")
    printed = np.abs(rb.response(*arrays["printed_w1"], w))
    ax.semilogx(w, np.minimum(printed, 5.0), ":", color="gray", label="eq. 7.15 as printed (clipped at 5)")
    ax.set_xlabel("w [rad/s]")
    ax.set_ylabel("|P/P0 - 1|, |W1|")
    ax.set_ylim(0, 5)
    ax.legend(fontsize=8)
    ax.set_title("Multiplicative uncertainty (thesis Fig. 7.4); colour: load 0/3/6 kg")
    save(fig, path)


NYQUIST_W_RAD_S = (8.0, 400.0)       # the reduced diagram: P0's integrator leaves the plot below it
NYQUIST_DISKS = 40


def nyquist_disks(p0: Plant, w1: tuple[np.ndarray, np.ndarray]) -> dict:
    """The set Pi(s) = P0 (1 + W1 Delta) of eq. 7.14 at log-spaced frequencies: centres P0(jw)
    and radii |W1(jw) P0(jw)| (mm/V)."""
    w = np.geomspace(*NYQUIST_W_RAD_S, NYQUIST_DISKS)
    centre = p0.response(w) / MM
    return {"w": w, "centre": centre, "radius": np.abs(rb.response(*w1, w) * centre)}


def plot_nyquist(arrays: dict, path: Path) -> None:
    """Like Fig. 7.7: the nominal plant's Nyquist curve in red, the uncertainty disks in blue,
    every plant of the set (colour: load) inside them."""
    from matplotlib.patches import Circle
    w = np.geomspace(*NYQUIST_W_RAD_S, 600)
    fig, ax = plt.subplots(figsize=(6, 6))
    disks = arrays["disks"]
    for c, r in zip(disks["centre"], disks["radius"]):
        ax.add_patch(Circle((c.real, c.imag), r, fill=False, color="tab:blue", lw=0.6, alpha=0.7))
    for plant in arrays["plants"]:
        g = plant.response(w) / MM
        ax.plot(g.real, g.imag, color=colour_for_load(plant.load_kg), lw=0.5, alpha=0.6)
    g0 = arrays["p0"].response(w) / MM
    ax.plot(g0.real, g0.imag, "r", lw=1.8, label=f"P0 ({arrays['p0'].label})")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("Re P(jw) [mm/V]")
    ax.set_ylabel("Im P(jw) [mm/V]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    ax.set_title(f"Nyquist of Pi(s) = P0 (1 + W1 Delta), w {NYQUIST_W_RAD_S[0]:g}-{NYQUIST_W_RAD_S[1]:g} rad/s "
                 "(thesis Fig. 7.7)", fontsize=9)
    save(fig, path)


def schedule_doc(plants: list[Plant], source: str, kp_fraction: float, ti_fraction: float,
                 ki_scale: float = KI_DETUNING) -> tuple[dict, list]:
    tunings = tune(plants, kp_fraction, ti_fraction)
    rows = compare_with_table_7_2(tunings, chapter7()["table_7_2"])

    def span(key):
        values = [r[key] for r in rows]
        return [round(min(values), 3), round(max(values), 3)] if values else None

    zn = ziegler_nichols(thesis_plant(), kp_fraction, ti_fraction)
    stable = all(rb.internally_stable(t.plant, t.kp_v_m, ki_scale * t.ki_v_m_s) for t in tunings)
    detuning = {}
    for scale in KI_SCALES_FIG_7_12:                 # Fig. 7.12: the linear loop's 10 mm step per Ki scale
        steps = [rb.step_on_plant(t.plant, t.kp_v_m, scale * t.ki_v_m_s) for t in tunings]
        detuning[f"{scale:g}"] = {key: [round(min(s[key] for s in steps), 3), round(max(s[key] for s in steps), 3)]
                                  for key in ("overshoot_pct", "settling_s")}
    doc = {"plants": source, "rule": {"kp_over_ku": kp_fraction, "ti_over_tu": ti_fraction, "ki_scale": ki_scale},
           "points": len(tunings), "compared_with_table_7_2": rows,
           "kp_ratio": span("kp_ratio"), "ki_ratio": span("ki_ratio"),
           "thesis_kp_over_ku": span("thesis_kp_over_ku"), "thesis_ki_tu_over_kp": span("thesis_ki_tu_over_kp"),
           "every_loop_stable_with_detuned_ki": stable,
           # overshoot and settling ranges over the set: the thesis's 0.2 Ki gives ~25 % and ~0.5 s
           "ki_detuning_steps": detuning,
           # chapter 7.4.2's "Ziegler-Nichols on the nominal plant" by the same rule
           "nominal_plant": {"kp_v_mm": zn.kp_v_m * MM, "ki_v_mm_s": zn.ki_v_m_s * MM,
                             "detuned_ki_v_mm_s": ki_scale * zn.ki_v_m_s * MM,
                             "thesis_kp_v_mm": chapter7()["pi"]["kp_v_mm"],
                             "thesis_ki_v_mm_s": chapter7()["pi"]["ki_v_mm_s"]}}
    return doc, tunings


KI_SCALES_FIG_7_12 = (1.0, 0.5, 0.2, 0.1)
STEP_FIG_7_12_M = 0.010


def plot_ki_detuning(tunings: list, path: Path) -> None:
    """Like Fig. 7.12: (a) the Ziegler-Nichols PI's 10 mm step on every plant of the set;
    (b) on the thesis's nominal plant with Ki scaled by 1, 0.5, 0.2 and 0.1 (linear loop)."""
    from scipy import signal
    t = np.linspace(0.0, 0.4, 801)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for tuning in tunings:
        _, y = signal.step(rb.complementary(tuning.plant, tuning.kp_v_m, tuning.ki_v_m_s), T=t)
        axes[0].plot(t, 150.0 + y * STEP_FIG_7_12_M / MM, color=colour_for_load(tuning.plant.load_kg), lw=0.6)
    zn = ziegler_nichols(thesis_plant())
    for scale in KI_SCALES_FIG_7_12:
        _, y = signal.step(rb.complementary(zn.plant, zn.kp_v_m, scale * zn.ki_v_m_s), T=t)
        axes[1].plot(t, 150.0 + y * STEP_FIG_7_12_M / MM, lw=1.2, label=f"{scale:g} Ki")
    axes[0].set_title("(a) Ziegler-Nichols PI, every plant (colour: load)", fontsize=9)
    axes[1].set_title(f"(b) {zn.plant.label} (eq. 7.13's plant), Ki detuned", fontsize=9)
    for ax in axes:
        ax.set_xlabel("t [s] after the 10 mm step")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("y [mm]")
    axes[1].legend(fontsize=8)
    fig.suptitle("PI step responses (thesis Fig. 7.12), linear loop", fontsize=10)
    save(fig, path)


def format_schedule(doc: dict, path: str) -> str:
    lines = [f"schedule: {doc['points']} plants of {doc['plants']} -> {path}",
             f"  rule: Kp = {doc['rule']['kp_over_ku']:g} Ku, Ti = {doc['rule']['ti_over_tu']:.4g} Tu; "
             f"ki_scale {doc['rule']['ki_scale']:g}; every loop stable with the detuned Ki: "
             f"{doc['every_loop_stable_with_detuned_ki']}"]
    if doc["compared_with_table_7_2"]:
        lines += [f"  against Table 7.2 ({len(doc['compared_with_table_7_2'])} points): Kp x{doc['kp_ratio'][0]}-"
                  f"{doc['kp_ratio'][1]}, Ki x{doc['ki_ratio'][0]}-{doc['ki_ratio'][1]}",
                  f"  Table 7.2 itself is Kp = {doc['thesis_kp_over_ku'][0]}-{doc['thesis_kp_over_ku'][1]} Ku and "
                  f"Ki = ({doc['thesis_ki_tu_over_kp'][0]}-{doc['thesis_ki_tu_over_kp'][1]}) Kp / Tu on this set's "
                  f"plants (the classical rule: 0.45 Ku, 1.2 Kp / Tu)"]
    steps = doc["ki_detuning_steps"]
    lines.append("  10 mm step, linear loop, over the set (Fig. 7.12): " + "; ".join(
        f"{scale} Ki: overshoot {v['overshoot_pct'][0]:.0f}-{v['overshoot_pct'][1]:.0f} %, settling (5 %) "
        f"{v['settling_s'][0]:.2f}-{v['settling_s'][1]:.2f} s" for scale, v in steps.items()))
    n = doc["nominal_plant"]
    lines.append(f"  nominal plant (eq. 7.13): Kp {n['kp_v_mm']:.4f} V/mm, Ki {n['ki_v_mm_s']:.3f} "
                 f"(x{doc['rule']['ki_scale']:g}: "
                 f"{n['detuned_ki_v_mm_s']:.3f}) V/(mm s); thesis Kp {n['thesis_kp_v_mm']}, Ki {n['thesis_ki_v_mm_s']}")
    return "\n".join(lines)
