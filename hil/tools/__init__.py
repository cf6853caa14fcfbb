"""Host tools around the controller and the emulator: benchmarks, direct-kinematics
evaluation, workspace figures, the dynamics validation against MuJoCo."""
