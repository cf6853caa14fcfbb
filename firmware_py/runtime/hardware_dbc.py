"""The project's own nodes (the DBC profile): per leg a node sending LEG_STATE every SYNC,
LEG_PRESSURE every 16th and VALVE_STATUS, taking VALVE_CMD; the hexapod's IMU sending
IMU_ATTITUDE and IMU_RATE. Every frame E2E-protected (`protocol.codec`); a node is identified
by SDO against the EDS the configuration names (`[devices] leg_eds`, `imu_eds`).
"""

from __future__ import annotations

from firmware_py.runtime.hardware import Hardware
from protocol.codec import CODECS, FrameDecoder
from protocol.devices import identity_of
from protocol.e2e import E2E_REJECTED, RxStatus
from protocol.interfaces import (
    attitude_into,
    leg_pressure_into,
    leg_state_into,
    rate_into,
    valve_command_values,
)
from protocol.nodes import IMU_NODE, SENDER_OF_NODE, rig_nodes
from protocol.outbox import Outbox


class DbcHardware(Hardware):
    profile = "hydrapod"

    def __init__(self, n_legs: int, has_imu: bool, devices_cfg, stats, clock):
        super().__init__(n_legs, rig_nodes(n_legs), IMU_NODE if has_imu else None, stats, clock)
        self.devices_cfg = devices_cfg
        self.names = {node: SENDER_OF_NODE[node] for node in self.nodes}
        self.valve_nodes = {node for node in self.nodes if node != IMU_NODE}      # a leg node drives its valve
        legs = range(1, n_legs + 1)
        rx = [f"LEG_STATE_{i}" for i in legs] + [f"VALVE_STATUS_{i}" for i in legs]
        rx += [f"LEG_PRESSURE_{i}" for i in legs] + [f"EMCY_{i}" for i in self.nodes]
        rx += [f"HEARTBEAT_{i}" for i in self.nodes]
        if has_imu:
            rx += ["IMU_ATTITUDE", "IMU_RATE"]
        self.decoder = FrameDecoder(rx)
        self.expected = self.decoder.expected_mask([f"LEG_STATE_{i}" for i in legs])
        self._leg_slots = [self.decoder.slot[f"LEG_STATE_{i}"] for i in legs]
        self._leg_values = [self.decoder.values[f"LEG_STATE_{i}"] for i in legs]
        self._leg_of_id = {CODECS[f"LEG_STATE_{i}"].frame_id: i - 1 for i in legs}
        self._heartbeat_of_id = {CODECS[f"HEARTBEAT_{node}"].frame_id: k for k, node in enumerate(self.nodes)}
        self._heartbeat_values = [self.decoder.values[f"HEARTBEAT_{node}"] for node in self.nodes]
        self._emcy_of_id = {CODECS[f"EMCY_{node}"].frame_id: node for node in self.nodes}
        self._emcy_values = {node: self.decoder.values[f"EMCY_{node}"] for node in self.nodes}
        self._pressure_of_id = {CODECS[f"LEG_PRESSURE_{i}"].frame_id: i - 1 for i in legs}
        self._pressure_values = [self.decoder.values[f"LEG_PRESSURE_{i}"] for i in legs]
        self._imu_attitude_id = CODECS["IMU_ATTITUDE"].frame_id if has_imu else -1
        self._imu_values = self.decoder.values["IMU_ATTITUDE"] if has_imu else None
        self._imu_rate_id = CODECS["IMU_RATE"].frame_id if has_imu else -1
        self._imu_rate_values = self.decoder.values["IMU_RATE"] if has_imu else None
        self.out_cmd = [Outbox(f"VALVE_CMD_{i}") for i in legs]

    def filters(self) -> list[dict]:
        return self.decoder.can_filters()

    def dispatch(self, msg) -> bool:
        frame_id = msg.arbitration_id
        status = self.decoder.receive_message(msg)
        if status is RxStatus.UNKNOWN_ID:
            return False
        if status is not RxStatus.OK:
            if status in E2E_REJECTED:
                self.stats.e2e_errors += 1
                leg = self._leg_of_id.get(frame_id)
                if leg is not None:
                    self._rejected[leg] = True
            return True
        if frame_id in self._leg_of_id:
            return True                                  # read() copies it after the window
        leg = self._pressure_of_id.get(frame_id)
        if leg is not None:                              # SI (Pa) from the codec, kept for the next read
            valid = leg_pressure_into(self._pressure_values[leg], self._pressure, leg)
            self._pressure_valid[leg] = valid            # a transducer fault: no piston force
            if valid:
                self._pressure_new[leg] = True
        elif frame_id == self._imu_attitude_id:
            if attitude_into(self._imu_values, self._attitude):
                self._attitude_new = True
        elif frame_id == self._imu_rate_id:
            if rate_into(self._imu_rate_values, self._rate):
                self._rate_new = True
        elif frame_id in self._heartbeat_of_id:
            k = self._heartbeat_of_id[frame_id]
            self.heartbeat(k, int(self._heartbeat_values[k][0]))
        elif frame_id in self._emcy_of_id:
            node = self._emcy_of_id[frame_id]
            self.emergency(node, int(self._emcy_values[node][0]))
        return True

    def restarted(self, node: int) -> None:
        self.decoder.restart_sender(SENDER_OF_NODE[node])      # its alive counters restart too

    def begin_window(self, counter: int) -> None:
        self.decoder.begin_cycle()

    def end_cycle(self) -> int:
        return self.decoder.end_cycle(self.expected)

    def all_fresh(self) -> bool:
        fresh = self.decoder.fresh
        for slot in self._leg_slots:
            if not fresh[slot]:
                return False
        return True

    def read_legs(self, meas) -> None:
        fresh = self.decoder.fresh
        for leg, slot in enumerate(self._leg_slots):
            ok = bool(fresh[slot])
            meas.fresh[leg] = ok
            if ok:
                leg_state_into(self._leg_values[leg], meas, leg)

    def write(self, cmd, send) -> None:
        for leg, box in enumerate(self.out_cmd):
            valve_command_values(box.values, cmd, leg)
            send(box)

    def expected_devices(self) -> dict:
        devices = self.devices_cfg
        return {node: (identity_of(eds), eds) for node in self.nodes
                for eds in [devices.imu_eds if node == IMU_NODE else devices.leg_eds]}

    def prepare(self, client_of, nodes) -> None:
        """The project's nodes carry their frames as built: nothing to configure."""

    def adopt(self, prepared) -> None:
        """Nothing was prepared."""

    def leg_report(self) -> str:
        last = [RxStatus(int(self.decoder.last_status[slot])).name for slot in self._leg_slots]
        return f"last LEG_STATE status {last}"

    def describe(self) -> str:
        return "[devices]"
