"""The `hydrapod` command: figures on stdout, user errors as one line and exit 2 (in this
process); the console script and `python -m hil.cli` as processes."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from hil.cli import build_parser
from tests.support.cli import command_parsers, hydrapod

CONSOLE_SCRIPT = Path(sys.executable).with_name("hydrapod")   # installed by `make test` with the package


def test_bus_load_json_at_500hz():
    result = hydrapod("bus-load", "--rate-hz", "500", "--json")
    assert result.returncode == 0, result.stderr
    budget = json.loads(result.stdout)
    assert budget["rate_hz"] == 500 and budget["bitrate"] == 1_000_000
    assert budget["total_load"] <= 0.80 and budget["compute_window_us"] >= 400
    assert any(m["name"] == "VALVE_CMD_6" and m["bits_worst"] == 95 for m in budget["messages"])


def test_bus_load_table_and_exit_1_when_it_does_not_fit():
    ok = hydrapod("bus-load")
    assert ok.returncode == 0 and "compute window" in ok.stdout and ok.stdout.rstrip().endswith("fits")
    too_fast = hydrapod("bus-load", "--rate-hz", "1000")
    assert too_fast.returncode == 1 and "DOES NOT FIT" in too_fast.stdout


def test_protocol_dump_text_and_json():
    text = hydrapod("protocol", "dump")
    assert text.returncode == 0 and "VALVE_CMD_1" in text.stdout and "E2E P01" in text.stdout
    data = json.loads(hydrapod("protocol", "dump", "--json").stdout)
    names = {m["name"] for m in data["messages"]}
    assert {"SYNC", "CTRL_STATUS", "HOST_WAYPOINT_ROT"} <= names


def test_protocol_bench_prints_ordered_percentiles():
    result = hydrapod("protocol", "bench", "--iterations", "300", "--json")
    assert result.returncode == 0, result.stderr
    cases = json.loads(result.stdout)["cases"]
    assert set(cases) == {"receive_leg_state", "encode_valve_cmd", "cycle_6_receive_6_encode"}
    for r in cases.values():
        assert 0 < r["p50_us"] <= r["p99_us"] <= r["max_us"] and r["n"] == 300


@pytest.mark.process
def test_module_entry_point_and_console_script():
    result = subprocess.run([sys.executable, "-m", "hil.cli", "bus-load", "--json"], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0 and json.loads(result.stdout)["fits"]
    assert CONSOLE_SCRIPT.exists(), f"console script missing: {CONSOLE_SCRIPT} (install the package: make test)"
    result = subprocess.run([str(CONSOLE_SCRIPT), "bus-load", "--rate-hz", "abc"], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("args, culprit", [
    (["bus-load", "--rate-hz", "abc"], "--rate-hz"),
    (["bus-load", "--rate-hz", "-5"], "--rate-hz"),
    (["bus-load", "--rate-hz", "nan"], "--rate-hz"),
    (["bus-load", "--bitrate", "2000000"], "--bitrate"),
    (["bus-load", "--max-load", "1.5"], "--max-load"),
    (["bus-load", "--bogus"], "--bogus"),
    (["frobnicate"], "frobnicate"),
    (["protocol"], "dump"),
    (["protocol", "bench", "--iterations", "1e9"], "--iterations"),
    ([], "COMMAND"),
])
def test_user_errors_are_one_line_and_exit_2(args, culprit):
    result = hydrapod(*args)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and culprit in lines[0] and "Traceback" not in result.stderr


def test_every_commands_help_renders():
    """`--help` formats each command's text with %-formatting: a bare % in a help is a traceback."""
    parsers = list(command_parsers(build_parser()))
    assert len(parsers) > 20
    for path, parser in parsers:
        assert parser.format_help(), path
