"""The physics both sides of the bus share: units, the LuGre friction law, the cylinder's
force balance, and the rig's data files.

The controller uses these equations as its model and the plant emulator as its simulation;
each keeps its own implementation of everything else it computes (the plant's mechanism is
MuJoCo's, the controller's is its own kinematics and virtual-work dynamics), so a modelling
bug on one side shows up in HIL. This package imports nothing else of the project.
"""
