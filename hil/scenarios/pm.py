"""pm-diagonal and pm-circle: thesis 11.5, the hexapod's two movements with PI+P (adaptive)
and model-based control; IAE per axis of the end-effector position."""

from __future__ import annotations

import math
from abc import abstractmethod
from pathlib import Path

import numpy as np

from firmware_py.mechanics.geometry import default_geometry
from firmware_py.mechanics.kinematics import DirectKinematics
from firmware_py.motion_control.time_scaling import rule_of
from hil.experiments import (
    IAE_FACTOR_MAX,
    MAX_ERROR_MM,
    MOVEMENT_OVERRIDES,
    THESIS_MOVEMENTS,
    Motion,
    circle_motion,
    diagonal_motion,
    movement_waypoints,
)
from hil.host import HostError, PlatformNotHeld
from hil.logdata import LogData
from hil.metrics import iae, split_faults
from hil.plotting import plt, save
from hil.reference_rebuild import clock_agreement, rebuild
from hil.runner import merge_sections
from hil.scenario import Analysis, Check, Figure, Scenario
from hil.scenarios.common import (
    NAME_OF_CONTROLLER,
    NEW_CONTROLLER,
    THESIS_PLATFORM_LIMITS,
    controller_at,
    run_controller_config,
)
from program.errors import UserInputError
from protocol.enums import Ack, Command, Fault, State, WaypointFlag

AXES = ("x", "y", "z")
SETTLE_AFTER_S = 0.5            # the IAE window ends this long after the movement's last point
RETURN_TIME_S, RETURN_ACCEL_S = 1.5, 0.3
THESIS_NAMES = {"adaptive": "iae_pi_plus_p", "model-based": "iae_model_based"}
THESIS_CONTROLLERS = tuple(THESIS_NAMES)     # at the thesis's timing they may fault: reported
RETIMES = 8                      # `--time-scale auto`: refusals answered by sending the movement slower
# realtime: a movement a fault cut short is repeated (after RESET + ENABLE) at most this often;
# the analysis judges from the log whether a machine stall caused the fault
MAX_ATTEMPTS = 3


class PlatformMovement(Scenario):
    rig = "hexapod"
    controllers = ("adaptive", "model-based", NEW_CONTROLLER)
    short_controllers = (NEW_CONTROLLER,)
    controller_overrides = MOVEMENT_OVERRIDES
    motion_name = ""
    thesis: dict = {}
    # the thesis's ta/tm; `--time-scale` runs them slower (the thesis's two controllers complete
    # both movements at 2: docs/MEASUREMENTS.md "Hexapod gains")
    time_scale = 1.0
    time_scalable = True
    platform_lost = False            # a thesis controller left it where the legs cannot hold it
    retime_on_refusal = False        # `--time-scale auto`: a refusal's TIME_SCALE is taken

    @abstractmethod
    def thesis_motion(self) -> Motion:
        """The thesis's movement (chapter 11.3) at the thesis's timing."""

    def motion(self) -> Motion:
        """The movement as run: the thesis's, `time_scale` times slower."""
        return self.thesis_motion().scaled(self.time_scale)

    def script(self, run) -> None:
        self.platform_lost = False
        for controller in self.chosen(run):
            if self.platform_lost:
                run.notes.append(f"{controller}: not run (the platform is where the legs cannot hold it)")
                continue
            run.select(controller)
            for attempt in range(1, MAX_ATTEMPTS + 1):
                try:
                    self._move(run, self.motion())     # retimed by a refusal for the one before
                    if run.host.state is not State.FAULT:
                        break
                    error: Exception = HostError("the controller faulted during the movement")
                except HostError as failure:
                    error = failure
                if run.host.state is not State.FAULT:
                    raise error
                fault = Fault(run.host.fault_code).name
                if run.pacing == "realtime" and attempt < MAX_ATTEMPTS:
                    run.notes.append(f"{controller}: fault {fault} during attempt {attempt} (realtime; whether a "
                                     f"machine stall caused it is judged from the log): recovered, the movement "
                                     f"repeated")
                    run.recover_from_fault()
                    continue
                if controller not in THESIS_CONTROLLERS:
                    raise error
                try:
                    run.recover_from_fault()
                    after = "recovered, the next controller runs"
                except PlatformNotHeld as lost:
                    after = f"the platform is where the legs cannot hold it ({lost}): the run ends there"
                    self.platform_lost = True
                run.notes.append(f"{controller}: fault {fault} during the movement at {self.time_scale:g} x the "
                                 f"thesis's timing: its figures are of the part before; {after}")
                break

    def configure_for(self, controllers: tuple[str, ...]) -> str | None:
        """The thesis's per-leg controllers swing the platform up to ~100 mm on these movements
        (docs/MEASUREMENTS.md "Hexapod gains"): with them in the run, the platform's tracking
        bound is widened so that the thesis's experiment runs as on its rig."""
        if not set(controllers) & set(THESIS_CONTROLLERS):
            return None
        self.controller_overrides = merge_sections(self.controller_overrides, THESIS_PLATFORM_LIMITS)
        limits = THESIS_PLATFORM_LIMITS["limits"]
        return (f"the thesis's controllers in the run: the platform's tracking bound widened to "
                f"{limits['platform_error_max_mm']:g} mm and {limits['platform_angle_max_deg']:g} deg for all")

    def planned_time_scale(self, controller_sections: dict, thesis_where_it_fits: bool = False) -> tuple[float, str]:
        """The planned time scale of the movement for the controller configured with these
        sections (`hil.design.capacity.plan`: EDGE_MARGIN above the fastest it accepts), or 1 where
        `thesis_where_it_fits` and it accepts that; and how it was found. UserInputError when
        none within the accepted range fits."""
        from hil.design.capacity import EDGE_MARGIN, PLAN_SCALES, accepted, plan
        cfg = self._controller_config(controller_sections)
        found = plan(cfg, self.thesis_motion())
        declared = (f"payload {cfg.hexapod.payload_kg:g} kg, supply "
                    f"{cfg.hydraulic_model.supply_pressure_pa / 1e5:g} bar declared")
        if not math.isfinite(found.time_scale):
            option = "fit" if thesis_where_it_fits else "auto"
            raise UserInputError(f"--time-scale {option}: no time scale within {PLAN_SCALES[0]:g}-{PLAN_SCALES[1]:g} "
                                 f"fits {self.name} with {declared}: {found.reason}")
        margin_pct = (EDGE_MARGIN - 1.0) * 100.0
        how = f"{margin_pct:g} % above the smallest the controller's capacity check accepts, {declared}"
        if thesis_where_it_fits and accepted(cfg, self.thesis_motion(), 1.0):
            return 1.0, f"the thesis's timing: it fits ({how}: {found.time_scale:g})"
        return found.time_scale, how

    def _move(self, run, motion: Motion) -> None:
        """To the exact home pose, so the movement starts from a known reference; then the
        movement, queued, and its settling."""
        run.host.waypoint(default_geometry().home_position_m, segment_time_s=RETURN_TIME_S,
                          accel_time_s=RETURN_ACCEL_S, flags=WaypointFlag.LAST | WaypointFlag.START)
        run.wait_s(RETURN_TIME_S + 0.3)
        duration = self._queue(run, motion)
        run.wait_s(duration + 0.2)
        run.wait_motion_done(5.0)
        run.wait_s(SETTLE_AFTER_S + 0.2)

    def _queue(self, run, motion: Motion) -> float:
        """The movement's waypoints; its duration. With `--time-scale auto` a waypoint the
        controller refuses BEYOND_CAPACITY (it carries more than was declared: its estimate)
        makes the host let what was accepted play out, clear the queue and send the movement
        again at the time scale CTRL_ACK names, or at the whole movement's plan with the payload
        CTRL_PAYLOAD reports where that is slower, as a host of the rig would."""
        for _ in range(RETIMES + 1):
            duration = 0.0
            for w in movement_waypoints(motion):
                strict = not self.retime_on_refusal
                result = run.host.waypoint(w.position_m, segment_time_s=w.segment_time_s,
                                           accel_time_s=w.accel_time_s, flags=w.flags, expect_ok=strict)
                if result is not Ack.ACCEPTED:
                    break
                duration += w.segment_time_s
            else:
                return duration
            factor = run.host.time_scale
            if result is not Ack.BEYOND_CAPACITY or not math.isfinite(factor):
                raise HostError(f"waypoint at {np.round(w.position_m * 1e3, 1).tolist()} mm refused: {result.name}")
            run.wait_motion_done(duration + 5.0)          # what was accepted plays out, then the queue is cleared
            run.host.command(Command.CLEAR_WAYPOINTS)
            self.time_scale = max(math.ceil(self.time_scale * factor * 100.0) / 100.0, self._replanned(run))
            run.notes.append(f"a waypoint refused BEYOND_CAPACITY (the controller's payload estimate): the movement "
                             f"sent again at {self.time_scale:g} x the thesis's timing")
            motion = self.motion()
        raise HostError(f"the movement still refused after {RETIMES} retimings")

    @staticmethod
    def _controller_config(sections: dict):
        """The controller's configuration with these sections over its defaults (what it runs with)."""
        from firmware_py.config import load_config
        return load_config(overrides=sections)

    def _replanned(self, run) -> float:
        """The whole movement's plan with the payload CTRL_PAYLOAD reports (0 when none has come
        or no timing fits: the refusal's own factor stands)."""
        from hil.design.capacity import declared, plan
        if not math.isfinite(run.host.payload_kg):
            return 0.0
        cfg = self._controller_config(merge_sections(self.controller_overrides, run.options.controller_config))
        scale = plan(declared(cfg, run.host.payload_kg), self.thesis_motion()).time_scale
        return scale if math.isfinite(scale) else 0.0

    def analyze(self, log: LogData, out: Path | None, rate_hz: float = 500.0) -> Analysis:
        period = 1.0 / rate_hz
        geometry = default_geometry()
        ta = movement_waypoints(self.motion())[0].accel_time_s       # as the controller decoded it
        ref = rebuild(log, "hexapod", period, rule=rule_of(run_controller_config(log), period))
        strokes = log.leg_positions(6)
        truth = np.column_stack([log.get("EMU_TRUTH").per_cycle(log.n_cycles, a) for a in ("X", "Y", "Z")])
        runs = {}
        for motion in ref.motions:
            if motion.step or not np.allclose(motion.trajectory.segments[:, 0, 5], ta, rtol=0.0, atol=1e-9):
                continue                                  # the return to home, not the movement
            controller = controller_at(log, motion.start)
            runs.setdefault(controller, []).append(motion)
        results, series = {}, {}
        dk = DirectKinematics(geometry, 1e-9, 50)
        status = log.get("CTRL_STATUS")
        fault_cycles = status.cycle[status["FAULT_CODE"] != 0]
        for controller, motions in runs.items():
            # a repeated movement: the attempts before the last fault were cut short by it
            span = (fault_cycles >= motions[0].start) & (fault_cycles <= motions[-1].end_cycle)
            if span.any():
                motions = [m for m in motions if m.start > fault_cycles[span].max()] or motions
            first = motions[0].start
            end = motions[-1].end_cycle + int(SETTLE_AFTER_S / period)
            last = min(end, log.n_cycles - 1)
            if last < first:                             # the log ended before this movement began
                continue
            cycles = np.arange(first, last + 1)
            # a movement cut short by a fault or by the end of the log has no comparable IAE
            complete = end <= log.n_cycles - 1 and not np.any((fault_cycles >= first) & (fault_cycles <= last))
            x_ref = _dk_path(dk, geometry, ref.yr[cycles])
            x_dk = _dk_path(dk, geometry, strokes[cycles])
            x_true = truth[cycles]
            results[controller] = {
                "window_s": round(len(cycles) * period, 3),
                "iae_truth_m_s": {a: iae(x_ref[:, i] - x_true[:, i], period) for i, a in enumerate(AXES)},
                "iae_dk_m_s": {a: iae(x_ref[:, i] - x_dk[:, i], period) for i, a in enumerate(AXES)},
                "max_error_truth_mm": {a: float(np.nanmax(np.abs(x_ref[:, i] - x_true[:, i])) * 1e3)
                                       for i, a in enumerate(AXES)},
                "truth_samples_missing": int(np.isnan(x_true).any(axis=1).sum()),
                "complete": bool(complete),
            }
            series[controller] = ((cycles - first) * period, x_ref, x_true, x_dk)
        checks = []
        clock = clock_agreement(log, ref, period)
        if clock.frames:
            checks.append(Check("the reference's clock as the analysis replays it equals the controller's (CTRL_CLOCK)",
                                clock.mismatches == 0, f"{clock.mismatches} of {clock.frames} frames differ", "0"))
        checks.append(Check("online time scaling: the slowest rate of the reference's clock", True,
                            f"{clock.slowest_rate:.3f} ({clock.stretched_s:.2f} s added)", "reported",
                            required=False))
        stalls, others = split_faults(log, period)
        mine = [(cycle, name) for cycle, name in others if controller_at(log, cycle) not in THESIS_CONTROLLERS]
        thesis_faults = [f"{controller_at(log, cycle)} {name}" for cycle, name in others if (cycle, name) not in mine]
        checks.append(Check("no controller fault without a machine stall before it (the thesis's controllers: "
                            "reported below)", not mine, f"{[name for _, name in mine] or 'none'}", "none"))
        checks.append(Check(f"the thesis's controllers at {self.time_scale:g} x the thesis's timing: no fault",
                            not thesis_faults, f"{thesis_faults or 'none'}", "none (they may fault at its timing)",
                            required=False))
        checks.append(Check("faults after a machine stall (realtime: recovered, the movement repeated)", not stalls,
                            f"{[name for _, name in stalls] or 'none'}", "none", required=False))
        if not runs:
            checks.append(Check(f"{self.motion_name} movement found in the log", False, "0 runs", ">= 1"))
        if "adaptive" in results and "model-based" in results:
            incomplete = [c for c in ("adaptive", "model-based") if not results[c]["complete"]]
            for basis in ("iae_truth_m_s", "iae_dk_m_s"):
                pi_p, mb = results["adaptive"][basis], results["model-based"][basis]
                better = [a for a in AXES if mb[a] < pi_p[a]]
                source = "ground truth" if "truth" in basis else "controller DK"
                checks.append(Check(f"model-based IAE < PI+P on every axis ({source})",
                                    len(better) == 3 and not incomplete,
                                    ", ".join(f"{a} {mb[a]:.4g} vs {pi_p[a]:.4g}" for a in AXES)
                                    + (f" (not comparable, cut short by a fault: {', '.join(incomplete)}; both "
                                       f"complete at --time-scale 2)" if incomplete else ""),
                                    "thesis Table 11.x: model-based lower on x, y, z",
                                    required=basis == "iae_truth_m_s" and not incomplete))
        for controller, r in results.items():
            checks.append(Check(f"{controller}: ground truth recorded every cycle", r["truth_samples_missing"] == 0,
                                f"{r['truth_samples_missing']} cycles missing", "0"))
            if controller in THESIS_NAMES:
                thesis = self.thesis[THESIS_NAMES[controller]]
                checks.append(Check(f"{controller}: IAE within the thesis's order of magnitude (x0.1-x10, each axis)",
                                    all(0.1 * thesis[a] <= r["iae_truth_m_s"][a] <= 10 * thesis[a] for a in AXES),
                                    ", ".join(f"{a} {r['iae_truth_m_s'][a]:.4g}" for a in AXES),
                                    ", ".join(f"{a} {thesis[a]:.4g}" for a in AXES), required=False))
        if NEW_CONTROLLER in results:
            checks += self._new_controller_checks(results[NEW_CONTROLLER])
        elif NEW_CONTROLLER in {NAME_OF_CONTROLLER.get(int(v)) for v in np.unique(status["CONTROLLER"])}:
            checks.append(Check(f"{NEW_CONTROLLER}: its movement found in the log", False, "none", "one"))
        figures = []
        if out is not None and series:
            figures = self._plots(series, out)
        # the thesis column: the controller's own figure; model-based's beside the new controller
        table = ["| controller | axis | IAE truth m·s | IAE DK m·s | thesis IAE m·s | max error mm |",
                 "|---|---|---|---|---|---|"]
        for controller, r in results.items():
            thesis = self.thesis.get(THESIS_NAMES.get(controller, "iae_model_based"), {})
            for a in AXES:
                table.append(f"| {controller} | {a} | {r['iae_truth_m_s'][a]:.5f} | {r['iae_dk_m_s'][a]:.5f} | "
                             f"{thesis.get(a, float('nan')):.5f} | {r['max_error_truth_mm'][a]:.2f} |")
        return Analysis({"movement": self.motion_name, "time_scale": self.time_scale, "controllers": results,
                         "clock": {"slowest_rate": clock.slowest_rate, "stretched_s": round(clock.stretched_s, 3),
                                   "frames_checked": clock.frames, "mismatches": clock.mismatches}},
                        self.thesis, checks, figures,
                        ["\n".join(table)])

    def _new_controller_checks(self, r: dict) -> list[Check]:
        """The computed-torque controller against the thesis's model-based figures."""
        thesis = self.thesis["iae_model_based"]
        iae, worst = r["iae_truth_m_s"], r["max_error_truth_mm"]
        scale = f" at {self.time_scale:g} x the thesis's timing"
        return [
            Check(f"{NEW_CONTROLLER}: completes the movement without fault{scale}", r["complete"],
                  "complete" if r["complete"] else "cut short", "complete"),
            Check(f"{NEW_CONTROLLER}: IAE <= {IAE_FACTOR_MAX:g} x the thesis's model-based on every axis",
                  r["complete"] and all(iae[a] <= IAE_FACTOR_MAX * thesis[a] for a in AXES),
                  ", ".join(f"{a} {iae[a]:.4g} ({iae[a] / thesis[a]:.2f} x)" for a in AXES),
                  ", ".join(f"{a} <= {IAE_FACTOR_MAX * thesis[a]:.4g}" for a in AXES)),
            Check(f"{NEW_CONTROLLER}: largest position error <= {MAX_ERROR_MM:g} mm on every axis",
                  r["complete"] and all(worst[a] <= MAX_ERROR_MM for a in AXES),
                  ", ".join(f"{a} {worst[a]:.2f} mm" for a in AXES), f"<= {MAX_ERROR_MM:g} mm"),
            Check(f"{NEW_CONTROLLER}: IAE at or below the thesis's model-based on every axis (the goal beyond)",
                  all(iae[a] <= thesis[a] for a in AXES), ", ".join(f"{a} {iae[a]:.4g}" for a in AXES),
                  ", ".join(f"{a} {thesis[a]:.4g}" for a in AXES), required=False),
        ]

    def _plots(self, series, out: Path) -> list[Figure]:
        fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
        for controller, (t, x_ref, x_true, _) in series.items():
            for i, ax in enumerate(axes):
                if controller == next(iter(series)):
                    ax.plot(t, x_ref[:, i] * 1e3, "k--", lw=1, label="reference")
                ax.plot(t, x_true[:, i] * 1e3, lw=1, label=controller)
                ax.set_ylabel(f"{AXES[i]} [mm]")
                ax.grid(alpha=0.3)
        axes[0].legend(fontsize=7)
        axes[-1].set_xlabel("t [s]")
        path_xyz = out / f"{self.name.replace('-', '_')}_xyz.png"
        save(fig, path_xyz)
        fig = plt.figure(figsize=(6, 5))
        ax = fig.add_subplot(projection="3d")
        for controller, (_, x_ref, x_true, _) in series.items():
            if controller == next(iter(series)):
                ax.plot(*(x_ref.T * 1e3), "k--", lw=1, label="reference")
            ax.plot(*(x_true.T * 1e3), lw=1, label=controller)
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("y [mm]")
        ax.set_zlabel("z [mm]")
        ax.legend(fontsize=7)
        path_3d = out / f"{self.name.replace('-', '_')}_path.png"
        save(fig, path_3d)
        return [Figure(path_xyz.name, "End-effector x, y, z vs time (emulator ground truth)",
                       f"thesis {self.chapter}: x, y, z of the platform for PI+P and model-based"),
                Figure(path_3d.name, "3-D path", f"thesis {self.chapter}: the path in space")]


def _dk_path(dk: DirectKinematics, geometry, strokes: np.ndarray) -> np.ndarray:
    """Platform positions of joint strokes (n, 6), warm-started cycle to cycle; NaN where not solved."""
    out = np.full((len(strokes), 3), np.nan)
    dk.reset()
    for k, s in enumerate(strokes):
        if np.isnan(s).any():
            continue
        dk.solve(geometry.leg_min_m + s)
        if dk.converged:
            out[k] = dk.pose[:3]
        else:
            dk.reset()
    return out


class PmDiagonal(PlatformMovement):
    name = "pm-diagonal"
    title = "movement I (cube diagonals), PI+P vs model-based"
    chapter = "11.3 movement I, 11.5"
    motion_name = "diagonal"
    thesis = THESIS_MOVEMENTS["diagonal"]

    def thesis_motion(self) -> Motion:
        return diagonal_motion(default_geometry())


class PmCircle(PlatformMovement):
    name = "pm-circle"
    title = "movement II (circle in z = 631 mm), PI+P vs model-based"
    chapter = "11.3 movement II, 11.5"
    motion_name = "circle"
    thesis = THESIS_MOVEMENTS["circle"]

    def thesis_motion(self) -> Motion:
        return circle_motion(default_geometry())
