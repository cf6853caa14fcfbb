"""The thesis's numbers the design tools and friction scenarios compare against: the
project's own copies in hil/design/data (read once; nothing outside the project at run time)."""

from __future__ import annotations

import tomllib
from functools import cache
from importlib import resources


@cache
def thesis_data(name: str) -> dict:
    """data/NAME.toml (chapter6: Tables 6.1/6.2 and the experiments; chapter7: eq. 7.13-7.27,
    Table 7.2). Shared: callers read it, never change it."""
    with resources.files("hil.design").joinpath(f"data/{name}.toml").open("rb") as handle:
        return tomllib.load(handle)
