"""The sensor faults the host injects, substituted into what a leg's transducers report:
an encoder that drifts (it reads in its own counts: the drift shifts the measurand), an
encoder and load cell frozen at their onset (STUCK), a load cell frozen (FORCE_STUCK), reading
zero (FORCE_ZERO) or out of range (OUT_OF_RANGE, saturating at the wire's maximum)."""

from __future__ import annotations

from plant_emulator.injected import InjectedFaults
from protocol.enums import EmuFault

OUT_OF_RANGE_DEFAULT_N = 1e9            # saturates at the DBC's maximum


def encoder_drift_m(faults: InjectedFaults, node: int, rig_time_s: float) -> float:
    """ENCODER_DRIFT (um/s since its onset): how far the encoder has drifted by now."""
    rate = faults.param(node, EmuFault.ENCODER_DRIFT)
    if rate is None:
        return 0.0
    start = faults.onset_values.setdefault((node, EmuFault.ENCODER_DRIFT), rig_time_s)
    return rate * 1e-6 * (rig_time_s - start)


def substitute(faults: InjectedFaults, node: int, position_m: float, force_n: float) -> tuple[float, float]:
    """What the leg's encoder and load cell report under the node's sensor faults."""
    if faults.get(node, EmuFault.STUCK):
        position_m, force_n = faults.onset_values.setdefault((node, EmuFault.STUCK), (position_m, force_n))
    if faults.get(node, EmuFault.FORCE_STUCK):
        force_n = faults.onset_values.setdefault((node, EmuFault.FORCE_STUCK), force_n)
    if faults.get(node, EmuFault.FORCE_ZERO):
        force_n = 0.0
    value = faults.param(node, EmuFault.OUT_OF_RANGE)
    if value is not None:
        force_n = float(value) if value else OUT_OF_RANGE_DEFAULT_N
    return position_m, force_n
