"""Issue 7, item 11: every CLI error path is one line naming the culprit and exit code 2.

The cases are generated from the parser itself: every numeric option gets a non-number and
an out-of-range value, every choice a bad choice, every bus a bad bus string, every input
file a missing one, every output a place it cannot go. An option the parser gains without
a way to break it here fails `test_every_option_has_an_error_path`, so the list stays whole.
Commands run in this process (`hil.cli.main`); the files and processes a command would
start are never reached, because user input is checked first.
"""

from __future__ import annotations

import argparse
import signal

import can
import pytest

from hil.cli import build_parser, main
from tests.support.cli import command_parsers

# free-text options and positionals: a bad value for each, and the text the line must name
BAD_TEXT = {
    "--bus": ("udp_multicast:10.0.0.1", "10.0.0.1"),
    "--config": ("/nonexistent/hydrapod.toml", "/nonexistent/hydrapod.toml"),
    "--geometry": ("/nonexistent/geometry.toml", "/nonexistent/geometry.toml"),
    "--summary": ("/nonexistent/dir/summary.json", "--summary"),
    "--controllers": ("pi,fuzzy", "fuzzy"),
    "--loads": ("3,heavy", "heavy"),
    "--positions": ("50,high", "high"),
    "--inject": ("LEAK:1:3", "LEAK:1:3"),
    "--targets": ("decoder,nope", "nope"),
    "--rigs": ("testbench,crane", "crane"),
    "--fit": ("nonsense", "nonsense"),
    "--scenario": ("no-such-scenario", "no-such-scenario"),
    "scenario": ("no-such-scenario", "no-such-scenario"),
    "log": ("/nonexistent/run.blf", "/nonexistent/run.blf"),
    "--plants": ("/nonexistent/metrics.json", "/nonexistent/metrics.json"),
    "--nominal": ("120;6", "120;6"),
    "--ki-scales": ("0.2,x", "0.2,x"),
    "--pose": ("0,0,631", "0,0,631"),
    "--controller-config": ("/nonexistent/schedule.toml", "/nonexistent/schedule.toml"),
    "--emulator-config": ("/nonexistent/rig.toml", "/nonexistent/rig.toml"),
    "--replay": ("/nonexistent/run.blf", "/nonexistent/run.blf"),
    "--snapshot": ("/nonexistent/dir/screen.svg", "--snapshot"),
    "--export-dir": ("/nonexistent/dir", "/nonexistent/dir"),
    "spec": ("/nonexistent/campaign.toml", "/nonexistent/campaign.toml"),
    "--scheduler": ("tcp//nohost", "tcp//nohost"),
    "--time-scale": ("fast", "fast"),
    "--key": ("bogus_key", "bogus_key"),
    "--values": ("0,abc", "0,abc"),
    "--movements": ("circle,square", "circle,square"),
    "--seeds": ("1,x", "1,x"),
}
OUTPUT_DIRS = ("--out", "--plot")          # given a path below a regular file: cannot be created
# what a command needs before the option under test is reached
REQUIRED = {("hil", "run"): ["sha-step"], ("hil", "analyze"): ["{tmp}/run.blf", "--scenario", "sha-step"],
            ("campaign", "run"): ["{tmp}/campaign.toml"]}


def _walk(parser: argparse.ArgumentParser):
    """(words, option) of every command's own options."""
    for path, command in command_parsers(parser):
        for action in command._actions:
            if not isinstance(action, argparse._SubParsersAction) and action.dest != "help":
                yield path, action


def _cases(tmp_dir: str):
    """(argv, culprit) for every way this file knows to break each option."""
    for path, action in _walk(build_parser()):
        name = action.option_strings[-1] if action.option_strings else action.dest
        if isinstance(action, argparse._StoreTrueAction) or (not path and name == "command"):
            continue
        values = []
        kind = action.type
        if kind is not None and hasattr(kind, "low"):
            values.append(("not-a-number", name))
            if kind.low is not None:
                low = kind.low if kind.low_open else kind.low - (1 if kind.kind is int else 0.5 * max(abs(kind.low), 1))
                values.append((str(kind.kind(low)), name))
            if kind.high is not None:
                values.append((str(kind.kind(kind.high * 2 + 1)), name))
        elif action.choices is not None:
            values.append(("no-such-choice", name))
        elif name in BAD_TEXT:
            values.append(BAD_TEXT[name])
        elif name in OUTPUT_DIRS:
            values.append((f"{tmp_dir}/a-file/sub", "a-file"))
        else:
            values.append((None, None))          # unknown: test_every_option_has_an_error_path fails
        for value, culprit in values:
            if value is None:
                yield path, name, None, None
                continue
            required = REQUIRED.get(path, [])
            if action.option_strings:
                if name == "--scenario":         # hil analyze LOG --scenario BAD
                    required = required[:1]
                argv = list(path) + required + [name, value]
            elif name == "log":
                argv = list(path) + [value, "--scenario", "sha-step"]
            else:
                argv = list(path) + [value]
            yield path, name, argv, culprit


@pytest.fixture(scope="module")
def tmp_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli-errors")
    (d / "a-file").write_text("a regular file, not a directory\n")
    (d / "campaign.toml").write_text('[campaign]\nscenario = "sha-step"\n')      # a valid spec
    with can.Logger(str(d / "run.blf")) as log:           # a small, readable log for `hil analyze`
        for k in range(1, 5):
            log(can.Message(arbitration_id=0x080, data=[k], is_extended_id=False, timestamp=float(k)))
    return str(d)


CASES = list(_cases("{tmp}"))


def test_every_option_has_an_error_path():
    unknown = [f"{' '.join(p)} {n}" for p, n, argv, _ in CASES if argv is None]
    assert not unknown, f"options without an error-path case here: {unknown}"
    assert len(CASES) > 60


@pytest.fixture
def keep_signal_handlers():
    """A daemon's command installs SIGTERM/SIGINT handlers before it opens the bus."""
    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGINT)}
    yield
    for sig, handler in saved.items():
        signal.signal(sig, handler)


@pytest.mark.parametrize("case", [c for c in CASES if c[2] is not None],
                         ids=lambda c: " ".join(c[2]).replace("{tmp}", "T"))
def test_each_error_is_one_line_and_exit_2(case, tmp_dir, capsys, keep_signal_handlers):
    _, _, argv, culprit = case
    argv = [a.replace("{tmp}", tmp_dir) for a in argv]
    try:
        code = main(argv)
    except SystemExit as stop:                  # argparse's errors
        code = stop.code
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert code == 2, (argv, captured.err[-2000:])
    assert len(lines) == 1 and culprit in lines[0] and "Traceback" not in captured.err, captured.err
    assert captured.out == ""


# what a config or geometry file can hold wrong, and what the line must name (the
# controller's own file: tests/firmware_py/test_controller_cli.py)
FILE_ERRORS = [
    (["emulator", "calibrate", "--config"], "[nope]\nx = 1\n", "unknown section [nope]"),
    (["emulator", "bench", "--config"], "[nodes]\nbogus = 1\n", "unknown key [nodes].bogus"),
    (["emulator", "calibrate", "--config"], '[nodes]\ncommand_timeout_syncs = "a"\n',
     "[nodes].command_timeout_syncs = 'a' must be an integer"),
    (["emulator", "calibrate", "--config"], "[chambers]\nseal_leakage_l_min_per_bar = -1\n",
     "[chambers].seal_leakage_l_min_per_bar = -1 is out of range"),
    (["emulator", "calibrate", "--config"], "[nodes\n", "not valid TOML"),
    (["kinematics", "dk-eval", "--geometry"], "{geometry}\n[nope]\nx = 1\n", "unknown section nope"),
    (["kinematics", "bench", "--geometry"], "rings = 5\n", "rings = 5 must be a section"),
    (["kinematics", "validate-dynamics", "--geometry"], "[nope\n", "not valid TOML"),
]


@pytest.mark.parametrize("argv, text, culprit", FILE_ERRORS,
                         ids=lambda v: v if isinstance(v, str) else " ".join(v))
def test_bad_files_are_one_line_and_exit_2(argv, text, culprit, tmp_path, capsys):
    from importlib import resources
    good = resources.files("physics").joinpath("data/geometry.toml").read_text()
    path = tmp_path / "bad.toml"
    path.write_text(text.replace("{geometry}", good))
    try:
        code = main(argv + [str(path)])
    except SystemExit as stop:
        code = stop.code
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and culprit in err, err


def test_a_misspelt_geometry_key_is_refused(tmp_path, capsys):
    from importlib import resources
    good = resources.files("physics").joinpath("data/geometry.toml").read_text()
    path = tmp_path / "g.toml"
    path.write_text(good.replace("stroke_mm = 290.0", "stroke_mm = 290.0\nstrok_mm = 300.0"))
    assert main(["kinematics", "workspace", "--geometry", str(path)]) == 2
    assert "unknown key legs.strok_mm" in capsys.readouterr().err
