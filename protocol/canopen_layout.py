"""The CANopen device profile's bus (`protocol/devices/canopen-layout.toml`): which stock
devices sit at which node ids, and what their PDOs put on the bus, read from each device's
EDS with the `canopen` library (`protocol.pdo`): the COB-ID, the mapped objects' bits (the DLC) and the
transmission type (1..240: every n-th SYNC; its SYNC start value, sub-index 6, the phase).
RPDOs are the controller's: it sends each one every cycle. The host protocol and the
controller's own frames (SYNC, CTRL_*, HOST_*, its heartbeat and EMCY) stay the DBC's.
What `busload.bus_budget` budgets for `hydrapod bus-load --devices canopen`.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass

from program.errors import UserInputError
from protocol.dbc import CONTROLLER_NODE, Schedule, schedules
from protocol.devices import DEVICES_DIR, EMCY_BASE, HEARTBEAT_BASE, object_dictionary
from protocol.pdo import RPDO, TPDO, pdo_maps

LAYOUT_FILE = DEVICES_DIR / "canopen-layout.toml"
EMCY_DLC = 8
HEARTBEAT_DLC = 1
LEG_DEVICES = ("valve", "encoder", "leg_sensors")
# the controller's and host's frames that are the same on either profile
OWN_FRAMES = ("SYNC", "CTRL_STATUS", "CTRL_PAYLOAD", "CTRL_CLOCK", "CTRL_LOAD", "CTRL_ACK", "HOST_CMD", "HOST_TEST",
              "HOST_WAYPOINT_POS", "HOST_WAYPOINT_ROT", "HOST_WAYPOINT_TIME", "EMCY_16", "HEARTBEAT_16")


@dataclass(frozen=True)
class Device:
    name: str                  # e.g. LEG3_VALVE, IMU
    eds: str
    node: int
    sync_start: int = 0        # every-n-th-SYNC TPDOs' start value (0: the EDS's)
    leg: int | None = None     # the leg it belongs to (None: the platform's, the IMU)
    settings: tuple[tuple[int, int, int], ...] = ()    # (index, sub-index, value) written before the PDOs
    kind: str = ""             # its table in the layout: valve, encoder, leg_sensors, imu


def _settings(entry: dict, kind: str, path) -> tuple[tuple[int, int, int], ...]:
    """A kind's `settings` table as (index, sub-index, value), each an object of its EDS; a
    key that is not one is a line naming the layout file, the kind and the key."""
    od = object_dictionary(entry["eds"])
    out = []
    for key, value in entry.get("settings", {}).items():
        index, _, sub = key.partition(":")
        try:
            where = (int(index, 16), int(sub or "0", 0))
        except ValueError:
            raise UserInputError(f"{path}: [{kind}] settings key {key!r} is not \"0xIIII\" or \"0xIIII:S\"") from None
        if od.get_variable(*where) is None or not isinstance(value, int) or isinstance(value, bool):
            raise UserInputError(f"{path}: [{kind}] settings {key} = {value!r}: not an integer object of "
                                 f"{entry['eds']}")
        out.append((*where, value))
    return tuple(out)


def load_layout(n_legs: int, path=LAYOUT_FILE) -> list[Device]:
    """The devices of a rig with `n_legs` legs (six: the hexapod, with its IMU)."""
    with open(path, "rb") as handle:
        layout = tomllib.load(handle)
    devices = []
    for leg in range(1, n_legs + 1):
        for kind in LEG_DEVICES:
            entry = layout[kind]
            starts = entry.get("sync_start", [])
            devices.append(Device(f"LEG{leg}_{kind.upper()}", entry["eds"], entry["node"] + leg - 1,
                                  starts[leg - 1] if starts else 0, leg, _settings(entry, kind, path), kind))
    if n_legs == 6:
        devices.append(Device("IMU", layout["imu"]["eds"], layout["imu"]["node"],
                              settings=_settings(layout["imu"], "imu", path), kind="imu"))
    return devices


def _pdos(device: Device, od, sender: str, kind: str) -> list[Schedule]:
    out = []
    for pdo in pdo_maps(od, kind, device.name):
        period = 1 if kind == RPDO else pdo.sync_period
        start = device.sync_start if device.sync_start and period > 1 else pdo.sync_start
        phase = (start - 1) % period if period > 1 and start else 0
        out.append(Schedule(pdo.name, pdo.cob_id, pdo.dlc, sender, period, phase, 0, None))
    return out


def device_schedules(device: Device) -> list[Schedule]:
    """A device's frames: its RPDOs (the controller's), TPDOs, heartbeat and EMCY."""
    od = object_dictionary(device.eds, device.node)
    frames = _pdos(device, od, CONTROLLER_NODE, RPDO)
    frames += _pdos(device, od, device.name, TPDO)
    heartbeat_ms = int(od[0x1017].default) if 0x1017 in od else 0
    if heartbeat_ms:
        frames.append(Schedule(f"{device.name}_HEARTBEAT", HEARTBEAT_BASE + device.node, HEARTBEAT_DLC, device.name,
                               0, 0, heartbeat_ms, None))
    frames.append(Schedule(f"{device.name}_EMCY", EMCY_BASE + device.node, EMCY_DLC, device.name, 0, 0, 0, None))
    return frames


def bus_schedules(n_legs: int, buses: int = 1) -> list[tuple[Schedule, ...]]:
    """Each bus's frames, legs split in order across `buses` (as even as they go); the SYNC
    on every bus, in phase; the host, the controller's own frames and the IMU on the first."""
    if not 1 <= buses <= n_legs:
        raise ValueError(f"buses must be 1..{n_legs}, got {buses}")
    own = {s.name: s for s in schedules()}
    devices = load_layout(n_legs)
    out = []
    for bus in range(buses):
        legs = legs_on_bus(n_legs, buses, bus)
        frames = [own["SYNC"]] + ([own[name] for name in OWN_FRAMES[1:]] if bus == 0 else [])
        for device in devices:
            if device.leg in legs or (device.leg is None and bus == 0):
                frames += device_schedules(device)
        out.append(tuple(sorted(frames, key=lambda s: s.frame_id)))
    return out


def legs_on_bus(n_legs: int, buses: int, bus: int) -> range:
    """The legs on bus `bus` (0-based) when `n_legs` are split in order across `buses`."""
    per_bus = math.ceil(n_legs / buses)
    return range(bus * per_bus + 1, min((bus + 1) * per_bus, n_legs) + 1)


def budgets(rate_hz: float, bitrate: float, n_legs: int, buses: int, **limits) -> list[dict]:
    """`busload.bus_budget` of each bus of the layout split across `buses`."""
    from protocol.busload import bus_budget
    return [bus_budget(rate_hz, bitrate, scheds=frames, **limits) for frames in bus_schedules(n_legs, buses)]


def highest_rate(bitrate: float, n_legs: int, rate_hz: float, **limits) -> float:
    """The highest whole SYNC rate, at most `rate_hz`, at which one bus carries the layout (0: none)."""
    low, high = 0, int(rate_hz)
    while low < high:                        # load and window are monotonic in the rate
        mid = (low + high + 1) // 2
        if budgets(mid, bitrate, n_legs, 1, **limits)[0]["fits"]:
            low = mid
        else:
            high = mid - 1
    return float(low)


def split_plan(rate_hz: float, bitrate: float, n_legs: int, **limits) -> dict:
    """What carries the layout: one bus at `rate_hz`, else the fewest buses that do (legs
    split in order, one SYNC each, in phase), and the highest rate one bus carries."""
    fewest = next((b for b in range(1, n_legs + 1)
                   if all(x["fits"] for x in budgets(rate_hz, bitrate, n_legs, b, **limits))), None)
    return {"rate_hz": rate_hz, "n_legs": n_legs, "one_bus_fits": fewest == 1, "fewest_buses": fewest,
            "legs_per_bus": [list(legs_on_bus(n_legs, fewest, k)) for k in range(fewest)] if fewest else [],
            "one_bus_rate_hz": highest_rate(bitrate, n_legs, rate_hz, **limits)}
