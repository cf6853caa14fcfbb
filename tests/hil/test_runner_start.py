"""The runner's judgements: a run whose emulated plant diverged fails; the controller's
start: in realtime a start that a fault ends (a machine stall
while the loop starts) is recovered with RESET + ENABLE and noted, its window kept for the
log's judgement; in lockstep, or after the last try, it is the run's failure. The same for a
fault that refuses a controller's selection and for a recovery a stall faults again."""

from pathlib import Path

import pytest

import hil.runner as runner
from hil.host import HostError
from hil.runner import START_TRIES, Run, RunOptions
from hil.scenarios import SCENARIOS
from protocol.enums import Ack, Command, Fault, State


class FakeChild:
    def __init__(self, name, args, out):
        self.name = name

    def start(self):
        pass


class FakeHost:
    """CTRL_STATUS says FAULT after each start or recovery, `faults` times, then READY."""

    def __init__(self, faults: int):
        self.faults = faults
        self.state = None
        self.fault_code = 0
        self.commands = []

    def new_controller(self):
        pass

    def _settle(self):
        if self.faults:
            self.faults -= 1
            self.state, self.fault_code = State.FAULT, int(Fault.VALVE_FAULT)
        else:
            self.state, self.fault_code = State.READY, 0

    def wait_state(self, *states, max_cycles=0, wall_timeout_s=None):
        if State.READY in states and State.FAULT in states:      # the start's wait
            self._settle()
        elif State.IDLE in states:
            self.state = State.IDLE

    def command(self, command, argument=0, expect_ok=True):
        self.commands.append(command)
        if command is Command.ENABLE:
            self._settle()
            if self.state is State.READY:
                return Ack.ACCEPTED
        return Ack.ACCEPTED

    def wait_cycles(self, cycles):
        pass


def make_run(tmp_path: Path, pacing: str, faults: int, monkeypatch) -> Run:
    monkeypatch.setattr(runner, "Child", FakeChild)
    options = RunOptions(out_dir=tmp_path, pacing=pacing)
    run = Run(SCENARIOS["rt-hexapod"], options, runner.fresh_bus_spec(), tmp_path)
    run.host = FakeHost(faults)
    return run


@pytest.mark.parametrize("faults", [1, START_TRIES - 1])
def test_a_realtime_start_fault_is_recovered_noted_and_kept_for_the_log(tmp_path, monkeypatch, faults):
    run = make_run(tmp_path, "realtime", faults, monkeypatch)
    run.start_controller("model-based")
    assert run.host.state is State.READY
    assert len(run.start_retries) == faults
    assert all(start <= end for start, end in run.start_retries)
    assert sum("FAULT while starting (VALVE_FAULT); RESET + ENABLE" in n for n in run.notes) == faults
    assert run.host.commands.count(Command.RESET) == faults


def test_a_realtime_start_that_faults_every_time_fails_the_run(tmp_path, monkeypatch):
    run = make_run(tmp_path, "realtime", START_TRIES, monkeypatch)
    with pytest.raises(HostError, match="FAULT while starting \\(VALVE_FAULT\\)"):
        run.start_controller("model-based")


def test_a_lockstep_start_fault_fails_at_once(tmp_path, monkeypatch):
    run = make_run(tmp_path, "lockstep", 1, monkeypatch)
    with pytest.raises(HostError, match="FAULT while starting"):
        run.start_controller("model-based")
    assert run.start_retries == [] and Command.RESET not in run.host.commands


class FakeHeartbeatHost(FakeHost):
    node_heartbeats = 0

    def wait_until(self, *args, **kwargs):
        pass


@pytest.mark.parametrize(("scenario", "section", "key"), [("pm-diagonal", "hexapod", "payload_kg"),
                                                           ("sha-step", "testbench", "load_kg")])
def test_the_users_emulator_config_sets_the_load(tmp_path, monkeypatch, scenario, section, key):
    """A payload (or bench load) in --emulator-config reaches the emulator: the scenario's
    start load sits under it, not on its command line (which once overrode it silently)."""
    import tomllib
    started = []
    monkeypatch.setattr(runner, "Child", lambda name, args, out: started.append(args) or FakeChild(name, args, out))
    options = RunOptions(out_dir=tmp_path, pacing="lockstep", emulator_config={section: {key: 6.0}})
    run = Run(SCENARIOS[scenario], options, runner.fresh_bus_spec(), tmp_path)
    run.host = FakeHeartbeatHost(0)
    run.start_emulator()
    argv = started[0]
    config = tomllib.loads(Path(argv[argv.index("--config") + 1]).read_text())
    assert config[section][key] == 6.0 and "--load-kg" not in argv
    run.options.emulator_config = {}
    run.start_emulator()
    config = tomllib.loads(Path(started[1][started[1].index("--config") + 1]).read_text())
    assert config[section][key] == SCENARIOS[scenario].load_kg


def test_a_run_whose_plant_diverged_fails():
    ok = {"emulator": {"summary": {"plant_unstable": 0, "plant_unstable_first_s": None}}, "controller": {}}
    assert runner._plant_diverged(ok) is None
    broken = {"emulator": {"summary": {"plant_unstable": 3, "plant_unstable_first_s": 3.25}}}
    assert "diverged at t = 3.250 s" in runner._plant_diverged(broken)


class FaultedHost(FakeHost):
    """A machine stall has just faulted the controller (OVERRUN): SELECT_CONTROLLER is refused
    BAD_STATE while it is latched; the READY wait of each of the first `recovery_faults`
    recoveries sees FAULT again."""

    def __init__(self, recovery_faults: int):
        super().__init__(0)
        self.state, self.fault_code = State.FAULT, int(Fault.OVERRUN)
        self.recovery_faults = recovery_faults
        self.controller = None

    def command(self, command, argument=0, expect_ok=True):
        self.commands.append(command)
        if command is Command.SELECT_CONTROLLER and self.state is State.FAULT:
            raise HostError(f"HOST_CMD {command.name} {argument} refused: BAD_STATE")
        if command is Command.SELECT_CONTROLLER:
            self.controller = argument
        return Ack.ACCEPTED

    def wait_state(self, *states, max_cycles=0, wall_timeout_s=None):
        if State.IDLE in states:
            self.state = State.IDLE
        elif self.recovery_faults:
            self.recovery_faults -= 1
            self.state = State.FAULT
            raise HostError("controller state READY not reached within 1000 cycles (state FAULT, fault code 9)")
        else:
            self.state = State.READY

    def wait_until(self, condition, max_cycles, what=None, wall_timeout_s=None):
        assert condition() or what is None, what


@pytest.mark.parametrize("recovery_faults", [0, runner.RECOVERY_TRIES - 1])
def test_realtime_a_fault_before_the_selection_is_recovered_then_selected(tmp_path, monkeypatch, recovery_faults):
    run = make_run(tmp_path, "realtime", 0, monkeypatch)
    run.host = FaultedHost(recovery_faults)
    run.select("adaptive")
    assert run.host.state is State.READY and run.host.controller == runner.CONTROLLER_NAMES["adaptive"]
    assert run.host.commands.count(Command.RESET) == recovery_faults + 1
    assert sum("before its selection" in n for n in run.notes) == 1
    assert sum("recovery attempt" in n and "faulted OVERRUN" in n for n in run.notes) == recovery_faults


def test_a_recovery_that_faults_every_time_or_in_lockstep_fails(tmp_path, monkeypatch):
    run = make_run(tmp_path, "realtime", 0, monkeypatch)
    run.host = FaultedHost(runner.RECOVERY_TRIES)
    with pytest.raises(HostError, match="READY not reached"):
        run.recover_from_fault()
    assert run.host.commands.count(Command.RESET) == runner.RECOVERY_TRIES
    run = make_run(tmp_path, "lockstep", 0, monkeypatch)
    run.host = FaultedHost(0)
    with pytest.raises(HostError, match="SELECT_CONTROLLER .* refused: BAD_STATE"):
        run.select("adaptive")
    assert Command.RESET not in run.host.commands
