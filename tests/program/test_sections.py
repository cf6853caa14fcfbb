"""Configuration sections (program/sections.py): each key declared once with its unit,
range and SI factor; the defaults, the user's file and overrides in layers; every wrong
value one line naming the file, the key and the range."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from program.errors import UserInputError
from program.sections import ConfigFile, Key, Section, flag, frozen, key, load_file, numbers, table

MM, PCT = 1e-3, 100.0
SHARED = Key("supply_pressure_bar", 1.0, 400.0, si=1e5)


class Wrong(UserInputError):
    pass


@frozen
class Valve(Section):
    stroke_m: float = key("stroke_mm", 1.0, 1000.0, si=MM)
    spread: float = key("spread_pct", 0.0, 100.0, per=PCT)
    count: int = key("count", 1, 10)
    enabled: bool = flag("enabled")
    supply_pa: float = key(SHARED)
    tank_pa: float = key(SHARED, name="tank_pressure_bar")
    gains: np.ndarray = numbers("gains_per_mm", per=MM)
    grid: np.ndarray = table("grid_mm", si=MM)

    def validate(self, where, error) -> None:
        if self.tank_pa >= self.supply_pa:
            raise error(f"{where}.tank_pressure_bar must be below supply_pressure_bar")


@frozen
class File(ConfigFile):
    valve: Valve


DEFAULTS = """[valve]
stroke_mm = 300.0
spread_pct = 13.5
count = 2
enabled = true
supply_pressure_bar = 25.0
tank_pressure_bar = 1.0
gains_per_mm = [1.0, 2.0]
grid_mm = [[1.0, 2.0], [3.0, 4.0]]
"""


@pytest.fixture
def defaults(tmp_path):
    path = tmp_path / "defaults.toml"
    path.write_text(DEFAULTS)
    return path


def test_each_key_is_declared_once_and_read_in_si(defaults):
    cfg = load_file(File, defaults, error=Wrong)
    valve = cfg.valve
    assert valve.stroke_m == pytest.approx(0.3) and valve.spread == pytest.approx(0.135)
    assert valve.count == 2 and isinstance(valve.count, int) and valve.enabled is True
    assert valve.supply_pa == pytest.approx(25e5) and valve.tank_pa == pytest.approx(1e5)
    assert np.allclose(valve.gains, [1e3, 2e3]) and np.allclose(valve.grid, [[1e-3, 2e-3], [3e-3, 4e-3]])
    assert list(Valve.keys()) == ["stroke_mm", "spread_pct", "count", "enabled", "supply_pressure_bar",
                                  "tank_pressure_bar", "gains_per_mm", "grid_mm"]
    assert Valve.keys()["tank_pressure_bar"].range == SHARED.range     # one declaration, two names
    assert cfg.raw["valve"]["stroke_mm"] == 300.0                      # the file's units kept for the log
    with pytest.raises(dataclasses.FrozenInstanceError):
        valve.count = 3


def test_the_users_file_then_overrides_go_over_the_defaults(defaults, tmp_path):
    user = tmp_path / "user.toml"
    user.write_text("[valve]\nstroke_mm = 150.0\ncount = 3\n")
    cfg = load_file(File, defaults, user, {"valve": {"count": 4}}, Wrong)
    assert cfg.valve.stroke_m == pytest.approx(0.15) and cfg.valve.count == 4
    assert cfg.valve.spread == pytest.approx(0.135)                    # untouched keys keep the default


@pytest.mark.parametrize("text,culprit", [
    ("[valve]\nstroke_mm = 2000.0\n", "[valve].stroke_mm = 2000.0 is out of range [1, 1000]"),
    ("[valve]\ncount = 2.5\n", "[valve].count = 2.5 must be an integer in [1, 10]"),
    ("[valve]\ncount = true\n", "[valve].count = True must be an integer"),
    ("[valve]\nenabled = 1\n", "[valve].enabled = 1 must be true or false"),
    ("[valve]\nstroke_mm = nan\n", "[valve].stroke_mm = nan must be a finite number"),
    ("[valve]\nstrokes_mm = 1.0\n", "unknown key [valve].strokes_mm (known: stroke_mm,"),
    ("[valves]\nstroke_mm = 1.0\n", "unknown section [valves] (known: valve)"),
    ("valve = 3\n", "[valve] must be a table"),
    ("[valve]\ngains_per_mm = []\n", "[valve].gains_per_mm must be a non-empty list of finite numbers"),
    ("[valve]\ngrid_mm = [[1.0], [1.0, 2.0]]\n", "[valve].grid_mm must have rows of one length"),
    ("[valve]\ntank_pressure_bar = 30.0\n", "[valve].tank_pressure_bar must be below supply_pressure_bar"),
    ("[valve\n", "not valid TOML"),
])
def test_a_wrong_value_is_one_line_naming_the_file_and_the_key(defaults, tmp_path, text, culprit):
    user = tmp_path / "user.toml"
    user.write_text(text)
    with pytest.raises(Wrong) as raised:
        load_file(File, defaults, user, error=Wrong)
    message = str(raised.value)
    assert culprit in message and str(user) in message and "\n" not in message


def test_defaults_must_set_every_key_and_a_missing_file_is_named(defaults, tmp_path):
    partial = tmp_path / "partial.toml"
    partial.write_text(DEFAULTS.replace("count = 2\n", ""))
    with pytest.raises(Wrong, match=r"\[valve\] lacks count"):
        load_file(File, partial, error=Wrong)
    with pytest.raises(Wrong, match="no such file"):
        load_file(File, defaults, tmp_path / "absent.toml", error=Wrong)
    with pytest.raises(Wrong, match="is a directory"):
        load_file(File, defaults, tmp_path, error=Wrong)
