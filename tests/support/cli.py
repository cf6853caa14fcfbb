"""`hydrapod ...` run in this process (`hil.cli.main`): its exit code and what it printed.
The entry points themselves (console script, `python -m ...`) have process tests of their own."""

from __future__ import annotations

import argparse
import contextlib
import io
import json
from dataclasses import dataclass
from pathlib import Path

from hil.cli import main


@dataclass
class Result:
    returncode: int
    stdout: str
    stderr: str


def command_parsers(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()):
    """(words, parser) of the command and every subcommand under it, depth first."""
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from command_parsers(sub, (*path, name))


def hydrapod(*args: str) -> Result:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in args])
        except SystemExit as stop:            # argparse's one-line errors exit 2
            code = stop.code if isinstance(stop.code, int) else 1
    return Result(code, out.getvalue(), err.getvalue())


def reanalysed(out: Path, scenario: str, tmp_path: Path) -> tuple[dict, dict]:
    """`hydrapod hil analyze` on a run's log alone: (its metrics.json, the run's own)."""
    proc = hydrapod("hil", "analyze", out / "run.blf", "--scenario", scenario, "--out", tmp_path, "--json")
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads((tmp_path / "metrics.json").read_text()), json.loads((out / "metrics.json").read_text())
