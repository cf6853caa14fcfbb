"""The plant emulator: hydraulics, friction, mechanism, sensors and CiA 408 node behaviour
on the bus, fault injection. Physics is pure; node behaviour is frames. (Built by the
later issues.)
"""

import firmware_py  # noqa: F401  (sets numba's cache directory before any kernel compiles)
