"""What a scenario is: the rig, the controllers, the host's script, the analysis of a log,
and the expected outcome (checks), each beside the thesis's figure."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path

from hil.logdata import LogData
from program.errors import UserInputError


@dataclass
class Check:
    name: str
    passed: bool
    measured: str
    expected: str
    required: bool = True       # False: a thesis comparison reported (and in the closing note), not asserted
    # True: a speed goal (the loop's timing). The command asserts it, as a benchmark does; the
    # test suite asserts the behaviour checks only (a shared CI machine has no RT kernel).
    benchmark: bool = False

    def as_dict(self) -> dict:
        return {"name": self.name, "passed": bool(self.passed), "measured": self.measured, "expected": self.expected,
                "required": self.required, "benchmark": self.benchmark}


@dataclass
class Figure:
    file: str                  # PNG in the run directory
    caption: str               # what it shows
    thesis: str                # the thesis figure it stands beside, and what that figure shows


@dataclass
class Analysis:
    metrics: dict
    thesis: dict
    checks: list[Check]
    figures: list[Figure] = field(default_factory=list)
    tables: list[str] = field(default_factory=list)     # markdown, for report.md and the terminal


class Scenario(ABC):
    name = ""
    title = ""
    chapter = ""
    rig = "testbench"
    pacing = "lockstep"                       # default pacing
    pacings: tuple[str, ...] = ("lockstep", "realtime")
    controllers: tuple[str, ...] = ("pi", "adaptive")
    load_kg = 0.0                             # the emulator's load at start
    sweeps_loads = False                      # runs its script at several loads (`--loads` picks them)
    time_scalable = False                     # its movements' timing scales (`--time-scale`)
    controller_overrides: dict = {}           # controller TOML sections for this experiment
    emulator_overrides: dict = {}

    short_controllers: tuple[str, ...] | None = None     # --short runs only these (None: all)

    def controllers_for(self, chosen: tuple[str, ...] | None, short: bool) -> tuple[str, ...]:
        return chosen or (self.short_controllers if short and self.short_controllers else self.controllers)

    def configure_for(self, controllers: tuple[str, ...]) -> str | None:
        """Adjust this scenario (a copy) for the controllers that will run; a note saying how,
        for the report, or None."""
        return None

    def first_controller(self, chosen: tuple[str, ...] | None, short: bool = False) -> str:
        return self.controllers_for(chosen, short)[0]

    def chosen(self, run) -> tuple[str, ...]:
        return self.controllers_for(run.options.controllers, run.options.short)

    def chosen_loads(self, run, planned: tuple[float, ...]) -> tuple[float, ...]:
        return run.options.loads or planned

    def check_positions(self, positions_m: tuple[float, ...]) -> None:
        """`--positions`: only the scenarios that step at several working positions take it."""
        raise UserInputError(f"--positions: {self.name} does not step at several working positions")

    @abstractmethod
    def script(self, run) -> None:
        """Drive the host during the run."""

    @abstractmethod
    def analyze(self, log: LogData, out: Path | None, rate_hz: float = 500.0) -> Analysis:
        """Metrics and checks from the decoded log alone."""
