"""The typed hand-offs between the bus and the controller: what the loop read this cycle
(`Measurements`, the state interfaces) and what the controller commands (`ValveCommands`,
the command interfaces). Both are allocated once; the cycle only writes into them.
"""

from __future__ import annotations

import numpy as np


class Measurements:
    """One cycle's inputs, SI. The loop fills it (it decides nothing); `Controller.update`
    reads it. Node events are the ones seen since the previous cycle's read."""

    def __init__(self, n_legs: int, n_nodes: int):
        # LEG_STATE_n, every cycle
        self.position_m = np.zeros(n_legs)             # encoder stroke from the retracted end
        self.force_n = np.zeros(n_legs)                # load cell, + = the rod pushes the load
        self.valve_state = np.zeros(n_legs, dtype=np.int64)   # CiA 408 state the valve reported
        self.sensor_fault = np.zeros(n_legs, dtype=bool)
        self.spool = np.zeros(n_legs)                  # the valve's actual spool, fraction of full input
        self.fresh = np.zeros(n_legs, dtype=bool)      # a valid LEG_STATE arrived this cycle
        self.rejected = np.zeros(n_legs, dtype=bool)   # a LEG_STATE failed the E2E check this cycle
        # LEG_PRESSURE_n, every 16th cycle: the latest valid sample
        self.pa_pa = np.zeros(n_legs)
        self.pb_pa = np.zeros(n_legs)
        self.ps_pa = np.zeros(n_legs)                  # the supply at the valve's P port
        self.pressure_valid = np.zeros(n_legs, dtype=bool)
        self.pressure_fresh = np.zeros(n_legs, dtype=bool)    # a valid sample arrived since the last cycle
        # IMU_ATTITUDE (hexapod): roll, pitch, yaw of R = Rz Ry Rx
        self.attitude_rad = np.zeros(3)
        self.attitude_fresh = False                    # a valid sample arrived since the last cycle
        # node events
        self.emergency = False                         # an EMCY with an error code from a valve node
        self.imu_emergency = False                     # ... from the IMU
        self.heartbeat_age_s = np.zeros(n_nodes)       # since each node's last heartbeat
        self.stalled = False                           # the loop's clock ran past the stall limit
        self.overrun = False                           # the previous cycle missed its deadline


class ValveCommands:
    """One cycle's outputs per leg: the CiA 408 control word (CW_D power stage enabled,
    CW_H hold, CW_M device mode active, CW_R reset on its rising edge) as 0/1 and the spool
    setpoint as a fraction of full valve input."""

    def __init__(self, n_legs: int):
        self.enable = np.ones(n_legs)       # CW_D
        self.hold = np.ones(n_legs)         # CW_H
        self.active = np.zeros(n_legs)      # CW_M
        self.reset = np.zeros(n_legs)       # CW_R
        self.spool = np.zeros(n_legs)

    def hold_all(self) -> None:
        """Every valve to HOLD: powered, spool centred."""
        self.enable[:] = 1.0
        self.hold[:] = 1.0
        self.active[:] = 0.0
        self.reset[:] = 0.0
        self.spool[:] = 0.0

    def disable_all(self) -> None:
        """Every valve DISABLED: power stage off, spool centred by its spring."""
        self.hold_all()
        self.enable[:] = 0.0
        self.hold[:] = 0.0
