"""Layered TOML configuration with a range for every key (shared by the emulator and the
controller): packaged defaults, then the user's file, then programmatic overrides.

A schema maps section -> key -> spec, where spec is `(low, high)` (ints when both bounds
are ints), `bool`, `str` (any string) or `None` (a non-empty list of finite numbers,
checked further by its user). An unknown section or key, a wrong type or a value out of
range raises the caller's error class with one line naming the file, the key, the value
and the allowed range; the CLI turns it into exit code 2.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

from program.errors import UserInputError

Schema = dict[str, dict[str, object]]


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


TABLE = "table"             # a schema entry: a list of rows of numbers (a 2-D table)


def check_value(schema: Schema, source: str, section: str, key: str, value,
                error: type[UserInputError] = UserInputError):
    spec = schema[section][key]
    where = f"config {source}: [{section}].{key}"
    if spec is bool:
        if not isinstance(value, bool):
            raise error(f"{where} = {value!r} must be true or false")
        return value
    if spec is str:
        if not isinstance(value, str):
            raise error(f"{where} = {value!r} must be a string")
        return value
    if spec == TABLE:                                 # rows of numbers, checked by its user
        if not isinstance(value, list) or not value or not all(
                isinstance(row, list) and row and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                      and math.isfinite(v) for v in row) for row in value):
            raise error(f"{where} must be a non-empty list of rows of finite numbers")
        return [[float(v) for v in row] for row in value]
    if spec is None:                                  # numeric list, checked by its user
        if not isinstance(value, list) or not value or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value):
            raise error(f"{where} must be a non-empty list of finite numbers")
        return [float(v) for v in value]
    low, high = spec
    if isinstance(low, int) and isinstance(high, int):
        if not isinstance(value, int) or isinstance(value, bool):
            raise error(f"{where} = {value!r} must be an integer in [{low}, {high}]")
    elif not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
        raise error(f"{where} = {value!r} must be a finite number in [{low:g}, {high:g}]")
    if not low <= value <= high:
        raise error(f"{where} = {value!r} is out of range [{low:g}, {high:g}]")
    return value


def merge(schema: Schema, base: dict, override: dict, source: str,
          error: type[UserInputError] = UserInputError) -> dict:
    """`base` with `override` applied; every override key validated."""
    merged = {section: dict(values) for section, values in base.items()}
    for section, values in override.items():
        if section not in schema:
            raise error(f"config {source}: unknown section [{section}] (known: {', '.join(schema)})")
        if not isinstance(values, dict):
            raise error(f"config {source}: [{section}] must be a table")
        for key, value in values.items():
            if key not in schema[section]:
                raise error(f"config {source}: unknown key [{section}].{key} (known: {', '.join(schema[section])})")
            merged.setdefault(section, {})[key] = check_value(schema, source, section, key, value, error)
    return merged


def load_layered(schema: Schema, defaults_path: Path, path: str | Path | None = None,
                 overrides: dict | None = None, error: type[UserInputError] = UserInputError) -> dict:
    """Defaults (which must set every key), then the user's file, then overrides."""
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
