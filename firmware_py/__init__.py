"""The controller: kinematics, dynamics, trajectory, estimation, control, supervisor, the
fixed-step loop and the daemon. Pure math modules take arrays and write into preallocated
arrays; only the loop/daemon modules touch the bus. (Built by the later issues.)
"""

from .numba_cache import configure as _configure_numba_cache

_configure_numba_cache()
