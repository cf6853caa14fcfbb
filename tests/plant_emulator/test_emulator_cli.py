"""`hydrapod emulator` CLI: calibrate and bench print their tables; user errors are one line, exit 2."""

import json
import subprocess
import sys

import pytest

from tests.support.cli import hydrapod


def test_calibrate_json_has_every_point_beside_table_a3():
    result = hydrapod("emulator", "calibrate", "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert len(report["points"]) == 33 and report["summary"]["points"] == 33
    first = report["points"][0]
    assert set(first["ratio"]) == {"b0", "b1", "k01"} and first["thesis"]["b0"] == 13345
    assert "linearisation" in report["method"]


def test_bench_json_reports_realtime_factors():
    result = hydrapod("emulator", "bench", "--json", "--seconds", "0.2")
    assert result.returncode == 0, result.stderr
    rows = {r["rig"]: r for r in json.loads(result.stdout)}
    assert set(rows) == {"testbench", "hexapod"}
    assert all(r["realtime_factor"] > 0 for r in rows.values())


def test_bad_config_and_arguments_are_one_line_exit_2(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[nodes]\ncommand_timeout_syncs = 0\n")
    for args, culprit in (
            (("emulator", "calibrate", "--config", str(bad)), "command_timeout_syncs"),
            (("emulator", "--bus", "udp_multicast:10.0.0.1", "--rig", "testbench"), "not a multicast"),
            (("emulator", "--load-kg", "-1"), "--load-kg"),
            (("emulator", "calibrate", "--fit", "nonsense"), "nonsense")):
        result = hydrapod(*args)
        assert result.returncode == 2, (args, result.stderr)
        assert len(result.stderr.strip().splitlines()) == 1 and culprit in result.stderr, result.stderr


@pytest.mark.process
def test_python_m_plant_emulator_is_the_emulator_command():
    result = subprocess.run([sys.executable, "-m", "plant_emulator", "--rig", "crane"], capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 2 and "python -m plant_emulator" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
