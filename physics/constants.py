"""Physical constants and unit factors to SI: the one home of each."""

GRAVITY_M_S2 = 9.81                 # standard gravity as the thesis uses it
ATMOSPHERE_PA = 101325.0            # absolute pressure of the atmosphere

# thesis and data-sheet units -> SI
MM = 1e-3                           # millimetre
BAR = 1e5                           # bar -> Pa
CM3 = 1e-6                          # cm^3 -> m^3
L_MIN = 1e-3 / 60.0                 # l/min -> m^3/s
KG_MM2 = 1e-6                       # kg mm^2 -> kg m^2
US = 1e-6                           # microsecond
MS = 1e-3                           # millisecond
