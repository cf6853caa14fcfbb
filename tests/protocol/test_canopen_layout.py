"""The CANopen device profile's bus budget: each device's frames from its EDS (canopen's own
PDO reading is the oracle), and what carries six legs at 500 Hz."""

import math

import canopen
import pytest

from protocol.busload import MAX_LOAD, MIN_COMPUTE_WINDOW_US, bus_budget, frame_bits_worst
from protocol.canopen_layout import budgets, bus_schedules, device_schedules, load_layout, split_plan
from protocol.devices import object_dictionary
from tests.support.cli import hydrapod


@pytest.mark.parametrize("device", load_layout(6), ids=lambda d: d.name)
def test_each_device_s_pdos_are_what_canopen_reads_from_its_eds(device):
    network = canopen.Network()
    node = canopen.LocalNode(device.node, object_dictionary(device.eds, device.node))
    network.add_node(node)
    oracle = []
    for kind, maps in (("RPDO", node.rpdo), ("TPDO", node.tpdo)):
        maps.read(from_od=True)
        oracle += [(f"{device.name}_{kind}{k}", pdo.cob_id, math.ceil(pdo.length / 8), pdo.trans_type)
                   for k, pdo in maps.map.items() if pdo.enabled]
    ours = [(s.name, s.frame_id, s.dlc, s.sync_period) for s in device_schedules(device) if "PDO" in s.name]
    assert [(n, c, d) for n, c, d, _ in ours] == [(n, c, d) for n, c, d, _ in oracle]
    for (_, _, _, period), (name, _, _, transmission) in zip(ours, oracle):
        assert period == (1 if "RPDO" in name else transmission)        # the controller sends RPDOs each cycle


def test_six_stock_legs_at_500_hz_need_two_buses_or_a_lower_rate():
    one = budgets(500.0, 1e6, 6, 1)[0]
    assert not one["fits"] and one["total_load"] > 1.0                # 6 x (RPDO + 3 TPDOs) every cycle
    plan = split_plan(500.0, 1e6, 6)
    assert plan["fewest_buses"] == 2 and plan["legs_per_bus"] == [[1, 2, 3], [4, 5, 6]]
    two = budgets(500.0, 1e6, 6, 2)
    assert all(b["fits"] and b["total_load"] <= MAX_LOAD and b["compute_window_us"] >= MIN_COMPUTE_WINDOW_US
               for b in two)
    rate = plan["one_bus_rate_hz"]
    assert budgets(rate, 1e6, 6, 1)[0]["fits"] and not budgets(rate + 1, 1e6, 6, 1)[0]["fits"]


def test_every_bus_has_its_sync_and_the_host_and_imu_are_on_the_first():
    first, second = bus_schedules(6, 2)
    names = [{s.name for s in bus} for bus in (first, second)]
    assert "SYNC" in names[0] and "SYNC" in names[1]
    assert {"IMU_TPDO1", "HOST_CMD", "CTRL_STATUS"} <= names[0] and not {"IMU_TPDO1", "HOST_CMD"} & names[1]
    assert {f"LEG{k}_VALVE_RPDO1" for k in (1, 2, 3)} <= names[0] and "LEG4_VALVE_RPDO1" in names[1]
    ids = [s.frame_id for s in first]
    assert len(ids) == len(set(ids))                                   # no two frames share an id


def test_one_stock_leg_fits_one_bus_and_the_load_is_a_brute_force_count():
    frames = bus_schedules(1, 1)[0]
    budget = bus_budget(500.0, 1e6, scheds=frames)
    assert budget["fits"] and split_plan(500.0, 1e6, 1)["one_bus_fits"]
    bits = sum(frame_bits_worst(s.dlc) for c in range(1, 241) for s in frames if s.due(c)) / 240
    bits += sum(frame_bits_worst(s.dlc) * 2.0 / s.cycle_time_ms for s in frames if s.cycle_time_ms)
    assert budget["total_load"] == pytest.approx(bits * 1e-6 / 2e-3, rel=1e-12)


def test_the_command_says_what_carries_them_and_refuses_bad_arguments(capsys):
    from hil.cli import main
    result = hydrapod("bus-load", "--devices", "canopen")          # once as a process: its exit code
    assert result.returncode == 1 and "one bus does not carry them" in result.stdout
    assert "2 buses do (legs 1-3 / legs 4-6; one SYNC each, in phase): --buses 2" in result.stdout
    assert main(["bus-load", "--devices", "canopen", "--buses", "2"]) == 0
    capsys.readouterr()
    for args, culprit in ((("--buses", "2"), "--buses 2: the hydrapod devices' DBC is one bus"),
                          (("--devices", "canopen", "--rig", "testbench", "--buses", "2"),
                           "--buses 2: the testbench has 1 leg(s)")):
        assert main(["bus-load", *args]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and culprit in err[0]
