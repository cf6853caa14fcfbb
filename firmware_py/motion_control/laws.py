"""The controller kinds behind one small interface: each writes the valve inputs as spool
fractions of full input (the valves' unit on the wire), or says it cannot act.

- `JointSpaceLaw`: PI (7.4), adaptive PI+P (7.5) and model-based (11.4): the per-leg pipeline
  (`joint_space.JointController`) computes them in the thesis's volts; this law turns its
  output into spool.
- `ComputedTorqueLaw`: the task-space PID through the inverse dynamics and the valve map
  (`computed_torque.py`), on the hexapod or the test bench's one leg.

Each update is in place on arrays made at construction; `supply_pa` is each valve's supply as
its P-port transducer last read it.
"""

from __future__ import annotations

import numpy as np

from firmware_py.motion_control.joint_space import COMPUTED_TORQUE, MODEL_BASED, JointController


class JointSpaceLaw:
    """One of the thesis's per-leg controllers; its integrator runs in the joint pipeline."""

    runs_joint_law = True

    def __init__(self, kind: int, joint: JointController, full_scale_v: float):
        self.kind, self.joint = int(kind), joint
        self.full_scale_v = np.array(full_scale_v)          # 0-d: no conversion in the cycle
        self.needs_reference_forces = self.kind == MODEL_BASED     # eq. 11.5's tau along the reference

    def reset(self) -> None:
        """Nothing of its own: the joint pipeline clears its integrator while inactive."""

    def update(self, reference, force_n, supply_pa, spool_out) -> bool:
        """The pipeline's input this cycle (V) as spool."""
        np.divide(self.joint.u_v, self.full_scale_v, out=spool_out)
        return True


class ComputedTorqueLaw:
    """Computed torque on the rig's model (`platform`: the hexapod's PlatformModel, None on
    the test bench); the joint pipeline only estimates."""

    runs_joint_law = False
    kind = COMPUTED_TORQUE

    def __init__(self, computed_torque, joint: JointController, platform, needs_reference_forces: bool):
        self.ct, self.joint, self.platform = computed_torque, joint, platform
        self.needs_reference_forces = needs_reference_forces

    def reset(self) -> None:
        """Valves locked or a fault: the integral and the reference-force history start again."""
        self.ct.reset()

    def update(self, reference, force_n, supply_pa, spool_out) -> bool:
        """False: singular (spool_out untouched)."""
        joint, ct = self.joint, self.ct
        ct.supply_from(supply_pa)
        if not ct.update(self.platform, reference.yr, joint.position_read, joint.velocity_estimate, joint.error_m,
                         reference.vr,
                         reference.ar, force_n):
            return False
        np.copyto(spool_out, ct.spool_cmd)
        return True
