"""A computation in stages: a generator that yields between them and returns its result, so
the loop can spread it over the slack of several cycles (a waypoint commit on the hexapod)."""

from __future__ import annotations

from collections.abc import Generator
from typing import TypeVar

T = TypeVar("T")
Stages = Generator[None, None, T]


def at_once(stages: Stages[T]) -> T:
    """Every stage now: the result."""
    while True:
        try:
            next(stages)
        except StopIteration as done:
            return done.value
