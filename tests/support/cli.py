"""`hydrapod ...` run in this process (`hil.cli.main`): its exit code and what it printed.
The entry points themselves (console script, `python -m ...`) have process tests of their own."""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass

from hil.cli import main


@dataclass
class Result:
    returncode: int
    stdout: str
    stderr: str


def hydrapod(*args: str) -> Result:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in args])
        except SystemExit as stop:            # argparse's one-line errors exit 2
            code = stop.code if isinstance(stop.code, int) else 1
    return Result(code, out.getvalue(), err.getvalue())
