"""The actuator residuals (firmware_py/supervision/residuals.py) in the controller's cycle, on the
emulator's hexapod in process: quiet on a healthy move (margin >= 1.5), the leg named when
its spool sticks (within 25 cycles) or its rod seizes (30 cycles measured: the valve first
has to open against the blocked piston), SUPPLY_PRESSURE when the supply is lost; the valves'
supply transducers judged against the model's supply."""

import math

import numpy as np
import pytest

from firmware_py.config import load_config
from firmware_py.supervision.residuals import (
    NOT_JUDGED,
    PRESSURE_SIGMAS,
    ActuatorResiduals,
    ChamberPrediction,
    SpoolResidual,
    breakaway_force_n,
    lag_uncertainty,
    sample_floor_pa,
    sample_verdict,
)
from hil.in_process import InProcessLoop
from physics import hydraulics as hy
from physics.constants import BAR
from plant_emulator.params import load_config as load_emulator_config
from protocol.dbc import signal_scale
from protocol.enums import EmuFault, Fault, State, ValveState, WaypointFlag

PERIOD_S = 0.002
FAULT_AT = 400                     # cycles into the move (20 mm/s)
DETECT_WITHIN = 25
SPOOL_WITHIN = 2                   # a jammed spool is off its lag's prediction at its first report
PRESSURE_PHASES = np.arange(6, 12)     # LEG_PRESSURE_1..6's SyncPhase (the DBC)


# each fault's EMU_CTRL injection on leg 1's node (or the power unit's)
FAULTS = {"seized": (1, EmuFault.LEG_JAM, 0), "spool": (1, EmuFault.SPOOL_STUCK, 20),
          "supply": (1, EmuFault.SUPPLY_LOSS, 0), "supply60": (1, EmuFault.SUPPLY_DROP, 60),
          "seal": (1, EmuFault.SEAL_LEAK, 10), "load_cell": (3, EmuFault.FORCE_STUCK, 0)}


def run_move(fault: str | None, cycles: int = 700, residuals: bool = True, supervisor: dict | None = None,
             hook=None, forced_hold: dict | None = None):
    """Home, then the platform 30 mm up at about 20 mm/s with the adaptive controller on the
    emulated hexapod in process (its sensors as on the bus: counts, noise, LEG_PRESSURE on
    its phases); `fault` injected FAULT_AT cycles in. Returns (max |r| / threshold before the
    fault, the cycle after the fault at which the controller faulted or None, the loop, the
    platform's positions). `forced_hold`: from when it says "on", every valve is forced to
    HOLD after the update, as a loop would that did not tell the controller."""
    cfg = load_config(overrides={"residuals": {"enabled": residuals}, "supervisor": supervisor or {}})
    loop = InProcessLoop(cfg, load_emulator_config(), "adaptive")
    loop.activate(50)
    assert loop.status.state is State.READY
    x, y, z = loop.ctl.rig.home_pose
    positions = []

    def cycle():
        loop.sim.read(loop.meas)
        loop.ctl.update(loop.meas, loop.cmd)
        if forced_hold and forced_hold.get("on"):
            loop.cmd.hold_all()
        loop.sim.write(loop.cmd)
        loop.ctl.after_write()
        loop.ctl.host.acks.clear()
        positions.append(loop.rig.platform_pose()[0].copy())

    loop.waypoint((x, y, z + 0.03), 1.7, 0.2, WaypointFlag.START | WaypointFlag.LAST)
    status = loop.status
    quiet, detected = 0.0, None
    positions.clear()
    for k in range(cycles):
        if k == FAULT_AT and fault is not None:
            loop.sim.inject(*FAULTS[fault])
        if hook is not None:
            hook(k, loop)
        cycle()
        if k < FAULT_AT:
            assert status.state is not State.FAULT, status.fault.name
            if k > 10:
                quiet = max(quiet, float(status.residual_ratio.max()))
        elif detected is None and status.state is State.FAULT:
            detected = k - FAULT_AT
    return quiet, detected, loop, np.array(positions)


def peak(loop, monitor: str) -> float:
    """A monitor's false-alarm margin measure (the summary's `{monitor}_peak`)."""
    return loop.status.margins.as_dict()[f"{monitor}_peak"]


def test_threshold_floor_is_the_seals_breakaway_force():
    cfg = load_config()
    assert breakaway_force_n(cfg.friction.vector) == pytest.approx(12.1994 + 10.6468)


def test_quiet_on_a_healthy_move_with_margin():
    quiet, detected, loop, _ = run_move(None)
    assert quiet < 1.0 / 1.5
    assert detected is None and loop.status.state in (State.RUNNING, State.READY)


@pytest.mark.parametrize(("fault", "within", "code"), [("spool", SPOOL_WITHIN, Fault.SPOOL_MISMATCH),
                                                      ("seized", 40, Fault.ACTUATOR_RESIDUAL)])
def test_a_leg_fault_names_the_leg(fault, within, code):
    _, detected, loop, _ = run_move(fault)
    assert detected is not None and detected <= within, detected
    assert loop.status.fault is code and loop.status.fault_leg == 1


def test_a_lost_supply_is_the_supplys_fault():
    _, detected, loop, _ = run_move("supply")
    assert detected is not None
    assert loop.status.fault is Fault.SUPPLY_PRESSURE and loop.status.fault_leg == 0


def test_a_leg_without_a_pressure_sample_waits_for_its_first():
    """The chambers' level sets the valve's flows and no force shows it: a leg whose
    transducers have not spoken at activation is judged nothing until its first sample, then
    starts from it; a leg with a sample starts at once."""
    cfg = load_config()
    r = cfg.residuals
    supply = np.full(2, cfg.hydraulic_model.supply_pressure_pa)
    res = ActuatorResiduals(2, cfg.hydraulics, cfg.friction.vector, PERIOD_S,
                            0.5, r.column_stiffness_n_m, cfg.actuator.encoder_resolution_m, r.correction_gain,
                            r.filter_s, r.persistence_cycles, r.flow_spread)
    position, force, zeros = np.array([0.1, 0.1]), np.array([200.0, 200.0]), np.zeros(2)
    pa, pb = np.array([5e5, 0.0]), np.array([4e5, 0.0])
    res.start(position, np.array([True, False]), pa, pb)
    sampled = np.array([False, False])
    for k in range(20):
        if k == 10:
            sampled[1], pa[1], pb[1] = True, 12e5, 3e5
        res.update(np.full(2, 0.02), np.array([True, True]), position, force, zeros, zeros, sampled, pa, pb, supply)
        sampled[1] = False
        if k < 10:
            assert not res.seeded[1] and res.residual[1] == 0.0 and res.ratio[1] == 0.0
        elif k == 10:
            assert res.seeded[1] and res.state[1, hy.S_PA] == 12e5 and res.state[1, hy.S_PB] == 3e5
    assert res.seeded[0] and res.residual[0] != 0.0 and res.residual[1] != 0.0


def path_excursion_m(positions: np.ndarray, healthy: np.ndarray) -> float:
    """How far the platform strayed from the healthy run's path after the fault (a stop
    along the path is no excursion), less the distance it had before it."""
    distance = np.linalg.norm(positions[FAULT_AT - 1:, None, :] - healthy[None, :, :], axis=2).min(axis=1)
    return float(np.max(distance - distance[0]))


def test_the_controlled_stop_keeps_the_platform_near_its_path():
    """A stuck spool, caught at its first report: locking every leg at once leaves the
    platform ~6 mm off its path (the locked leg's error amplified by the near-vertical legs);
    the controlled stop keeps it within half of that and 5 mm, and with the residuals off the
    tracking limit lets it go far further. A seized rod stays within 5 mm."""
    *_, healthy = run_move(None)
    excursion = {}
    for name, fault, overrides in (("stop", "spool", {}), ("lock", "spool", {"controlled_stop_ms": 0.0}),
                                   ("late", "spool", None), ("seized", "seized", {})):
        *_, positions = run_move(fault, residuals=overrides is not None, supervisor=overrides or {})
        excursion[name] = 1e3 * path_excursion_m(positions, healthy)
    assert excursion["stop"] < 0.5 * excursion["lock"] < excursion["late"], excursion
    assert excursion["stop"] <= 5.0 and excursion["seized"] <= 5.0, excursion


def test_frozen_limit_follows_from_the_noise_and_the_bit():
    from firmware_py.supervision.plausibility import FROZEN_FALSE_ALARM, frozen_limit
    n = frozen_limit(0.3, 0.1)
    p = 0.1 / (2 * np.sqrt(np.pi) * 0.3)
    assert p ** n < FROZEN_FALSE_ALARM <= p ** (n - 1) and n == 9
    assert frozen_limit(0.04, 0.1) == 0 and frozen_limit(0.0, 0.1) == 0     # too quiet to tell


def test_a_healthy_noisy_load_cell_is_never_frozen_a_stuck_one_is():
    """Quantised Gaussian readings (0.3 N on 0.1 N) over 100,000 cycles of six legs: no
    fault; the same reading repeated: the leg after the derived count."""
    from firmware_py.supervision.plausibility import FrozenLoadCells
    cells = FrozenLoadCells(6, 0.3, 0.1)
    rng = np.random.default_rng(11)
    fresh = np.ones(6, dtype=bool)
    readings = np.round((50.0 + 0.3 * rng.standard_normal((100_000, 6))) / 0.1) * 0.1
    assert all(cells.update(row, fresh) == -1 for row in readings)
    stuck = readings[-1] + 0.1 * np.arange(1, 13)[:, None]        # the others keep changing ...
    stuck[:, 2] = 42.0                                              # ... leg 3 reads 42 N from now on
    seen = [cells.update(row, fresh) for row in stuck]
    assert seen.index(2) == cells.limit                             # the first 42 N, then `limit` repeats


def test_a_frozen_load_cell_faults_its_leg_in_the_cycle():
    """In the controller: leg 3's load cell stops changing mid-move -> LOAD_CELL, leg 3."""
    from firmware_py.supervision.plausibility import frozen_limit
    cfg = load_config()
    quiet, detected, loop, _ = run_move("load_cell")
    assert detected is not None
    assert detected <= frozen_limit(cfg.residuals.load_cell_noise_n, signal_scale("LEG_STATE_1", "FORCE")) + 1
    assert loop.status.fault is Fault.LOAD_CELL and loop.status.fault_leg == 3


def test_chamber_pressure_samples_keep_the_margin_and_the_detection():
    """With LEG_PRESSURE samples as the bus brings them (each leg every 16th SYNC, 0.02 bar
    noise) setting the model's level: still quiet with margin, a seized rod still named in
    25 cycles."""
    quiet, detected, loop, _ = run_move(None)
    assert quiet < 1.0 / 1.5 and detected is None
    assert 0.0 < peak(loop, "pressure") < 1.0 / 1.5          # the chambers' sample-to-sample prediction
    _, detected, loop, _ = run_move("seized")
    assert detected is not None and detected <= DETECT_WITHIN
    assert loop.status.fault is Fault.ACTUATOR_RESIDUAL and loop.status.fault_leg == 1


@pytest.mark.parametrize("cycles_after_sample", [0, 13])
def test_a_leaking_seal_is_named_at_the_legs_next_pressure_sample(cycles_after_sample):
    """10x the calibrated leakage across leg 1's piston pulls p_A and p_B together: the
    chambers' prediction from the last LEG_PRESSURE sample misses at the next one. Onset right
    after leg 1's sample is the longest wait (16 cycles to the next)."""
    onset = []

    def leak(k, loop):
        if not onset and k >= FAULT_AT and loop.sim.counter % 16 == (PRESSURE_PHASES[0] + cycles_after_sample) % 16:
            loop.sim.inject(*FAULTS["seal"])
            onset.append(k)

    _, detected, loop, _ = run_move(None, hook=leak)
    assert onset and loop.status.fault is Fault.CHAMBER_PRESSURE and loop.status.fault_leg == 1
    assert detected + FAULT_AT - onset[0] <= DETECT_WITHIN, (detected, onset)


@pytest.mark.parametrize("cycles_before_sample", [0, 1, 2])
def test_a_stuck_spool_before_a_pressure_sample_is_the_spools_fault(cycles_before_sample):
    """A spool stuck open just before leg 1's LEG_PRESSURE sample: the chambers miss their
    prediction (it follows the command) a cycle before the spool check has persisted; the
    spool off its band explains them, and SPOOL_MISMATCH names the leg."""
    onset = []

    def stick(k, loop):
        if not onset and k >= FAULT_AT and loop.sim.counter % 16 == (PRESSURE_PHASES[0] - cycles_before_sample) % 16:
            loop.sim.inject(*FAULTS["spool"])
            onset.append(k)

    _, detected, loop, _ = run_move(None, cycles=FAULT_AT + 40, hook=stick)
    assert onset and detected is not None, onset
    assert loop.status.fault is Fault.SPOOL_MISMATCH and loop.status.fault_leg == 1, loop.status.fault.name


def _ringing_leg(plant_lag: int, known_late: bool, amplitude: float, hz: float) -> float:
    """A leg at rest, its spool swinging as computed torque's force loop rings (40 bar), the
    emulator's chamber laws in 32 steps a cycle as the plant, which applies each command
    `plant_lag` cycles after it was computed (1: at the next SYNC, as the controller assumes);
    LEG_PRESSURE every 16th cycle. The prediction's largest ratio after its first samples."""
    cfg = load_config(overrides={"hydraulic_model": {"supply_pressure_bar": 40.0}})
    hp, ps = cfg.hydraulics, cfg.hydraulic_model.supply_pressure_pa
    floor = sample_floor_pa(cfg.residuals.pressure_noise_pa, signal_scale("LEG_PRESSURE_1", "PA") * BAR)
    prediction = ChamberPrediction(1, hp, PERIOD_S, cfg.actuator.encoder_resolution_m, cfg.residuals.flow_spread,
                                   cfg.residuals.leakage_spread, cfg.residuals.stiffness_spread, floor, 1,
                                   cfg.residuals.pressure_carry, int(ValveState.ACTIVE))
    y = np.array([0.05])
    plant = np.zeros(hy.S_SIZE)
    plant[hy.S_Y] = y[0]
    plant[hy.S_PA], plant[hy.S_PB] = hy.holding_pressures(0.0, ps, hp)
    prediction.start(y)
    commands = amplitude * np.sin(2.0 * math.pi * hz * PERIOD_S * np.arange(600))
    worst = 0.0
    for k in range(3, 600):
        for _ in range(32):
            plant[hy.S_SPOOL] = hy.spool_step(plant[hy.S_SPOOL], commands[k - plant_lag], PERIOD_S / 32, hp)
            hy.chamber_step(plant, y[0], 0.0, ps, PERIOD_S / 32, hp, 1.0, hp[hy.HP_SEAL_LEAK])
        late = commands[k - 2] if known_late else commands[k - 1]
        prediction.update(np.array([commands[k - 1]]), np.array([late]), np.ones(1, dtype=bool), y,
                          np.array([int(ValveState.ACTIVE)]), np.array([k % 16 == 0]),
                          plant[hy.S_PA:hy.S_PA + 1].copy(), plant[hy.S_PB:hy.S_PB + 1].copy(), np.array([ps]))
        if k > 100:
            worst = max(worst, float(prediction.ratio[0]))
    return worst


@pytest.mark.parametrize("amplitude,hz", [(0.17, 36.0), (0.4, 62.5)])
def test_a_command_applied_a_cycle_late_is_no_chamber_fault(amplitude, hz):
    """A command applied a cycle after the controller assumed (it reached the valve after the
    SYNC, or the sensor frames came a cycle late) while the spool swings: the prediction on
    that command is far off the samples (a hex-kick run at 40 bar latched CHAMBER_PRESSURE
    so), the one on the command before matches them."""
    assert _ringing_leg(1, True, amplitude, hz) < 1.0 / 1.5                 # on time
    assert _ringing_leg(2, True, amplitude, hz) < 1.0 / 1.5                 # a cycle late, both candidates
    assert _ringing_leg(2, False, amplitude, hz) > 1.0                      # the applied command alone


def _verdicts(ratios, carry=0.4, ages=None):
    """sample_verdict over one leg's judged samples; the legs faulty after each."""
    last, evidence, above = np.zeros(1), np.zeros(1), np.zeros(1, dtype=np.int64)
    out = []
    for k, r in enumerate(ratios):
        age = np.array([-1 if ages is not None and ages[k] < 0 else 0])
        ratio = np.array([r if age[0] >= 0 else NOT_JUDGED])
        faulty, _, _ = sample_verdict(ratio, np.zeros(1, dtype=np.bool_), age, carry, 1, last, evidence, above)
        out.append(faulty)
    return out


def test_chamber_evidence_adds_the_sample_before_beyond_carry():
    """A fault at the threshold's edge (0.72 at a sample, as a 10x leak at the probe's operating
    point gives) is named at its second; one beyond alone is; a model error held under
    (1 + carry) / 2 of its bound never is; a broken-off prediction has no sample before."""
    assert _verdicts([0.72, 0.72]) == [0, 1]
    assert _verdicts([1.01]) == [1]
    assert _verdicts([0.69] * 200) == [0] * 200
    assert _verdicts([0.9, 0.3, 0.75]) == [0] * 3
    assert _verdicts([0.9, 0.0, 0.9], ages=[0, -1, 0]) == [0, 0, 0]


def test_the_prediction_floor_is_two_samples_noise_and_the_wire_step():
    assert sample_floor_pa(2e3, 1e3) == pytest.approx(PRESSURE_SIGMAS * math.sqrt(2.0) * 2e3 + 1e3)
    assert PRESSURE_SIGMAS == 6.0


def test_the_supply_band_is_the_flow_gains_spread_through_the_orifice_law():
    """A supply p gives sqrt((p - p_T) / (p_S - p_T)) of the model's flow: the band's edges are
    where that leaves 1 -+ the spread (ratio 1)."""
    from firmware_py.supervision.plausibility import supply_step
    tank, drop, spread = 0.9e5, 24.1e5, 0.135
    ps = tank + np.array([(1 - spread) ** 2, (1 + spread) ** 2, 1.0, 0.0]) * drop
    ratio, run = np.zeros(4), np.zeros(4, dtype=np.int64)
    count, lone, peak = supply_step(ps, np.ones(4, dtype=bool), tank, drop, spread, ratio, run, 3, np.zeros(4))
    assert ratio[:3] == pytest.approx([1.0, 1.0, 0.0]) and ratio[3] == pytest.approx(1.0 / spread)
    assert peak == pytest.approx(1.0 / spread)
    assert count == 1 and lone == -1                   # the lone leg's first sample: not yet its fault


def test_supply_samples_name_the_power_unit_or_the_lone_transducer():
    from firmware_py.supervision.plausibility import SupplyPressure
    nominal, tank = 25e5, 0.9e5
    low = np.full(6, nominal)
    monitor = SupplyPressure(6, nominal, tank, 0.135, 3)
    for leg in range(6):                               # the legs' samples come one per cycle
        fresh = np.arange(6) == leg
        low[leg] = 12e5
        faulty, lone = monitor.update(low, fresh)
        assert faulty == (leg >= 2) and lone == -1     # the third leg beyond: the supply
    monitor = SupplyPressure(6, nominal, tank, 0.135, 3)
    ps = np.full(6, nominal)
    ps[4] = 0.0                                        # leg 5's transducer dead
    only_5 = np.arange(6) == 4
    assert monitor.update(ps, only_5) == (False, -1)   # one sample: wait for its next
    assert monitor.update(ps, np.ones(6, dtype=bool)) == (False, 4)
    bench = SupplyPressure(1, nominal, tank, 0.135, 3)   # one valve: its transducer is the supply's
    assert bench.update(np.array([15e5]), np.ones(1, dtype=bool)) == (True, -1)


@pytest.mark.parametrize("fault", ["supply", "supply60"])
def test_the_supply_transducers_find_a_lost_or_dropped_supply(fault):
    """Supply lost (to the tank) or down to 60 %, both with the power unit's 50 ms decay: it
    leaves the band at 14.5 ms and 50 ms; SUPPLY_PRESSURE once three legs' samples, on their
    phases of 16 cycles, have seen it. Healthy, the samples stay within 1 / 1.5 of the band."""
    _, detected, loop, _ = run_move(None)
    assert detected is None and peak(loop, "supply") * 1.5 < 1.0
    _, detected, loop, _ = run_move(fault)
    assert loop.status.fault is Fault.SUPPLY_PRESSURE and loop.status.fault_leg == 0
    assert detected is not None and detected <= (DETECT_WITHIN if fault == "supply" else 45), detected


@pytest.mark.parametrize("told", [True, False])
def test_the_daemons_shutdown_is_no_fault(told):
    """At SIGTERM the daemon shuts the controller down mid-move: it writes every valve HOLD
    itself, goes IDLE and judges nothing. Were the valves forced to HOLD behind its back, it
    would see its legs stop under an active command and latch a residual fault (the spools
    first: they are not where the commands would take them)."""
    forced = {}

    def hook(k, loop):
        if k == FAULT_AT:
            if told:
                loop.ctl.shut_down()
            else:
                forced["on"] = True

    _, detected, loop, _ = run_move(None, cycles=FAULT_AT + 60, hook=hook, forced_hold=forced)
    if told:
        assert detected is None and loop.status.state is State.IDLE and loop.status.faults == 0
        assert not loop.cmd.active.any() and loop.cmd.hold.all()
    else:
        assert loop.status.fault in (Fault.SPOOL_MISMATCH, Fault.ACTUATOR_RESIDUAL, Fault.SUPPLY_PRESSURE)


def spool_check(persistence: int = 2) -> SpoolResidual:
    cfg = load_config()
    return SpoolResidual(6, cfg.hydraulics, PERIOD_S, cfg.residuals.spool_floor, cfg.residuals.spool_lag_spread,
                         persistence, int(ValveState.ACTIVE))


def test_the_spool_lag_bound_is_the_decays_change_over_the_time_constants_spread():
    tau = 1.5e-3
    assert lag_uncertainty(PERIOD_S, tau, 0.0) == 0.0
    slow, fast = math.exp(-PERIOD_S / (1.5 * tau)), math.exp(-PERIOD_S / (0.5 * tau))
    nominal = math.exp(-PERIOD_S / tau)
    assert lag_uncertainty(PERIOD_S, tau, 0.5) == pytest.approx(max(slow - nominal, nominal - fast))


def test_the_spool_residual_follows_the_valves_lag_and_names_a_jammed_spool():
    """Against the emulator's own spool law (hy.spool_step), reported in 1 % steps: random
    commands (some beyond full input) keep every ratio below 1 / 1.5, a command the valve
    applied a period late too; a spool jammed at 20 % is that leg's fault at its second
    report; a valve not ACTIVE is not judged."""
    cfg = load_config()
    check, rng = spool_check(), np.random.default_rng(7)
    spool, sent = np.zeros(6), np.zeros((3, 6))              # sent[0] two cycles back, sent[1] three
    fresh, active = np.ones(6, dtype=bool), np.full(6, int(ValveState.ACTIVE))
    check.start()
    peak = 0.0
    for k in range(2000):
        late = k % 97 == 50                                  # this period the valve kept the older command
        applied = sent[1] if late else sent[0]
        for i in range(6):
            spool[i] = hy.spool_step(spool[i], applied[i], PERIOD_S, cfg.hydraulics)
        report = np.round(spool * 100.0) / 100.0
        assert check.update(sent[0], sent[1], report, fresh, active) == 0
        peak = max(peak, check.peak)
        sent[1], sent[0] = sent[0].copy(), sent[2].copy()
        sent[2] = np.clip(sent[2] + 0.05 * rng.standard_normal(6), -1.2, 1.2) if k % 5 else rng.uniform(-1, 1, 6)
    assert 0.1 < peak < 1.0 / 1.5
    faulty = []
    for _ in range(3):
        for i in range(6):
            spool[i] = hy.spool_step(spool[i], 0.2 if i == 3 else sent[0][i], PERIOD_S, cfg.hydraulics)
        faulty.append(check.update(sent[0], sent[1], np.round(spool * 100.0) / 100.0, fresh, active))
    assert faulty[:2] == [0, 1] and check.worst_leg == 3 and check.ratio[3] > 2.0
    active[3] = int(ValveState.HOLD)
    assert check.update(sent[0], sent[1], spool, fresh, active) == 0 and check.ratio[3] == 0.0
