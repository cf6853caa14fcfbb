"""The identified actuator of Table A.3 as a discrete plant for closed-loop tests.

P(s) = Y/Xv = k01 b0 / (s (s^2 + b1 s + b0)), Y in mm, Xv in V (thesis units); here in SI
(metres, volts), discretised with a zero-order hold at the loop period. The valve command
computed in cycle k acts from SYNC k+1 (one cycle of latency, docs/ARCHITECTURE.md "Timing model");
the encoder quantises to 0.125 mm; the load cell reads m (y'' + g).
"""

import numpy as np
from scipy import signal

from hil.metrics import step_response

TABLE_A3 = {  # Po mm: (b0, b1, k01) for 0, 3, 6 kg
    60: ((12036, 116, 249), (9929, 102, 245), (8453, 94, 236)),
    150: ((11425, 106, 236), (9591, 97, 229), (7696, 90, 227)),
    240: ((13754, 112, 264), (11270, 104, 265), (9106, 96, 265)),
}
LOADS = (0.0, 3.0, 6.0)


class LinearPlant:
    def __init__(self, b0, b1, k01, period_s, y0_m, load_mass_kg=1.35, resolution_m=0.125e-3):
        a = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, -b0, -b1]])
        b = np.array([[0.0], [0.0], [k01 * 1e-3 * b0]])          # mm/s/V -> m/s/V
        ad, bd, *_ = signal.cont2discrete((a, b, np.eye(3), np.zeros((3, 1))), period_s, method="zoh")
        self.ad, self.bd = ad, bd[:, 0]
        self.x = np.array([y0_m, 0.0, 0.0])
        self.mass = load_mass_kg
        self.resolution = resolution_m
        self.pending_u = 0.0

    def measure(self):
        y = round(self.x[0] / self.resolution) * self.resolution
        force = self.mass * (self.x[2] + 9.81)
        return y, force

    def advance(self, u_volts):
        """One period with the command of the previous cycle; `u_volts` acts from the next."""
        self.x = self.ad @ self.x + self.bd * self.pending_u
        self.pending_u = u_volts


def step_metrics(t, y, y0, step):
    """Overshoot (%) and 5 % settling time (s) of a step from y0 by `step` (the HIL metric)."""
    m = step_response(t, y, y0, step)
    return m["overshoot_pct"], m["settling_s"]
