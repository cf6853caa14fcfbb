"""Configuration files of declared sections: each TOML table is a frozen dataclass whose
fields declare their key once (its name in the file, the file's unit, the allowed range in
that unit and the factor to SI); the field holds the SI value.

Layers: the packaged defaults (which must set every key), then the user's file, then
programmatic overrides (thesis units, as in the file). An unknown section or key, a wrong
type or a value out of range raises the file's error class with one line naming the file,
the key, the value and the range; every CLI turns it into exit code 2.

    @frozen
    class Timing(Section):
        spin_s: float = key("spin_us", 0.0, 5000.0, si=US)

    @frozen
    class ControllerConfig(ConfigFile):
        timing: Timing

A key both sides of the bus read is declared once as a `Key` and used by both
(`key(SHARED_KEY)`, or `key(SHARED_KEY, toml="other_name")` where a side names it otherwise).
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from program.errors import UserInputError

# sections and files are frozen; eq off: their arrays have no truth value to compare by
frozen = dataclass(frozen=True, eq=False)
FLOAT, INT, BOOL, STR, NUMBERS, TABLE = "float", "int", "bool", "str", "numbers", "table"


@dataclass(frozen=True)
class Key:
    """One key of a section: its name in the file, its kind, its range in the file's unit
    (numbers), and how the file's value becomes the field's SI value: times `si`, divided
    by `per` (per=MM for N/mm -> N/m, per=100 for a percentage)."""
    toml: str
    low: float | None = None
    high: float | None = None
    si: float = 1.0
    kind: str | None = None          # None: int where both bounds are ints, else float
    per: float = 1.0

    def __post_init__(self):
        if self.kind is None:
            whole = isinstance(self.low, int) and isinstance(self.high, int)
            object.__setattr__(self, "kind", INT if whole else FLOAT)

    @property
    def range(self) -> tuple:
        """(low, high) in the file's unit."""
        return self.low, self.high

    def check(self, value, where: str, error: type[UserInputError]):
        """The file's value, validated; a wrong one raises `error` with one line."""
        if self.kind == BOOL:
            if not isinstance(value, bool):
                raise error(f"{where} = {value!r} must be true or false")
            return value
        if self.kind == STR:
            if not isinstance(value, str):
                raise error(f"{where} = {value!r} must be a string")
            return value
        if self.kind == NUMBERS:
            if not isinstance(value, list) or not value or not all(_finite_number(v) for v in value):
                raise error(f"{where} must be a non-empty list of finite numbers")
            return [float(v) for v in value]
        if self.kind == TABLE:
            if not isinstance(value, list) or not value or not all(
                    isinstance(row, list) and row and all(_finite_number(v) for v in row) for row in value):
                raise error(f"{where} must be a non-empty list of rows of finite numbers")
            if len({len(row) for row in value}) != 1:
                raise error(f"{where} must have rows of one length")
            return [[float(v) for v in row] for row in value]
        if self.kind == INT:
            if not isinstance(value, int) or isinstance(value, bool):
                raise error(f"{where} = {value!r} must be an integer in [{self.low}, {self.high}]")
        elif not _finite_number(value):
            raise error(f"{where} = {value!r} must be a finite number in [{self.low:g}, {self.high:g}]")
        if not self.low <= value <= self.high:
            raise error(f"{where} = {value!r} is out of range [{self.low:g}, {self.high:g}]")
        return value

    def to_si(self, value):
        if self.kind in (NUMBERS, TABLE):
            return np.asarray(value, dtype=float) * self.si / self.per
        if self.kind == FLOAT:
            return float(value) * self.si / self.per
        return value


def _finite_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def key(toml: str | Key, low: float | None = None, high: float | None = None, *, si: float = 1.0,
        per: float = 1.0, kind: str | None = None, name: str | None = None) -> Any:
    """A section's field declared by its key, or by a shared `Key` (`name`: this file's
    name for it). `kind` defaults to int when both bounds are ints, else float."""
    if isinstance(toml, Key):
        declared = dataclasses.replace(toml, toml=name) if name else toml
    else:
        declared = Key(toml, low, high, si, kind, per)
    return dataclasses.field(metadata={"key": declared})


def flag(toml: str) -> Any:
    return key(toml, kind=BOOL)


def numbers(toml: str, *, si: float = 1.0, per: float = 1.0) -> Any:
    """A list of numbers (a 1-D array in SI); its shape is checked by the section."""
    return key(toml, si=si, per=per, kind=NUMBERS)


def table(toml: str, *, si: float = 1.0, per: float = 1.0) -> Any:
    """Rows of numbers (a 2-D array in SI); its shape is checked by the section."""
    return key(toml, si=si, per=per, kind=TABLE)


class Section:
    """A TOML table as a frozen dataclass of SI values. `validate` checks what one key alone
    cannot (a key against another)."""

    @classmethod
    def keys(cls) -> dict[str, Key]:
        """The file's keys of this section, in declaration order."""
        return {f.metadata["key"].toml: f.metadata["key"] for f in dataclasses.fields(cls) if "key" in f.metadata}

    @classmethod
    def from_values(cls, values: dict, where: str, error: type[UserInputError]):
        """The section from validated file values (thesis units), in SI."""
        fields = {f.name: f.metadata["key"].to_si(values[f.metadata["key"].toml])
                  for f in dataclasses.fields(cls) if "key" in f.metadata}
        section = cls(**fields)
        section.validate(where, error)
        return section

    def validate(self, where: str, error: type[UserInputError]) -> None:
        """Checks across keys; none by default."""


@frozen
class ConfigFile:
    """A whole file: one field per section (the field's name is the TOML table's), and
    `raw`, the merged file values in thesis units (what a run writes beside its log)."""

    raw: dict

    @classmethod
    def sections(cls) -> dict[str, type[Section]]:
        hints = typing.get_type_hints(cls)
        return {f.name: hints[f.name] for f in dataclasses.fields(cls) if f.name != "raw"}

    @classmethod
    def schema(cls) -> dict[str, dict[str, Key]]:
        return {name: section.keys() for name, section in cls.sections().items()}

    @classmethod
    def build(cls, raw: dict, source: str, error: type[UserInputError]):
        """The file's sections from merged, validated values (thesis units)."""
        sections = {name: section.from_values(raw[name], f"config {source}: [{name}]", error)
                    for name, section in cls.sections().items()}
        config = cls(raw=raw, **sections)
        config.validate(source, error)
        return config

    def validate(self, source: str, error: type[UserInputError]) -> None:
        """Checks across sections; none by default."""


def read_toml(path: Path, error: type[UserInputError] = UserInputError) -> dict:
    try:
        with open(path, "rb") as handle:
            return tomllib.load(handle)
    except FileNotFoundError:
        raise error(f"config {path}: no such file") from None
    except IsADirectoryError:
        raise error(f"config {path}: is a directory, not a file") from None
    except tomllib.TOMLDecodeError as exc:
        raise error(f"config {path}: not valid TOML: {exc}") from None
    except OSError as exc:
        raise error(f"config {path}: cannot read: {exc.strerror}") from None


Schema = dict[str, dict[str, Key]]


def merge(schema: Schema, base: dict, override: dict, source: str,
          error: type[UserInputError] = UserInputError) -> dict:
    """`base` with `override` applied; every override key validated."""
    merged = {section: dict(values) for section, values in base.items()}
    for section, values in override.items():
        if section not in schema:
            raise error(f"config {source}: unknown section [{section}] (known: {', '.join(schema)})")
        if not isinstance(values, dict):
            raise error(f"config {source}: [{section}] must be a table")
        for name, value in values.items():
            if name not in schema[section]:
                raise error(f"config {source}: unknown key [{section}].{name} (known: {', '.join(schema[section])})")
            merged.setdefault(section, {})[name] = schema[section][name].check(
                value, f"config {source}: [{section}].{name}", error)
    return merged


def load_layered(schema: Schema, defaults_path: Path, path: str | Path | None = None,
                 overrides: dict | None = None, error: type[UserInputError] = UserInputError) -> dict:
    """Defaults (which must set every key), then the user's file, then overrides: the
    merged values in the file's units."""
    raw = merge(schema, {}, read_toml(defaults_path, error), str(defaults_path), error)
    for section, keys in schema.items():
        missing = [k for k in keys if k not in raw.get(section, {})]
        if missing:
            raise error(f"config {defaults_path}: [{section}] lacks {', '.join(missing)}")
    if path is not None:
        raw = merge(schema, raw, read_toml(Path(path), error), str(path), error)
    if overrides:
        raw = merge(schema, raw, overrides, "overrides", error)
    return raw


def load_file(config: type[ConfigFile], defaults_path: Path, path: str | Path | None = None,
              overrides: dict | None = None, error: type[UserInputError] = UserInputError):
    """A config file's sections: packaged defaults, the user's `path`, then `overrides`."""
    raw = load_layered(config.schema(), defaults_path, path, overrides, error)
    return config.build(raw, str(path) if path is not None else str(defaults_path), error)
