"""`hydrapod controller` / `python -m firmware_py`: config validation and CLI errors are one
line and exit 2; the bench prints its table as JSON."""

import json
import subprocess
import sys

import pytest

from firmware_py.config import ConfigError, load_config
from tests.support.cli import hydrapod


def run(args):
    return hydrapod(*args)


@pytest.mark.parametrize("text, culprit", [
    ("[pi]\nkp_v_mm = -1\n", "[pi].kp_v_mm = -1 is out of range [0, 100]"),
    ("[pi]\nkp = 1\n", "unknown key [pi].kp"),
    ("[nope]\nx = 1\n", "unknown section [nope]"),
    ("[supervisor]\nauto_enable = 1\n", "[supervisor].auto_enable = 1 must be true or false"),
    ("[supervisor]\nmissing_frames_fault = 2.5\n", "[supervisor].missing_frames_fault = 2.5 must be an integer"),
    ("[adaptive]\nkp_0kg_v_mm = [0.1, 0.2]\n", "[adaptive].kp_0kg_v_mm has 2 values, table_position_mm has 11"),
    ("[adaptive]\ntable_load_kg = [0.0, 6.0, 3.0]\n", "table_load_kg must hold 3 increasing"),
    ("[actuator]\nrod_radius_mm = 7.0\n", "rod_radius_mm = 7.0 must be smaller than bore_radius_mm"),
    ("[timing\n", "not valid TOML"),
    ("[valve_map]\nspool_pct = [[1.0, 2.0]]\n", "[valve_map].spool_pct is 1x2, force_n x velocity_mm_s is 43x65"),
    ("[valve_map]\npressure_a_bar = [[1.0, 2.0]]\n", "[valve_map].pressure_a_bar is 1x2"),
    ("[valve_map]\nforce_n = [1.0, 0.5]\n", "[valve_map].force_n must hold >= 2 strictly increasing"),
    ("[valve_map]\nspool_pct = 3\n", "[valve_map].spool_pct must be a non-empty list of rows"),
])
def test_config_errors_name_key_value_and_range(tmp_path, text, culprit):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=None) as info:
        load_config(path)
    assert culprit in str(info.value) and "\n" not in str(info.value)
    result = run(["controller", "--config", str(path)])
    assert result.returncode == 2
    assert result.stderr.strip().count("\n") == 0 and culprit in result.stderr, result.stderr


@pytest.mark.parametrize("args, culprit", [
    (["controller", "--bus", "bogus"], "bad bus 'bogus'"),
    (["controller", "--rate-hz", "0"], "--rate-hz"),
    (["controller", "--rig", "crane"], "--rig"),
    (["controller", "--controller", "pid"], "--controller"),
    (["controller", "--config", "/nonexistent.toml"], "no such file"),
])
def test_cli_errors_are_one_line_exit_2(args, culprit):
    result = run(args)
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.strip().count("\n") == 0 and culprit in result.stderr, result.stderr


def test_user_config_overrides_only_what_it_names(tmp_path):
    path = tmp_path / "gains.toml"
    path.write_text("[pi]\nkp_v_mm = 0.1\n")
    cfg = load_config(path)
    assert cfg.pi.kp_v_m == pytest.approx(100.0) and cfg.pi.ki_v_m_s == pytest.approx(460.0)


def test_bench_prints_every_controller_and_rig_as_json():
    result = run(["controller", "bench", "--json", "--cycles", "300"])
    assert result.returncode == 0, result.stderr
    rows = json.loads(result.stdout)["update_step_us"]
    assert {(r["rig"], r["controller"]) for r in rows} == {
        (rig, c) for rig in ("testbench", "hexapod") for c in ("pi", "adaptive", "model-based", "computed-torque")}
    for r in rows:
        assert 0 < r["p50_us"] <= r["p99_us"] <= r["max_us"] and r["state"] == "RUNNING"


@pytest.mark.process
def test_python_m_firmware_py_is_the_same_command():
    result = subprocess.run([sys.executable, "-m", "firmware_py", "--rig", "crane"], capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 2 and "python -m firmware_py" in result.stderr
