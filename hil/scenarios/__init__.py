"""The scenarios `hydrapod hil` runs, by name."""

from __future__ import annotations

from hil.scenario import Scenario
from hil.scenarios.friction import FrictionPresliding, FrictionSteady
from hil.scenarios.guide_free_fall import GuideFreeFall
from hil.scenarios.kick import HexapodKick
from hil.scenarios.pm import PmCircle, PmDiagonal
from hil.scenarios.rt_loop import RealtimeHexapod, RealtimeTestbench
from hil.scenarios.sha_classical import ShaClassical
from hil.scenarios.sha_identification import ShaIdentification
from hil.scenarios.sha_step import ShaStep
from hil.scenarios.sha_tracking import ShaPerturbation, ShaTracking
from hil.scenarios.soak import Soak
from hil.scenarios.stick_slip import ShaStickSlip

SCENARIOS: dict[str, Scenario] = {s.name: s for s in (
    ShaStep(), ShaTracking(), ShaPerturbation(), ShaIdentification(), ShaClassical(), ShaStickSlip(), PmDiagonal(),
    PmCircle(), RealtimeTestbench(), RealtimeHexapod(), Soak(), FrictionSteady(), FrictionPresliding(), HexapodKick(),
    GuideFreeFall())}
