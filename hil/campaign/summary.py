"""The campaign's summary: per controller the distribution of each reported metric, a map of
each over the two parameters that vary most, and the worst runs with links to their output.
report.md beside the table; the plots as PNG."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from hil.campaign.execute import METRICS_PREFIX

WORST = 5


def _numbers(rows: list[dict], column: str) -> np.ndarray:
    return np.array([float(r[column]) if isinstance(r.get(column), (int, float)) and r.get(column) is not None
                     else np.nan for r in rows])


def reported_metrics(rows: list[dict], chosen: tuple[str, ...]) -> list[str]:
    """The metric columns to report: the spec's (`metric.<name>`), else every numeric one."""
    present = sorted({k for r in rows for k, v in r.items() if k.startswith(METRICS_PREFIX)
                      and isinstance(v, float)})
    if chosen:
        return [METRICS_PREFIX + m for m in chosen if METRICS_PREFIX + m in present]
    return present


def varying_params(rows: list[dict]) -> list[str]:
    """Parameter columns with more than one value, most values first."""
    params = sorted({k for r in rows for k in r if k.startswith("param.") and k not in ("param.controller",
                                                                                          "param.draw")})
    counts = {p: len({r.get(p) for r in rows}) for p in params}
    return sorted((p for p in params if counts[p] > 1), key=lambda p: -counts[p])


def summarize(rows: list[dict], chosen: tuple[str, ...]) -> dict:
    """Per controller and metric: n, mean, worst (max) and its run."""
    ok = [r for r in rows if r.get("status") in ("ok", "failed")]
    controllers = sorted({str(r.get("param.controller", "-")) for r in ok})
    table: dict = {}
    for metric in reported_metrics(ok, chosen):
        for controller in controllers:
            mine = [r for r in ok if str(r.get("param.controller", "-")) == controller]
            values = _numbers(mine, metric)
            finite = np.isfinite(values)
            beyond = np.isposinf(values)               # e.g. a settling time: never within the window
            if not finite.any() and not beyond.any():
                continue
            worst = int(np.flatnonzero(beyond)[0]) if beyond.any() else int(np.nanargmax(values))
            table.setdefault(metric.removeprefix(METRICS_PREFIX), {})[controller] = {
                "n": int(finite.sum() + beyond.sum()), "never": int(beyond.sum()),
                "mean": float(np.mean(values[finite])) if finite.any() else math.nan,
                "min": float(np.min(values[finite])) if finite.any() else math.nan,
                "max_finite": float(np.max(values[finite])) if finite.any() else math.nan,
                "max": float(values[worst]), "worst_run": mine[worst]["run_id"], "worst_dir": mine[worst]["out_dir"]}
    return table


def design_robustness(table: dict, controller_config: dict) -> str:
    """sha-step: the PI's empirical worst overshoot and settling beside the linear PI loop's
    on Table A.3's 33 identified plants, with the controller's PI gains."""
    from firmware_py.config import load_config
    from hil.design.plants import table_a3_plants
    from hil.design.robustness import steps_on_plants
    cfg = load_config(None, controller_config or None)
    linear = steps_on_plants(table_a3_plants(), cfg.pi.kp_v_m, cfg.pi.ki_v_m_s)
    pi_os = table.get("overshoot_pct_max", {}).get("pi", {})
    pi_ts = table.get("settling_s_max", {}).get("pi", {})
    if not pi_os or not pi_ts:
        return "no PI run with overshoot and settling in the table"
    settled = f"{pi_ts['max_finite']:.2f} s" + (f" ({pi_ts['never']} never within the window)"
                                                 if pi_ts["never"] else "")
    return (f"PI, worst over the runs: overshoot {pi_os['max']:.1f} %, settling {settled}; "
            f"the linear loop on Table A.3's plants: overshoot {linear['overshoot_pct_min']:.1f}-"
            f"{linear['overshoot_pct_max']:.1f} % (worst {linear['overshoot_worst_plant']}), settling at most "
            f"{linear['settling_s_max']:.2f} s ({linear['settling_worst_plant']}).")


def write_report(out: Path, rows: list[dict], summary: dict, chosen: tuple[str, ...], plots: bool = True,
                 compare: str | None = None, controller_config: dict | None = None) -> Path:
    table = summarize(rows, chosen)
    comparison = design_robustness(table, controller_config or {}) if compare == "design-robustness" else ""
    figures = _plots(out, rows, chosen) if plots and rows else []
    lines = [f"# Campaign {summary['campaign']} ({summary['scenario']})", "",
             f"{summary['runs']} runs: {summary['ok']} ok, {summary['failed']} failed, {summary['hung']} hung, "
             f"{summary['spoiled']} spoiled by load, "
             f"{summary['error']} errors; " + (f"{summary['ran']} ran now on {summary['workers']} workers in "
                                               f"{summary['wall_s']} s ({summary['runs_per_minute']} runs/min)"
                                               if summary["ran"] else "none ran now (all in the table)")
             + ". Table: `results.parquet`, `results.csv`.",
             "", "| metric | controller | runs | mean | min | max | never settled / inf | worst run |",
             "|---|---|---|---|---|---|---|---|"]
    for metric, per in table.items():
        for controller, s in per.items():
            lines.append(f"| {metric} | {controller} | {s['n']} | {s['mean']:.4g} | {s['min']:.4g} | "
                         f"{s['max_finite']:.4g} | {s['never']} | [{s['worst_run']}]({_rel(out, s['worst_dir'])}) |")
    if comparison:
        lines += ["", "## Beside the linear prediction (`hydrapod design robustness`)", "", comparison]
    bad = [r for r in rows if r.get("status") != "ok"]
    if bad:
        lines += ["", "## Runs not ok", "", "| run | status | reason |", "|---|---|---|"]
        lines += [f"| [{r['run_id']}]({_rel(out, r['out_dir'])}) | {r.get('status')} | {r.get('reason') or ''} |"
                  for r in bad[:50]]
    for metric in reported_metrics(rows, chosen)[:4]:
        values = _numbers(rows, metric)
        order = [i for i in np.argsort(-np.nan_to_num(values, nan=-np.inf))[:WORST] if np.isfinite(values[i])]
        if not order:
            continue
        lines += ["", f"## Worst {metric.removeprefix(METRICS_PREFIX)}", "",
                  "| value | run | parameters |", "|---|---|---|"]
        for i in order:
            r = rows[i]
            params = ", ".join(f"{k.removeprefix('param.')}={r[k]}" for k in sorted(r) if k.startswith("param."))
            lines.append(f"| {values[i]:.4g} | [{r['run_id']}]({_rel(out, r['out_dir'])}) | {params} |")
    if figures:
        lines += ["", "## Figures", ""] + [f"![{f.stem}]({f.name})" for f in figures]
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _rel(out: Path, target: str) -> str:
    try:
        return str(Path(target).relative_to(out.resolve()))
    except ValueError:
        return target


def _plots(out: Path, rows: list[dict], chosen: tuple[str, ...]) -> list[Path]:
    from hil.plotting import plt, save
    figures = []
    metrics = reported_metrics(rows, chosen)[:4]
    controllers = sorted({str(r.get("param.controller", "-")) for r in rows})
    for metric in metrics:
        name = metric.removeprefix(METRICS_PREFIX)
        data = [_numbers([r for r in rows if str(r.get("param.controller", "-")) == c], metric) for c in controllers]
        data = [d[np.isfinite(d)] for d in data]
        if not any(len(d) for d in data):
            continue
        fig, ax = plt.subplots(figsize=(6, 3.5))
        ax.boxplot([d if len(d) else [math.nan] for d in data], tick_labels=controllers)
        ax.set_ylabel(name)
        ax.set_title(f"{name} per controller ({sum(len(d) for d in data)} runs)")
        figures.append(out / f"dist_{_safe(name)}.png")
        save(fig, figures[-1])
    varying = varying_params(rows)
    if len(varying) >= 2 and metrics:
        px, py = varying[0], varying[1]
        for metric in metrics[:2]:
            name = metric.removeprefix(METRICS_PREFIX)
            fig, axes = plt.subplots(1, len(controllers), figsize=(4.5 * len(controllers), 3.8), squeeze=False)
            for ax, controller in zip(axes[0], controllers):
                mine = [r for r in rows if str(r.get("param.controller", "-")) == controller]
                x, y, z = _numbers(mine, px), _numbers(mine, py), _numbers(mine, metric)
                shown = np.isfinite(x) & np.isfinite(y) & np.isfinite(z)
                sc = ax.scatter(x[shown], y[shown], c=z[shown], cmap="viridis", s=40)
                fig.colorbar(sc, ax=ax, label=name)
                ax.set_xlabel(px.removeprefix("param."))
                ax.set_ylabel(py.removeprefix("param."))
                ax.set_title(controller)
            figures.append(out / f"map_{_safe(name)}.png")
            save(fig, figures[-1])
    return figures


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)
