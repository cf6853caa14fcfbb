"""The scenarios `hydrapod hil` runs, by name."""

from __future__ import annotations

from ..scenario import Scenario
from .friction import FrictionPresliding, FrictionSteady
from .kick import HexapodKick
from .pm import PmCircle, PmDiagonal
from .realtime import RealtimeHexapod, RealtimeTestbench
from .sha_identification import ShaIdentification
from .sha_step import ShaStep
from .sha_tracking import ShaPerturbation, ShaTracking
from .soak import Soak

SCENARIOS: dict[str, Scenario] = {s.name: s for s in (
    ShaStep(), ShaTracking(), ShaPerturbation(), ShaIdentification(), PmDiagonal(), PmCircle(),
    RealtimeTestbench(), RealtimeHexapod(), Soak(), FrictionSteady(), FrictionPresliding(), HexapodKick())}
