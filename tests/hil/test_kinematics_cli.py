"""`hydrapod kinematics ...` from the command line: JSON outputs, plots, one-line errors."""

import json
from pathlib import Path

import pytest

from tests.support.cli import hydrapod


def run(*args, check=True):
    result = hydrapod(*args)
    if check:
        assert result.returncode == 0, result.stderr
    return result


def test_dk_eval_json_reports_every_guess_class_and_beats_the_thesis_near_the_pose():
    report = json.loads(run("kinematics", "dk-eval", "--samples", "2000", "--seed", "5", "--json").stdout)
    rows = {r["guess"]: r for r in report["results"]}
    assert list(rows) == ["qH", "q1", "q10", "q25", "q50"]
    assert rows["qH"]["convergence_pct"] == 100.0 and rows["qH"]["acc2_pct"] == 100.0
    assert rows["q1"]["convergence_pct"] == 100.0 and rows["q1"]["acc1_pct"] >= 99.2
    assert rows["q10"]["convergence_pct"] >= 99.93
    assert rows["q1"]["mean_iterations"] <= 4
    for row in rows.values():
        assert row["max_iterations"] <= 100 and row["mean_solve_us"] > 0


def test_workspace_prints_extents_and_writes_plots(tmp_path):
    report = json.loads(run("kinematics", "workspace", "--plot", str(tmp_path / "ws"), "--resolution", "21",
                            "--json").stdout)
    extents = report["extents"]
    assert 250 <= extents["dexterous_x_mm_at_z675"] <= 350
    assert 450 <= extents["parallel_x_mm_at_z600"] <= 550
    assert 50 <= extents["roll_deg_at_z700"] <= 60
    assert len(report["plots"]) == 3
    for path in report["plots"]:
        with open(path, "rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_validate_dynamics_json_is_within_the_thesis_error_off_the_singular_surface(tmp_path):
    report = json.loads(run("kinematics", "validate-dynamics", "--json", "--plot", str(tmp_path)).stdout)
    rows = report["trajectories"]
    # Fig. 10.3 and Figs. E.1-E.6
    assert [Path(f).name for f in report["figures"]] == ["fig10_3_errors.png"] + [
        f"figE_{k}_{name}.png" for k, name in enumerate(["Tx", "Ty", "Tz", "Rx", "Ry", "Rz"], 1)]
    assert all(Path(f).stat().st_size > 10_000 for f in report["figures"])
    assert [r["name"] for r in rows] == ["Tx", "Ty", "Tz", "Rx", "Ry", "Rz"]
    for row in rows:
        assert row["max_abs_error_n"] <= row["thesis_absmax_n"]
        assert row["rel_error_pct"] <= row["thesis_rel_pct"]
        if row["name"] in ("Tx", "Ty", "Tz", "Ry"):
            assert row["forward_max_closure_um"] <= 10.0 and not row["crosses_singularity"]
        else:
            assert row["crosses_singularity"] and row["forward_max_closure_um"] is None


def test_bench_json_reports_time_and_zero_numpy_allocations():
    report = json.loads(run("kinematics", "bench", "--calls", "300", "--json").stdout)
    for name in ("ik_numba", "dk_warm", "inverse_dynamics", "task_space_terms"):
        assert report[name]["numpy_retained_per_call"] == 0.0
        assert 0 < report[name]["p50_us"] <= report[name]["p99_us"]


@pytest.mark.parametrize("args, culprit", [
    (("kinematics", "dk-eval", "--samples", "0"), "--samples"),
    (("kinematics", "dk-eval", "--min-condition-index", "2"), "--min-condition-index"),
    (("kinematics", "workspace", "--geometry", "/nonexistent.toml"), "/nonexistent.toml"),
    (("kinematics", "bench", "--calls", "ten"), "--calls"),
    (("kinematics", "nope"), "nope"),
])
def test_bad_input_is_one_line_and_exit_2(args, culprit):
    proc = run(*args, check=False)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and culprit in lines[0], proc.stderr


def test_bad_geometry_file_is_one_line_and_exit_2(tmp_path):
    from importlib import resources
    good = resources.files("physics").joinpath("data/geometry.toml").read_text()
    bad = tmp_path / "g.toml"
    bad.write_text(good.replace("base_radius_mm = 95.0", "base_radius_mm = -1"))
    proc = run("kinematics", "workspace", "--geometry", str(bad), check=False)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1
    assert "rings.base_radius_mm" in proc.stderr
    bad.write_text("[rings]\nbase_radius_mm = 95\n")
    proc = run("kinematics", "workspace", "--geometry", str(bad), check=False)
    assert proc.returncode == 2 and "missing key legs" in proc.stderr
