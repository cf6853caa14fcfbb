"""The hydraulic power unit (thesis 8.2.2, Fig. 8.4): a gear pump of fixed flow behind a
relief valve that sets the supply pressure, feeding the six servo-valves through the pressure
line's hoses and distributor, and a gas accumulator where one is fitted.

The supply pressure is a state: the line's compliance C (oil and hose walls, eq. 4.11's bulk
modulus, plus the accumulator's gas above its precharge, isothermal) integrates the pump's flow
less what the valves' P edges draw and what the relief passes,

    C(ps) dps/dt = Q_pump - sum_i Q_P,i(ps) - Q_relief(ps),
    Q_relief = Q_pump (ps - ps_set + override) / override   for ps above its cracking pressure,

so at rest the relief passes the whole pump flow at the set pressure, and legs drawing
together can take at most Q_pump before the supply falls. Linearly implicit in ps (the relief
and the open valves make it stiff: ~0.2 ms without an accumulator). Pure and in place."""

from __future__ import annotations

import numba
import numpy as np

from physics.constants import ATMOSPHERE_PA, BAR, CM3, L_MIN
from program.sections import Key, Section, frozen, key

PUMP_FLOW = Key("pump_flow_l_min", 0.1, 1000.0, L_MIN)     # the gear pump's delivery

# -- parameter vector (filled by `pack`) ---------------------------------------------------
PU_PUMP = 0            # pump flow [m^3/s]
PU_SET = 1             # the relief's set pressure: the supply at rest [Pa gauge]
PU_OVERRIDE = 2        # the relief's rise from cracking to the full pump flow [Pa]
PU_LINE_C = 3          # the pressure line's compliance [m^3/Pa]
PU_GAS = 4             # accumulator gas volume at its precharge [m^3] (0: none)
PU_PRECHARGE = 5       # its precharge [Pa absolute]
PU_SIZE = 6


@frozen
class PowerUnitSection(Section):
    """The power unit: a [power_unit] table's keys (the set pressure is the actuator's supply)."""
    pump_flow_m3_s: float = key(PUMP_FLOW)
    relief_override_pa: float = key("relief_override_bar", 0.01, 50.0, si=BAR)
    line_volume_m3: float = key("line_volume_cm3", 1.0, 1e5, si=CM3)
    line_bulk_modulus_pa: float = key("line_bulk_modulus_bar", 100.0, 30000.0, si=BAR)
    accumulator_gas_m3: float = key("accumulator_gas_cm3", 0.0, 1e5, si=CM3)
    accumulator_precharge_pa: float = key("accumulator_precharge_bar", 1.0, 400.0, si=BAR)


def pack(section: PowerUnitSection, supply_pa: float) -> np.ndarray:
    """The parameter vector of the power unit set to `supply_pa` (gauge)."""
    pu = np.zeros(PU_SIZE)
    pu[PU_PUMP], pu[PU_SET] = section.pump_flow_m3_s, supply_pa
    pu[PU_OVERRIDE] = section.relief_override_pa
    pu[PU_LINE_C] = section.line_volume_m3 / section.line_bulk_modulus_pa
    pu[PU_GAS] = section.accumulator_gas_m3
    pu[PU_PRECHARGE] = section.accumulator_precharge_pa + ATMOSPHERE_PA
    return pu


@numba.njit(cache=True)
def compliance(ps: float, pu: np.ndarray) -> float:
    """dV/dp of the pressure line [m^3/Pa]: the line's own, and the accumulator's gas once the
    pressure is above its precharge (isothermal: V = V0 p0 / p)."""
    c = pu[PU_LINE_C]
    p = ps + ATMOSPHERE_PA
    if pu[PU_GAS] > 0.0 and p > pu[PU_PRECHARGE]:
        c += pu[PU_GAS] * pu[PU_PRECHARGE] / (p * p)
    return c


@numba.njit(cache=True)
def relief_flow(ps: float, pu: np.ndarray):
    """(flow, d flow / d ps) the relief valve passes to the tank."""
    slope = pu[PU_PUMP] / pu[PU_OVERRIDE]
    opened = ps - (pu[PU_SET] - pu[PU_OVERRIDE])
    if opened <= 0.0:
        return 0.0, 0.0
    return slope * opened, slope


@numba.njit(cache=True)
def supply_step(ps: float, drawn_m3_s: float, drawn_slope: float, h: float, pu: np.ndarray) -> float:
    """The supply pressure after h with the valves drawing `drawn_m3_s` from it (their slope
    d drawn / d ps: the implicit part), floored at the atmosphere's."""
    relief, relief_slope = relief_flow(ps, pu)
    rate = pu[PU_PUMP] - drawn_m3_s - relief
    return max(ps + h * rate / (compliance(ps, pu) + h * (relief_slope + drawn_slope)), 0.0)


def usable_volume(pu: np.ndarray, from_pa: float, to_pa: float) -> float:
    """The oil [m^3] the pressure line and the accumulator give while the supply falls from
    `from_pa` to `to_pa` (gauge): the integral of `compliance`, the gas's isothermal law in
    closed form above its precharge."""
    line = pu[PU_LINE_C] * (from_pa - to_pa)
    if pu[PU_GAS] <= 0.0:
        return line
    p_from = max(from_pa + ATMOSPHERE_PA, pu[PU_PRECHARGE])
    p_to = max(to_pa + ATMOSPHERE_PA, pu[PU_PRECHARGE])
    return line + pu[PU_GAS] * pu[PU_PRECHARGE] * (1.0 / p_to - 1.0 / p_from)
