"""Issue 7 item 10: 10^6 random frames (fixed seed) into the decoders and into the
controller's receive side and host-command parser: no exception, every frame counted."""


import pytest

from hil import fuzz
from tests.support.cli import hydrapod

FRAMES = 1_000_000
SEED = 20161


@pytest.mark.slow
@pytest.mark.parametrize("target", fuzz.TARGETS)
def test_a_million_random_frames_raise_nothing_and_are_all_counted(target):
    report = fuzz.run([target], FRAMES, SEED)[0]
    assert report.exceptions == 0, report.first_exception
    assert report.counted == FRAMES
    assert report.non_finite_outputs == 0
    # not vacuous: frames of every kind got through to each outcome
    assert report.accepted > 0.1 * FRAMES and report.rejected > 0.1 * FRAMES and report.unknown > 0.5 * FRAMES
    if target == "controller":
        assert report.host_commands > 1000


def test_the_fuzzer_counts_an_exception(monkeypatch):
    """The harness reports what escapes the receiver (so a zero above means something)."""
    original = fuzz.FrameDecoder.receive_message
    calls = [0]

    def flaky(self, msg):
        calls[0] += 1
        if calls[0] % 1000 == 0:
            raise ValueError("boom")
        return original(self, msg)

    monkeypatch.setattr(fuzz.FrameDecoder, "receive_message", flaky)
    report = fuzz.fuzz_decoder(10_000, SEED)
    assert report.exceptions == 10 and not report.ok
    assert report.first_exception == "ValueError: boom"


def test_the_same_seed_gives_the_same_frames():
    a = [(m.arbitration_id, bytes(m.data), m.is_extended_id) for m in fuzz.frames(2000, 7, ["HOST_CMD", "SYNC"])]
    b = [(m.arbitration_id, bytes(m.data), m.is_extended_id) for m in fuzz.frames(2000, 7, ["HOST_CMD", "SYNC"])]
    c = [(m.arbitration_id, bytes(m.data), m.is_extended_id) for m in fuzz.frames(2000, 8, ["HOST_CMD", "SYNC"])]
    assert a == b and a != c


def test_fuzz_command_exits_0_and_rejects_an_unknown_target():
    ok = hydrapod("hil", "fuzz", "--frames", "20000")
    assert ok.returncode == 0, ok.stderr
    assert "0 exceptions, 20000 counted" in ok.stdout
    bad = hydrapod("hil", "fuzz", "--targets", "decoder,parser")
    assert bad.returncode == 2
    assert bad.stderr.strip().count("\n") == 0 and "parser" in bad.stderr and "Traceback" not in bad.stderr
