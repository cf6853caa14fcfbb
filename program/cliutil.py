"""CLI plumbing shared by every hydrapod command: one-line errors, exit code 2.

A user-input problem (bad argument, bad bus string, bad config value) ends the command
with exactly one line on stderr naming the culprit and exit code 2, never a traceback.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from collections.abc import Callable
from pathlib import Path

from program.errors import UserInputError

EXIT_USAGE = 2


class OneLineArgumentParser(argparse.ArgumentParser):
    """argparse with errors reduced to a single line (no usage dump)."""

    def error(self, message: str):
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        sys.exit(EXIT_USAGE)


def number_in_range(kind: type, low: float | None = None, high: float | None = None,
                    *, low_open: bool = False) -> Callable[[str], float]:
    """argparse `type=` that parses `kind` and enforces [low, high] (or (low, high])."""
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a valid {kind.__name__}") from None
        if value != value or value in (float("inf"), float("-inf")):
            raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
        if low is not None and (value <= low if low_open else value < low):
            raise argparse.ArgumentTypeError(f"{text} is out of range: must be {'>' if low_open else '>='} {low:g}")
        if high is not None and value > high:
            raise argparse.ArgumentTypeError(f"{text} is out of range: must be <= {high:g}")
        return value
    parse.__name__ = kind.__name__
    parse.kind, parse.low, parse.high, parse.low_open = kind, low, high, low_open   # for the error-path tests
    return parse


def output_dir(path: str | Path, option: str = "--out") -> Path:
    """A directory a command writes into, made now; one line naming `option` when it cannot be."""
    out = Path(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise UserInputError(f"{option} {out}: cannot create the directory ({error.strerror})") from None
    return out


def output_file(text: str) -> str:
    """argparse `type=` for a file written at the end of a run (a summary): its directory
    must exist and be writable now, not after an hour of running."""
    path = Path(text)
    parent = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} is a directory")
    if not parent.is_dir():
        raise argparse.ArgumentTypeError(f"{text!r}: no such directory {str(parent)!r}")
    if not os.access(parent, os.W_OK | os.X_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise argparse.ArgumentTypeError(f"{text!r}: not writable")
    return text


def run(handler: Callable[[argparse.Namespace], int], args: argparse.Namespace, prog: str) -> int:
    """Run a subcommand; user-input errors become one line and exit 2."""
    try:
        return handler(args)
    except UserInputError as error:
        sys.stderr.write(f"{prog}: error: {error}\n")
        return EXIT_USAGE
    except BrokenPipeError:            # `hydrapod ... | head`: the reader left, not an error
        sys.stderr.close()
        return 0


class StopFlag:
    """SIGTERM / SIGINT set it; the loop checks it between frames."""

    def __init__(self):
        self.stopped = False
        self.signal = None
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, self._set)

    def _set(self, signum, _frame) -> None:
        self.stopped = True
        self.signal = signum

    def __call__(self) -> bool:
        return self.stopped
