"""The emulator's plant and sensor faults (EMU_CTRL INJECT_FAULT), in process: the frames a
controller would receive and the rig's state while each is injected and after it is cleared."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from physics import hydraulics as hy
from plant_emulator.emulator import Emulator
from plant_emulator.params import load_config
from plant_emulator.rigs import make_rig
from protocol.dbc import load_database
from protocol.enums import EmuCommand, EmuFault, NmtCommand, ValveState
from protocol.outbox import Outbox

PERIOD_S = 0.002
LEG_STATE = load_database().get_message_by_name("LEG_STATE_1")        # stock cantools decodes


class Capture:
    def __init__(self):
        self.frames = []

    def send(self, msg, timeout=None):
        self.frames.append((msg.arbitration_id, bytes(msg.data)))


class Bench:
    """An emulated test bench, its node started, driven frame by frame."""

    def __init__(self):
        self.cfg = load_config()
        self.bus = Capture()
        self.emulator = Emulator(self.bus, make_rig("testbench", self.cfg), self.cfg)
        self.emulator.boot()
        self.counter = 0
        nmt = Outbox("NMT")
        nmt.values[:] = (NmtCommand.START, 0)
        self._frame(nmt)
        self.emu = Outbox("EMU_CTRL")
        self.sync = Outbox("SYNC")
        self.cmd = Outbox("VALVE_CMD_1")

    def _frame(self, box: Outbox) -> None:
        assert box.encode()
        self.emulator.handle(copy.deepcopy(box.message))

    def inject(self, kind: EmuFault, param: int = 0, command: EmuCommand = EmuCommand.INJECT_FAULT,
               load_kg: float = 0.0) -> None:
        """One EMU_CTRL (one outbox: its E2E counter runs on)."""
        v, i = self.emu.values, self.emu.index
        v[i["COMMAND"]], v[i["TARGET"]], v[i["FAULT"]], v[i["FAULT_PARAM"]] = command, 1, kind, param
        v[i["LOAD_MASS"]] = load_kg
        self._frame(self.emu)

    def syncs(self, n: int, valve_active: bool = False) -> list[dict]:
        """n SYNCs (with `valve_active`, each after a VALVE_CMD: ACTIVE at spool 0); leg 1's
        LEG_STATE frames they produced, decoded."""
        self.bus.frames.clear()
        for _ in range(n):
            if valve_active:
                v, i = self.cmd.values, self.cmd.index
                v[i["CW_D"]], v[i["CW_H"]], v[i["CW_M"]], v[i["SPOOL_SETPOINT"]] = 1, 1, 1, 0.0
                self._frame(self.cmd)
            self.counter = self.counter % 240 + 1
            self.sync.values[0] = self.counter
            self._frame(self.sync)
        return [LEG_STATE.decode(data, decode_choices=False) for frame_id, data in self.bus.frames
                if frame_id == LEG_STATE.frame_id]

    @property
    def rig(self):
        return self.emulator.rig


def test_encoder_drift_adds_its_rate_since_the_onset_and_stops_when_cleared():
    bench = Bench()
    bench.syncs(20)
    bench.inject(EmuFault.ENCODER_DRIFT, 1000)                   # 1 mm/s
    frames = bench.syncs(250)                                    # 0.5 s
    truth_mm = bench.rig.state[0, hy.S_Y] * 1e3
    assert frames[-1]["POSITION"] - truth_mm == pytest.approx(0.5, abs=0.13)    # +- one encoder count
    # the sensor reads the drifted length in its own counts: every reading on the count grid
    count_mm = bench.emulator.cfg.sensors.encoder_resolution_m * 1e3
    counts = np.array([f["POSITION"] for f in frames]) / count_mm
    assert np.abs(counts - np.round(counts)).max() < 0.05          # the wire's 0.005 mm steps
    bench.inject(EmuFault.ENCODER_DRIFT, command=EmuCommand.CLEAR_FAULT)
    frames = bench.syncs(5)
    assert frames[-1]["POSITION"] == pytest.approx(bench.rig.state[0, hy.S_Y] * 1e3, abs=0.13)


@pytest.mark.parametrize("kind", [EmuFault.FORCE_STUCK, EmuFault.FORCE_ZERO])
def test_a_failed_load_cell_reads_stuck_or_zero_while_the_load_changes(kind):
    bench = Bench()
    before = bench.syncs(20)[-1]["FORCE"]
    bench.inject(kind)
    bench.inject(EmuFault.NONE, command=EmuCommand.SET_LOAD, load_kg=6.0)
    forces = [f["FORCE"] for f in bench.syncs(100)]
    assert bench.rig.rod_force_n[0] > before + 40.0                # the true force changed (6 kg more)
    expected = 0.0 if kind is EmuFault.FORCE_ZERO else forces[0]
    assert forces == [expected] * len(forces) and (kind is EmuFault.FORCE_ZERO or abs(forces[0] - before) < 5.0)


def test_frame_loss_drops_about_its_share_of_the_frames():
    bench = Bench()
    bench.inject(EmuFault.FRAME_LOSS, 30)
    received = len(bench.syncs(1000))
    assert 620 <= received <= 780                                   # 700 expected, 1000 draws: +- 5 sigma


def test_supply_drop_settles_at_its_fraction_and_clearing_restores_it():
    bench = Bench()
    cfg, rig = bench.cfg, bench.rig
    tank = cfg.hp[hy.HP_TANK]
    bench.inject(EmuFault.SUPPLY_DROP, 60)
    bench.syncs(1000)                                               # 2 s: many time constants
    assert rig.supply_pressure_pa == pytest.approx(tank + 0.6 * (cfg.actuator.supply_pressure_pa - tank), rel=1e-3)
    bench.inject(EmuFault.SUPPLY_DROP, command=EmuCommand.CLEAR_FAULT)
    bench.syncs(1)
    assert rig.supply_pressure_pa == cfg.actuator.supply_pressure_pa


def test_a_stuck_spool_drives_the_leg_whatever_the_valve_is_told():
    """The valve ACTIVE and told spool 0: the spool goes to the stuck 20 % (LEG_STATE's SPOOL
    says so at once) and the leg extends, until the valve's own control-deviation monitor
    (its demand against its spool) holds it. In HOLD the load-holding valves close and keep
    it where it is, stuck spool or not."""
    bench = Bench()
    bench.syncs(5, valve_active=True)
    y0 = bench.rig.state[0, hy.S_Y]
    bench.inject(EmuFault.SPOOL_STUCK, 20)
    frames = bench.syncs(50, valve_active=True)
    assert bench.rig.command[0] == pytest.approx(0.2)
    assert frames[0]["SPOOL"] == 0 and frames[1]["SPOOL"] >= 14 and frames[3]["SPOOL"] == 20
    jam = bench.cfg.nodes.spool_jam_syncs
    assert [f["VALVE_STATE"] for f in frames[jam - 1:jam + 1]] == [int(ValveState.ACTIVE), int(ValveState.FAULT_HOLD)]
    y1 = bench.rig.state[0, hy.S_Y]
    assert y1 > y0 + 1e-3                                          # extending, against a spool-0 command
    bench.syncs(50)
    y2 = bench.rig.state[0, hy.S_Y]
    bench.syncs(50)
    assert abs(bench.rig.state[0, hy.S_Y] - y2) < 1e-4            # held by the load-holding valves
    bench.inject(EmuFault.SPOOL_STUCK, command=EmuCommand.CLEAR_FAULT)
    bench.syncs(2)
    assert bench.rig.command[0] == 0.0
    assert np.isfinite(bench.rig.state).all()


def test_a_leaking_seal_equalises_the_held_chambers_and_clearing_restores_it():
    """HOLD (load-holding valves closed): a sound seal keeps PA and PB apart; one leaking 10x
    the calibrated leakage lets B fill from A until the chambers nearly share one pressure."""
    gaps = {}
    for factor in (0, 10):
        bench = Bench()
        if factor:
            bench.inject(EmuFault.SEAL_LEAK, factor)
            assert bench.rig.seal_leak[0] == pytest.approx(10 * bench.cfg.hp[hy.HP_LEAK])
        bench.syncs(200)
        state = bench.rig.state[0]
        gaps[factor] = abs(state[hy.S_PA] - state[hy.S_PB])
        assert np.isfinite(bench.rig.state).all()
    assert gaps[10] < 0.2 * gaps[0]
    bench.inject(EmuFault.SEAL_LEAK, command=EmuCommand.CLEAR_FAULT)
    bench.syncs(1)
    assert bench.rig.seal_leak[0] == bench.cfg.hp[hy.HP_SEAL_LEAK]
