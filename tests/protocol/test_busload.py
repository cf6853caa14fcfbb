"""The bus budget, asserted from the DBC: 500 Hz fits classic CAN at 1 Mbit/s, 1 kHz does not."""

import pytest

from protocol.busload import (
    COMPUTE_BUDGET_US,
    MAX_LOAD,
    MIN_COMPUTE_WINDOW_US,
    bus_budget,
    frame_bits_nominal,
    frame_bits_worst,
)
from protocol.dbc import schedules, sync_counter_overflow


@pytest.mark.parametrize("n_bytes, worst, nominal",
                         [(8, 135, 111), (6, 115, 95), (4, 95, 79), (1, 65, 55), (0, 55, 47)])
def test_frame_bits(n_bytes, worst, nominal):
    assert frame_bits_worst(n_bytes) == worst
    assert frame_bits_nominal(n_bytes) == nominal


def test_500hz_classic_can_fits_with_room_for_compute():
    budget = bus_budget(500, 1_000_000)
    assert budget["total_load"] <= MAX_LOAD
    assert budget["compute_window_us"] >= MIN_COMPUTE_WINDOW_US
    assert budget["compute_window_with_blocking_us"] >= COMPUTE_BUDGET_US
    assert budget["nominal_load"] < budget["total_load"]
    assert budget["fits"]


def test_every_cycle_carries_sync_six_sensor_and_six_command_frames():
    budget = bus_budget(500, 1_000_000)
    worst = budget["worst_cycle"]
    fast = {"SYNC"} | {f"LEG_STATE_{n}" for n in range(1, 7)} | {f"VALVE_CMD_{n}" for n in range(1, 7)}
    assert fast <= set(worst["frames"])
    assert len(worst["frames"]) <= len(fast) + 1                 # at most one slow frame per cycle
    phases = [p["phase"] for p in budget["timeline"]]
    assert phases == ["sync", "sensor_frames", "compute", "command_frames"]
    ends = [p["end_us"] for p in budget["timeline"]]
    assert ends == sorted(ends) and ends[-1] == pytest.approx(budget["period_us"])


def test_load_equals_a_brute_force_count_over_the_sync_counter():
    """Independent check: walk one full SYNC counter cycle and add up every frame that is due."""
    rate, bitrate = 500.0, 1_000_000
    overflow = sync_counter_overflow()
    bits = sum(frame_bits_worst(s.dlc) for counter in range(1, overflow + 1) for s in schedules() if s.due(counter))
    seconds = overflow / rate
    bits += sum(frame_bits_worst(s.dlc) * seconds * 1000 / s.cycle_time_ms for s in schedules() if s.cycle_time_ms)
    assert bus_budget(rate, bitrate)["total_load"] == pytest.approx(bits / seconds / bitrate, rel=1e-12)


def test_1khz_does_not_fit_classic_can():
    budget = bus_budget(1000, 1_000_000)
    assert not budget["fits"] and budget["compute_window_us"] < 0


def test_json_fields():
    budget = bus_budget(500, 1_000_000)
    for key in ("rate_hz", "bitrate", "total_load", "nominal_load", "compute_window_us", "messages"):
        assert key in budget
    for m in budget["messages"]:
        assert {"name", "id", "dlc", "bits_worst", "period_cycles"} <= set(m)
    assert {m["name"]: m["period_cycles"] for m in budget["messages"]}["LEG_PRESSURE_1"] == 16


def test_bad_rate_rejected():
    with pytest.raises(ValueError):
        bus_budget(0, 1_000_000)
