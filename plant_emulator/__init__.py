"""The plant emulator: hydraulics, mechanism (MuJoCo), sensors and CiA 408 node behaviour
on the bus, fault injection. Physics is pure; node behaviour is frames. It imports only
`physics` and `protocol`: what it simulates is its own, independent of the controller.
"""
