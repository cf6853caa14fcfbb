"""The platform's yaw from the IMU beside the legs (beyond the thesis).

With the legs within a few degrees of vertical, 1 deg of yaw is 0.134 mm of the legs'
alternating pattern, about one encoder count (0.125 mm): the legs cannot see the yaw they
let swing. The IMU can (IMU_ATTITUDE and IMU_RATE, every 16th SYNC). A complementary filter
keeps what each sees well:

    yaw = psi_imu + o,    psi_imu: the IMU's yaw at its sample, then + r dt each cycle
                          (r: the gyro's rate about the base's vertical, held until the next)
    o  += alpha (psi_legs - psi_imu - o),   alpha = dt / blend_s

so above 1 / (2 pi blend_s) Hz the yaw is the IMU's and below it the legs' (their direct
kinematics: no drift, the IMU's mounting and its own yaw drift taken out). Older than
`max_age_s` (0: always) since the IMU's last attitude (a silent or invalid IMU), the estimate is not
valid and the controller uses the legs alone. Allocation-free; every array is made here.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# state's slots
S_YAW, S_OFFSET, S_RATE, S_AGE, S_SAMPLE = range(5)


@njit(cache=True)
def wrapped(angle: float) -> float:
    """`angle` in (-pi, pi]."""
    return angle - 2.0 * math.pi * math.floor((angle + math.pi) / (2.0 * math.pi))


@njit(cache=True)
def quat_yaw(quat_wxyz) -> float:
    """The yaw of R = Rz(yaw) Ry(pitch) Rx(roll) (the bus's roll-pitch-yaw) of a quaternion."""
    w, x, y, z = quat_wxyz[0], quat_wxyz[1], quat_wxyz[2], quat_wxyz[3]
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


@njit(cache=True)
def vertical_rate(attitude_rpy, rate_body) -> float:
    """The rate about the base's vertical of a body rate: the third row of R = Rz Ry Rx."""
    roll, pitch = attitude_rpy[0], attitude_rpy[1]
    return (-math.sin(pitch) * rate_body[0] + math.cos(pitch) * math.sin(roll) * rate_body[1]
            + math.cos(pitch) * math.cos(roll) * rate_body[2])


@njit(cache=True)
def yaw_fusion_step(state, legs_yaw, attitude_rpy, attitude_fresh, rate_body, rate_fresh, period_s, alpha,
                    max_age_s) -> bool:
    """One cycle of the filter (state: yaw, offset, rate, age; NaN yaw: no sample yet);
    True when the estimate is valid."""
    if rate_fresh:
        state[S_RATE] = vertical_rate(attitude_rpy, rate_body)
    if attitude_fresh:
        if math.isnan(state[S_YAW]):                     # the first sample: start on the legs
            state[S_OFFSET] = wrapped(legs_yaw - attitude_rpy[2])
        state[S_YAW] = attitude_rpy[2]
        state[S_SAMPLE] = attitude_rpy[2]
        state[S_AGE] = 0.0
    elif not math.isnan(state[S_YAW]):
        state[S_YAW] = wrapped(state[S_YAW] + state[S_RATE] * period_s)
        state[S_AGE] += period_s
    if math.isnan(state[S_YAW]):
        return False
    state[S_OFFSET] += alpha * wrapped(legs_yaw - state[S_YAW] - state[S_OFFSET])
    return state[S_AGE] < max_age_s


@njit(cache=True)
def with_yaw_into(pose, yaw, out) -> None:
    """out = pose (x, y, z, qw, qx, qy, qz) turned about the base's vertical to `yaw`."""
    half = 0.5 * wrapped(yaw - quat_yaw(pose[3:7]))
    c, s = math.cos(half), math.sin(half)
    w, x, y, z = pose[3], pose[4], pose[5], pose[6]
    out[0], out[1], out[2] = pose[0], pose[1], pose[2]
    out[3], out[4], out[5], out[6] = c * w - s * z, c * x - s * y, c * y + s * x, c * z + s * w


class YawFusion:
    """The filter's state; `update` each cycle, then `valid`, `yaw_rad`, `sampled_yaw_rad`
    and `rate_rad_s`."""

    def __init__(self, period_s: float, blend_s: float, max_age_s: float):
        self.period_s, self.max_age_s = period_s, max_age_s
        self.alpha = period_s / blend_s
        self.state = np.zeros(5)
        self.valid = False
        self.reset()

    def reset(self) -> None:
        """No sample yet (a new activation, or the IMU rebooted)."""
        self.state[:] = (math.nan, 0.0, 0.0, math.inf, math.nan)
        self.valid = False

    def warm_up(self) -> None:
        """Load every kernel now (a sample, a cycle after it, the pose turned), then forget."""
        rpy, pose = np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
        for fresh in (True, False):
            self.update(quat_yaw(pose[3:7]), rpy, fresh, rpy, fresh)
        with_yaw_into(pose, self.yaw_rad, np.empty(7))
        self.reset()

    def update(self, legs_yaw: float, attitude_rpy, attitude_fresh: bool, rate_body, rate_fresh: bool) -> bool:
        self.valid = yaw_fusion_step(self.state, legs_yaw, attitude_rpy, attitude_fresh, rate_body, rate_fresh,
                                     self.period_s, self.alpha, self.max_age_s)
        return self.valid

    @property
    def yaw_rad(self) -> float:
        return wrapped(self.state[S_YAW] + self.state[S_OFFSET])

    @property
    def sampled_yaw_rad(self) -> float:
        """The IMU's last sample with the offset, not carried on by the held rate: what a fault
        is judged on (past a turn the held rate carries the estimate beyond the platform)."""
        return wrapped(self.state[S_SAMPLE] + self.state[S_OFFSET])

    @property
    def rate_rad_s(self) -> float:
        return self.state[S_RATE]
