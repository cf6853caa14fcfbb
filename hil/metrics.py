"""Metrics computed from decoded logs: step response, tracking error, IAE, timing.

Pure functions of arrays (SI in, SI out); the scenarios pick the windows.
"""

from __future__ import annotations

import math

import numpy as np

from hil.logdata import LogData
from protocol.enums import Fault, State

SETTLING_BAND = 0.05          # settling time: last exit from +/- 5 % of the step


def step_response(t_s, y, y0: float, step: float, band: float = SETTLING_BAND) -> dict:
    """Overshoot (% of the step), settling time (s, last exit from the band), rise time 10-90 %."""
    t_s, y = np.asarray(t_s, float), np.asarray(y, float)
    response = (y - y0) / step
    overshoot = max(0.0, float(np.nanmax(response) - 1.0) * 100.0)
    outside = np.nonzero(np.abs(response - 1.0) > band)[0]
    settling = float(t_s[outside[-1] + 1]) if len(outside) and outside[-1] + 1 < len(t_s) else (
        float("nan") if len(outside) else 0.0)
    above10 = np.nonzero(response >= 0.1)[0]
    above90 = np.nonzero(response >= 0.9)[0]
    rise = float(t_s[above90[0]] - t_s[above10[0]]) if len(above10) and len(above90) else float("nan")
    final = float(np.mean(response[-max(len(response) // 10, 1):]))
    return {"overshoot_pct": overshoot, "settling_s": settling, "rise_s": rise,
            "steady_error_pct": (final - 1.0) * 100.0}


def _free_response(t, params, count):
    """sum_k A_k e^(-zeta_k w_k t) sin(w_k sqrt(1 - zeta_k^2) t + phi_k) + c0 + c1 t."""
    out = params[-2] + params[-1] * t
    for k in range(count):
        amplitude, zeta, frequency, phase = params[4 * k:4 * k + 4]
        w = 2 * math.pi * frequency
        out = out + amplitude * np.exp(-zeta * w * t) * np.sin(w * math.sqrt(max(1.0 - zeta * zeta, 1e-9)) * t + phase)
    return out


def damped_oscillation(t_s, y, count: int = 1) -> dict:
    """The least-squares fit of `count` (1 or 2) damped modes on a slow drift to a free
    response: per mode frequency_hz (undamped, w / 2 pi), damping_ratio, amplitude (largest
    first), and the fit's r2. Started from several frequencies around the zero crossings'
    estimate (two modes: pairs a fifth to an octave apart)."""
    from scipy.optimize import curve_fit
    t_s, y = np.asarray(t_s, float), np.asarray(y, float)
    ok = np.isfinite(y)
    t_s, y = t_s[ok], y[ok]
    centred = y - np.mean(y)
    total = float(np.sum(centred ** 2))
    crossings = np.flatnonzero(np.diff(np.sign(centred)) != 0)
    span = t_s[-1] - t_s[0] if len(t_s) > 1 else 1.0
    guess = max(len(crossings), 1) / (2 * span)
    size = float(np.max(np.abs(centred))) if len(centred) else 0.0
    if count == 1:
        starts = [[f] for f in (0.5 * guess, guess, 2 * guess, 4 * guess)]
    else:
        starts = [[f, r * f] for f in (0.7 * guess, guess) for r in (1.5, 2.0)]
    lower = [0.0, 0.0, 0.0, -np.inf] * count + [-np.inf, -np.inf]
    upper = [np.inf, 0.99, np.inf, np.inf] * count + [np.inf, np.inf]
    best, best_residual = None, np.inf
    for frequencies in starts:
        for phase in (0.5, 2.0, -1.0):
            p0 = [v for f in frequencies for v in (size / count, 0.1, f, phase)] + [float(np.mean(y)), 0.0]
            try:
                p, _ = curve_fit(lambda t, *q: _free_response(t, q, count), t_s, y, p0=p0, bounds=(lower, upper),
                                 maxfev=5000)
            except (RuntimeError, ValueError):
                continue
            residual = float(np.sum((_free_response(t_s, p, count) - y) ** 2))
            if residual < best_residual:
                best, best_residual = p, residual
    if best is None or total == 0.0:
        return {"modes": [], "r2": math.nan}
    modes = sorted(({"frequency_hz": float(best[4 * k + 2]), "damping_ratio": float(best[4 * k + 1]),
                     "amplitude": float(best[4 * k])} for k in range(count)), key=lambda m: -m["amplitude"])
    return {"modes": modes, "r2": 1.0 - best_residual / total}


def iae(error, period_s: float) -> float:
    """Integral of the absolute error, rectangle rule on the cycle grid (NaN samples skipped)."""
    return float(np.nansum(np.abs(error)) * period_s)


def percentiles(values, qs=(50, 99)) -> dict:
    values = np.asarray(values, float)
    values = values[np.isfinite(values)]
    if not len(values):
        return {f"p{q}": None for q in qs} | {"max": None, "n": 0}
    return {f"p{q}": float(np.percentile(values, q)) for q in qs} | {"max": float(values.max()), "n": len(values)}


def ctrl_status_timing(log: LogData) -> dict:
    """From CTRL_STATUS (every 16th SYNC): the controller's own period error and compute time
    (each the max over its 16-cycle window), overruns (unwrapped from modulo 256)."""
    status = log.get("CTRL_STATUS")
    if not len(status):
        return {"windows": 0, "overruns": None}
    wraps = np.diff(status["OVERRUNS"]) < 0
    overruns = int(status["OVERRUNS"][-1] + 256 * np.count_nonzero(wraps))
    return {"windows": len(status), "overruns": overruns,
            "period_error_us": in_us(percentiles(status["PERIOD_ERROR_MAX"])),
            "compute_time_us": in_us(percentiles(status["COMPUTE_TIME_MAX"]))}


# A fault this many cycles after a machine stall is the stall's: two CTRL_STATUS windows
# (the overrun counter is reported every 16th cycle), and SENSOR_TIMEOUT's 5-cycle count fits.
STALL_WINDOW_CYCLES = 32
STALL_SYNC_GAP_PERIODS = 3.0    # a SYNC interval this long at the recorder: the bus's side stalled
# a sensor frame this long after its SYNC missed the controller's collection window
# ([timing].sync_window_fraction): the nodes' process (the emulator) was not running
STALL_LATE_FRAME_PERIODS = 0.6
LEG_STATE_NAMES = tuple(f"LEG_STATE_{leg}" for leg in range(1, 7))


def overrun_counts(log: LogData) -> tuple[np.ndarray, np.ndarray]:
    """(cycle, overruns so far) at each CTRL_STATUS, the modulo-256 counter unwrapped."""
    status = log.get("CTRL_STATUS")
    counter = np.asarray(status["OVERRUNS"], np.int64)
    wraps = np.concatenate(([0], np.cumsum(np.diff(counter) < 0)))
    return np.asarray(status.cycle, np.int64), counter + 256 * wraps


def fault_transitions(log: LogData) -> list[tuple[float, int, int]]:
    """(time, cycle, fault code) of every CTRL_STATUS that first shows a fault."""
    s = log.get("CTRL_STATUS")
    faulted = s["STATE"] == State.FAULT
    start = np.flatnonzero(faulted & ~np.concatenate(([False], faulted[:-1])))
    return [(float(s.time_s[i]), int(s.cycle[i]), int(s["FAULT_CODE"][i])) for i in start]


def after_machine_stall(log: LogData, cycle: int, period_s: float) -> bool:
    """Whether the machine stalled in the STALL_WINDOW_CYCLES before `cycle` (a fault reported
    there): the controller counted an overrun in the status windows covering them, the
    recorder saw a SYNC interval over STALL_SYNC_GAP_PERIODS, or sensor frames reached the bus
    more than STALL_LATE_FRAME_PERIODS after their SYNC (the emulator was not running: its
    frames of ~10 ms came in one burst). On a shared machine without an RT kernel each can
    starve the controller of a few cycles' frames; a fault after one is the machine's, and is
    counted as such, not as the fault's cause."""
    cycles, overruns = overrun_counts(log)
    start = cycle - STALL_WINDOW_CYCLES
    before = np.flatnonzero(cycles < start)
    upto = np.flatnonzero(cycles <= cycle + 16)       # the fault's own window reports it
    if len(upto) and overruns[upto[-1]] > (overruns[before[-1]] if len(before) else 0):
        return True
    lo, hi = max(start, 0), min(cycle + 1, log.n_cycles)
    sync = log.sync_time_s[lo:hi]
    if np.any(np.diff(sync[np.isfinite(sync)]) > STALL_SYNC_GAP_PERIODS * period_s):
        return True
    return late_sensor_frames(log, lo, hi, period_s) > 0


def realtime_paced(log: LogData, period_s: float) -> bool:
    """Whether the log's SYNCs came on the period's grid (realtime pacing), not as soon as each
    exchange was over (lockstep, where a long SYNC gap is no machine stall)."""
    sync = log.sync_time_s[np.isfinite(log.sync_time_s)]
    return len(sync) > 2 and abs(float(np.median(np.diff(sync))) - period_s) < 0.05 * period_s


def split_faults(log: LogData, period_s: float) -> tuple[list[tuple[int, str]], list[tuple[int, str]]]:
    """The controller's faults as (cycle, name): (the machine's, the others). A fault is the
    machine's in a realtime-paced log when it is OVERRUN (the stall watchdog) or follows a
    machine stall (`after_machine_stall`)."""
    realtime = realtime_paced(log, period_s)
    stalled, other = [], []
    for _, cycle, code in fault_transitions(log):
        machine = realtime and (code == Fault.OVERRUN or after_machine_stall(log, cycle, period_s))
        (stalled if machine else other).append((cycle, Fault(code).name))
    return stalled, other


def faults_in_windows(log: LogData, period_s: float, windows) -> list[str]:
    """The faults in (start, end) wall-clock windows of repeated starts or recoveries that no
    machine stall explains (a fault reaches CTRL_STATUS up to 16 cycles after it latched)."""
    if not windows:
        return []
    _, others = split_faults(log, period_s)
    times = {cycle: t for t, cycle, _ in fault_transitions(log)}
    return [name for cycle, name in others
            if any(start <= times[cycle] <= end + 16 * period_s for start, end in windows)]


def late_sensor_frames(log: LogData, lo: int, hi: int, period_s: float) -> int:
    """LEG_STATE frames of cycles [lo, hi) on the bus more than STALL_LATE_FRAME_PERIODS after
    their cycle's SYNC."""
    late = 0
    for name in LEG_STATE_NAMES:
        series = log.get(name)
        inside = (series.cycle >= lo) & (series.cycle < hi)
        if inside.any():
            delay = series.time_s[inside] - log.sync_time_s[series.cycle[inside]]
            late += int(np.count_nonzero(delay > STALL_LATE_FRAME_PERIODS * period_s))
    return late


def in_us(stats: dict) -> dict:
    """Seconds -> microseconds (0.1 us) for the float entries of a `percentiles` result."""
    return {k: (round(v * 1e6, 1) if isinstance(v, float) else v) for k, v in stats.items()}


def last_value_before(series_cycles, series_values, cycle: int, default=np.nan):
    """The value of the last frame at or before `cycle`."""
    idx = np.searchsorted(series_cycles, cycle, side="right") - 1
    return series_values[idx] if idx >= 0 else default
