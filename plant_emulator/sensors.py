"""What the rig's transducers report of its state at a SYNC, in SI before the wire (the
codecs round to the DBC's resolution after): each leg's encoder in counts of its resolution,
its load cell and chamber and supply transducers with their noise, and the platform's IMU.
The noise is drawn from one seeded generator in a fixed order, so a run repeats.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from physics import hydraulics as hy
from plant_emulator.params import Sensors


def attitude_rpy(quat_wxyz) -> np.ndarray:
    """(roll, pitch, yaw) of the bus's convention R = Rz(yaw) Ry(pitch) Rx(roll), from
    MuJoCo's rotation matrix of the body's quaternion (SciPy's Rotation is the tests' oracle)."""
    rot = np.empty(9)
    mujoco.mju_quat2Mat(rot, np.asarray(quat_wxyz, dtype=float))
    pitch = math.asin(max(-1.0, min(1.0, -rot[6])))
    return np.array([math.atan2(rot[7], rot[8]), pitch, math.atan2(rot[3], rot[0])])


class SensorModel:
    def __init__(self, sensors: Sensors, rng: np.random.Generator):
        self.encoder_m = sensors.encoder_resolution_m
        self.load_cell_noise_n = sensors.load_cell_noise_n
        self.pressure_noise_pa = sensors.pressure_noise_pa
        self.angle_noise_rad, self.rate_noise_rad_s = sensors.imu_angle_noise_rad, sensors.imu_rate_noise_rad_s
        self.rng = rng

    def encoder(self, stroke_m: float) -> float:
        """The encoder's reading of a stroke: whole counts."""
        return round(stroke_m / self.encoder_m) * self.encoder_m

    def load_cell(self, force_n: float) -> float:
        return force_n + self.load_cell_noise_n * self.rng.standard_normal()

    def pressures(self, rig, leg: int, out) -> None:
        """PA, PB and the supply at the valve's P port, each with its transducer's noise."""
        noise, rng = self.pressure_noise_pa, self.rng
        out[0] = rig.state[leg, hy.S_PA] + noise * rng.standard_normal()
        out[1] = rig.state[leg, hy.S_PB] + noise * rng.standard_normal()
        out[2] = rig.supply_pressure_pa + noise * rng.standard_normal()

    def attitude(self, rig, out) -> None:
        """The IMU's roll, pitch and yaw of the platform (its orientation filter's noise)."""
        _, quat = rig.platform_pose()
        out[:] = attitude_rpy(quat) + self.angle_noise_rad * self.rng.standard_normal(3)

    def rate(self, rig, out) -> None:
        """The IMU's angular rate in the platform frame."""
        out[:] = rig.platform_body_rate() + self.rate_noise_rad_s * self.rng.standard_normal(3)
