"""The controller: what would run on the rig's controller. Kinematics, dynamics, trajectory,
estimation, control, supervision, the fixed-step loop and the daemon. Pure computation takes
arrays and writes into preallocated arrays; only `loop` and `daemon` touch the bus.
"""
