"""The emulator and the controller as child OS processes: start, watch, stop, report.

Each child's stdout and stderr go to files in the run directory (no pipe can fill up and
block it); a child that exits early or does not stop fails the run with its exit status
and the tail of its stderr.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path


class ChildFailed(RuntimeError):
    """A child process crashed, hung or exited before it was asked to."""


class Child:
    def __init__(self, name: str, argv: list[str], directory: Path):
        self.name, self.argv = name, argv
        self.stdout_path = directory / f"{name}.stdout.log"
        self.stderr_path = directory / f"{name}.stderr.log"
        self.proc: subprocess.Popen | None = None
        self.stopping = False

    def start(self) -> None:
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        with open(self.stdout_path, "w") as out, open(self.stderr_path, "w") as err:
            self.proc = subprocess.Popen([sys.executable, *self.argv], stdout=out, stderr=err, env=env,
                                         stdin=subprocess.DEVNULL)

    @property
    def returncode(self) -> int | None:
        return None if self.proc is None else self.proc.poll()

    def tail(self, lines: int = 15) -> str:
        try:
            text = self.stderr_path.read_text(errors="replace").strip().splitlines()
        except OSError:
            return ""
        return "\n".join(text[-lines:])

    def check_alive(self) -> None:
        """Raise ChildFailed when the child has exited without being asked to."""
        code = self.returncode
        if code is not None and not self.stopping:
            raise ChildFailed(f"{self.name} exited with status {describe_status(code)} during the run; "
                              f"stderr tail:\n{self.tail()}")

    def terminate(self) -> None:
        self.stopping = True
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)

    def wait(self, timeout_s: float) -> int:
        """Wait for the exit; kill a child that does not stop in time (ChildFailed)."""
        try:
            return self.proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            raise ChildFailed(f"{self.name} did not stop within {timeout_s:g} s of SIGTERM and was killed; "
                              f"stderr tail:\n{self.tail()}") from None

    def kill(self) -> None:
        self.stopping = True
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()

    def summary_line(self) -> str:
        """The last line the child printed (both daemons end with a one-line summary)."""
        try:
            lines = self.stdout_path.read_text(errors="replace").strip().splitlines()
        except OSError:
            return ""
        return lines[-1] if lines else ""


def describe_status(code: int) -> str:
    if code < 0:
        try:
            return f"{code} ({signal.Signals(-code).name})"
        except ValueError:
            return str(code)
    return str(code)
