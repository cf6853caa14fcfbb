"""hex-kick: the hexapod's modes measured by pushing its platform (beyond the thesis).

The design basis of the computed-torque controller is the linearised plant of
`hydrapod design modes`. A push cannot see that plant (with the valves open it is
over-damped), so this experiment checks the same linearisation in the state a push can see,
through the bus, as a modal hammer test would on the rig: at each pose the controller goes to IDLE (the
valves HOLD with the load-holding valves closed: the legs are sealed oil columns), the host
pushes the platform for 20 ms (EMU_KICK), and the free response the recorder sees
(EMU_TRUTH) is fitted with a damped oscillation. Its frequency and damping ratio stand beside
the model's for the same state and push (`hil.design.modes.sealed_response`, fitted the same
way): the mechanism and the oil columns linearised at the pose, the chambers at the pressures
the valves' transducers read before the push (LEG_PRESSURE), each seal's bristles by
LuGre's law from the force they hold there (what the chambers push beyond the mechanism's
static load). The frequency and the damping ratio are asserted within 20 %.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from firmware_py.mechanics.geometry import default_geometry
from hil.experiments import circle_motion
from hil.logdata import LogData
from hil.metrics import damped_oscillation
from hil.plotting import plt, save
from hil.scenario import Analysis, Check, Figure, Scenario
from hil.scenarios.common import load_at, run_emulator_config
from protocol.enums import Command, KickAxis, State, WaypointFlag

# the push: the seals stay in pre-sliding (10 N slides them), the response ~0.5 mm against
# EMU_TRUTH's 0.025 mm steps
KICK_N = 3.0
KICK_S = 0.02
HOLD_S = 1.5                   # held by the controller on the pose before sealing
SETTLE_S = 0.6                 # after IDLE, before the push
OBSERVE_S = 1.5                # the free response fitted
FIT_SKIP_S = 0.01              # after the push ends
MOVE_S, MOVE_ACCEL_S = 2.0, 0.5
TOLERANCE = 0.20               # measured vs model, frequency and damping ratio (reported against it)
ONE_MODE_R2 = 0.97             # below: a second mode in the response (off centre, y moves with yaw)
FIT_R2_MIN = 0.95              # a push's response is a clean free oscillation (asserted)
CREEP_DAMPING = 0.9            # a fitted component this damped is the platform's creep, not a mode
AXES = (KickAxis.X, KickAxis.Y)
TRUTH_SIGNALS = {KickAxis.X: "X", KickAxis.Y: "Y", KickAxis.Z: "Z"}


def pushed_mode(modes: list[dict], axis: int) -> dict | None:
    """The model's mode a push along `axis` moves most (its unit-peak shape's largest share)."""
    return max(modes, key=lambda m: abs(float(m["shape"][axis])), default=None)


def free_mode(y: np.ndarray, period_s: float) -> tuple[dict, dict]:
    """The largest oscillating mode of a free response (one damped mode, or two where one does
    not fit: off centre y moves with yaw; a component damped beyond CREEP_DAMPING is the
    platform's creep after a sealing that moved it, not a mode) and the fit."""
    t = np.arange(len(y)) * period_s
    fit = damped_oscillation(t, y)
    if not fit["r2"] >= ONE_MODE_R2:
        fit = damped_oscillation(t, y, count=2)
    oscillating = [m for m in fit["modes"] if m["damping_ratio"] < CREEP_DAMPING]
    main = oscillating[0] if oscillating else {"frequency_hz": math.nan, "damping_ratio": math.nan,
                                               "amplitude": math.nan}
    return main, fit


def sealed_pressures(log: LogData, cycle: int, period_s: float) -> np.ndarray | None:
    """(2, 6) PA, PB of every leg's last LEG_PRESSURE before `cycle` within the settle (the
    sealed chambers the push meets), or None when a leg has none."""
    window = slice(max(cycle - int(SETTLE_S / period_s), 0), cycle)
    out = np.empty((2, 6))
    for i in range(6):
        series = log.get(f"LEG_PRESSURE_{i + 1}")
        for row, signal in enumerate(("PA", "PB")):
            values = series.per_cycle(log.n_cycles, signal)[window]
            values = values[~np.isnan(values)]
            if not len(values):
                return None
            out[row, i] = values[-1]
    return out


def bristle_forces(cfg, position_m, payload_kg: float, pressures: np.ndarray) -> np.ndarray:
    """What the seals' bristles hold at rest: the chambers' force less the static load."""
    from hil.design.modes import joint_space, pose_quaternion
    from plant_emulator.rigs import HexapodRig
    rig = HexapodRig(cfg)
    rig.set_load(payload_kg)
    static = joint_space(rig, position_m, pose_quaternion((0.0, 0.0, 0.0)))[1]
    return cfg.area_a_m2 * (pressures[0] - cfg.alpha * pressures[1]) - static


def kick_poses(short: bool) -> dict[str, tuple[float, float, float]]:
    """Home and (full run) the circle's start, the movements' farthest point from home."""
    geometry = default_geometry()
    poses = {"home": tuple(float(v) for v in geometry.home_position_m)}
    if not short:
        poses["circle start"] = tuple(float(v) for v in circle_motion(geometry).parts[0][1])
    return poses


class HexapodKick(Scenario):
    name = "hex-kick"
    title = "the hexapod's modes by a push on the sealed platform, beside the linear model"
    chapter = "beyond the thesis (docs/MEASUREMENTS.md \"Hexapod modes\")"
    rig = "hexapod"
    pacings = ("lockstep",)              # the same cycles every run; a fit needs no wall clock
    controllers = ("computed-torque",)   # it only brings the platform to the poses (on them: 0.1 mm)

    def script(self, run) -> None:
        host = run.host
        for pose in kick_poses(run.short).values():
            host.waypoint(pose, segment_time_s=MOVE_S, accel_time_s=MOVE_ACCEL_S,
                          flags=WaypointFlag.LAST | WaypointFlag.START)
            run.wait_s(MOVE_S + 0.3)
            run.wait_motion_done(5.0)
            run.wait_s(HOLD_S)                             # at rest on the pose before sealing
            host.command(Command.DISABLE)                  # valves HOLD: the chambers sealed
            host.wait_state(State.IDLE, max_cycles=run.cycles(1.0))
            run.wait_s(SETTLE_S)
            for axis in AXES:
                host.kick(axis, KICK_N, KICK_S)
                run.wait_s(OBSERVE_S)
            run.enable()
            host.wait_state(State.READY, max_cycles=run.cycles(2.0))

    def analyze(self, log: LogData, out: Path | None, rate_hz: float = 500.0) -> Analysis:
        # the modal model here: it loads MuJoCo's model and SciPy, which the hosts that only
        # list or run scenarios need not import (0.8 s of every `hydrapod` start)
        from hil.design.modes import sealed_modes, sealed_response

        period = 1.0 / rate_hz
        truth = log.get("EMU_TRUTH")
        cfg = run_emulator_config(log)
        rows, models = [], {}
        for event in log.events_named("EMU_KICK"):
            axis = KickAxis(int(event.values["AXIS"]))
            if axis not in TRUTH_SIGNALS:
                continue
            k0 = event.cycle
            before = slice(max(k0 - int(0.2 / period), 0), k0)
            pose = tuple(round(float(np.nanmean(truth.per_cycle(log.n_cycles, s)[before])), 4) for s in "XYZ")
            push_s = float(event.values["DURATION"])
            start = int(math.ceil(push_s / period)) + 1 + int(FIT_SKIP_S / period)   # after the push
            stop = int(OBSERVE_S / period) - 2
            y = truth.per_cycle(log.n_cycles, TRUTH_SIGNALS[axis])[k0 + start:min(k0 + stop, log.n_cycles)]
            main, fit = free_mode(y, period)
            load = load_at(log, k0)
            load = cfg.hexapod.payload_kg if load is None else load     # set at start, or by EMU_CTRL
            pressures = sealed_pressures(log, k0, period)
            # the model: the same push on the sealed platform in the state the log shows
            model = None if pressures is None else free_mode(sealed_response(
                cfg, np.array(pose), pressures, int(axis), float(event.values["FORCE"]), push_s, OBSERVE_S,
                payload_kg=load, period_s=period)[start:stop], period)[0]
            if (pose, load) not in models:
                models[(pose, load)] = sealed_modes(cfg, np.array(pose), payload_kg=load)
            undeflected = pushed_mode(models[(pose, load)], int(axis))
            rows.append({"pose_mm": [round(v * 1e3, 1) for v in pose], "load_kg": load, "axis": axis.name,
                         "push_n": round(float(event.values["FORCE"]), 2), **{k: round(v, 4) for k, v in main.items()},
                         "r2": round(fit["r2"], 4), "modes_fitted": len(fit["modes"]),
                         "other_modes": [{k: round(v, 4) for k, v in m.items()} for m in fit["modes"]
                                         if m is not main],
                         "model_frequency_hz": round(model["frequency_hz"], 4) if model and math.isfinite(
                             model["frequency_hz"]) else None,
                         "model_damping_ratio": round(model["damping_ratio"], 4) if model and math.isfinite(
                             model["frequency_hz"]) else None,
                         "undeflected_model_hz": round(undeflected["frequency_hz"], 4) if undeflected else None,
                         "bristle_force_n": None if pressures is None else [
                             round(float(f), 2) for f in bristle_forces(cfg, np.array(pose), load, pressures)],
                         "_t": np.arange(len(y)) * period, "_y": y})
        checks = []
        if not rows:
            checks.append(Check("pushes found in the log", False, "0", ">= 1"))
        for r in rows:
            where = f"{r['axis']} at ({', '.join(f'{v:g}' for v in r['pose_mm'])}) mm"
            checks.append(Check(f"{where}: the response fitted as a free oscillation", r["r2"] >= FIT_R2_MIN,
                                f"r2 {r['r2']:.3f} ({r['modes_fitted']} mode(s))", f">= {FIT_R2_MIN}"))
            # the model of the state each sealing leaves (docs/MEASUREMENTS.md "Hexapod modes")
            if r["model_frequency_hz"] is None:
                checks.append(Check(f"{where}: a model mode along it", False, "none", "one"))
                continue
            for name, measured, model in (("frequency", r["frequency_hz"], r["model_frequency_hz"]),
                                          ("damping ratio", r["damping_ratio"], r["model_damping_ratio"])):
                ratio = measured / model if model else math.nan
                checks.append(Check(f"{where}: {name}", bool(abs(ratio - 1.0) <= TOLERANCE),
                                    f"{measured:.3g} (model {model:.3g}, x{ratio:.2f}; {r['modes_fitted']}-mode fit "
                                    f"r2 {r['r2']:.3f})",
                                    f"within {TOLERANCE:.0%} of the model"))
        table = ["| pose mm | axis | push N | f Hz | model f Hz | zeta | model zeta | amplitude mm | fit r2 |",
                 "|---|---|---|---|---|---|---|---|---|"]
        table += [f"| {', '.join(f'{v:g}' for v in r['pose_mm'])} | {r['axis']} | {r['push_n']:g} | "
                  f"{r['frequency_hz']:.3f} | {r['model_frequency_hz']} | {r['damping_ratio']:.3f} | "
                  f"{r['model_damping_ratio']} | {r['amplitude'] * 1e3:.3f} | {r['r2']:.3f} |" for r in rows]
        figures = [self._plot(rows, out)] if out is not None and rows else []
        metrics = {"kicks": [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows]}
        thesis = {"note": "beyond the thesis: the modal model of `hydrapod design modes` checked through the bus"}
        return Analysis(metrics, thesis, checks, figures, ["\n".join(table)])

    def _plot(self, rows, out: Path) -> Figure:
        fig, axes = plt.subplots(len(rows), 1, figsize=(7, 1.8 * len(rows)), squeeze=False)
        for ax, r in zip(axes[:, 0], rows):
            ax.plot(r["_t"], (r["_y"] - np.nanmean(r["_y"])) * 1e3, lw=0.8)
            ax.set_title(f"{r['axis']} at {r['pose_mm']} mm: {r['frequency_hz']:.2f} Hz (model "
                         f"{r['model_frequency_hz']}), zeta {r['damping_ratio']:.3f} "
                         f"(model {r['model_damping_ratio']})", fontsize=7)
            ax.set_ylabel("mm")
            ax.grid(alpha=0.3)
        axes[-1, 0].set_xlabel("t after the push [s]")
        path = out / "hex_kick.png"
        save(fig, path)
        return Figure(path.name, "The platform's free response to a 2 N, 20 ms push with the valves in HOLD",
                      "none in the thesis: the modal model's check (docs/MEASUREMENTS.md \"Hexapod modes\")")
