"""A controller's whole state put back in place: every array and plain value of its objects
(`Controller.checkpoint`), for a linearisation by differences that must start each update
from the same state (hil/design/closed_loop.py). A deep copy would turn the views the
controller shares between its parts (the legs' velocity estimate in their Kalman states)
into unrelated arrays; this writes the saved values back into the very arrays.
"""

from __future__ import annotations

import numpy as np


class Checkpoint:
    """Every array and plain value of a controller's objects, put back in place by `restore`
    (a deep copy would turn the views the controller shares between its parts, e.g. the
    legs' velocity estimate in their Kalman states, into unrelated arrays)."""

    PACKAGES = ("firmware_py", "protocol")

    def __init__(self, root):
        self.items: list[tuple[object, str, object]] = []
        seen: set[int] = set()
        stack = [root]
        while stack:
            obj = stack.pop()
            if id(obj) in seen or not hasattr(obj, "__dict__"):
                continue
            seen.add(id(obj))
            for name, value in vars(obj).items():
                if isinstance(value, np.ndarray):
                    self.items.append((obj, name, (value, value.copy())))
                elif value is None or isinstance(value, (bool, int, float, str)):
                    self.items.append((obj, name, value))
                else:
                    members = value if isinstance(value, (list, tuple)) else (value,)
                    stack.extend(m for m in members if type(m).__module__.startswith(self.PACKAGES))

    def restore(self) -> None:
        for obj, name, value in self.items:
            if isinstance(value, tuple):
                array, saved = value
                array[...] = saved
                value = array
            if getattr(obj, name) is not value:          # (frozen configs never change)
                setattr(obj, name, value)
