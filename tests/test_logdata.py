"""The log reader's cycle assignment: the emulator's cyclic frames belong to the cycle whose
SYNC counter their EMU_TRUTH carries (low 4 bits), also when they arrive cycles late."""

from __future__ import annotations

from hil.logdata import _assign_cycles
from protocol.codec import CODECS

SYNC, TRUTH, LEG = (CODECS[name].frame_id for name in ("SYNC", "EMU_TRUTH", "LEG_STATE_1"))


def test_an_emulator_five_cycles_behind_at_the_end_of_the_log_keeps_its_cycles():
    """In a slow VM the emulator's answers trailed the last SYNCs by five cycles. A truth with
    phase 15 was matched to a cycle past the log's end (no SYNC: the lookup's default -1 is
    15 modulo 16), and its LEG_STATE read as lost."""
    counters = list(range(90, 104))                  # SYNC counters; cycle k has counters[k]
    lag = 5
    frames = []
    for k, counter in enumerate(counters):
        frames.append((SYNC, bytes([counter]), float(k)))
        answered = k - lag
        if answered >= 0:                            # the emulator answers an older SYNC
            phase = counters[answered] % 16
            frames.append((LEG, bytes(6), k + 0.5))
            frames.append((TRUTH, bytes([0, phase << 4, 0, 0, 0, 0, 0, 0]), k + 0.6))
    for answered in range(len(counters) - lag, len(counters)):      # the rest after the last SYNC
        t = len(counters) + answered
        frames.append((LEG, bytes(6), t + 0.5))
        frames.append((TRUTH, bytes([0, (counters[answered] % 16) << 4, 0, 0, 0, 0, 0, 0]), t + 0.6))
    cycles = _assign_cycles(frames)
    truths = [int(c) for (frame_id, *_), c in zip(frames, cycles) if frame_id == TRUTH]
    legs = [int(c) for (frame_id, *_), c in zip(frames, cycles) if frame_id == LEG]
    assert truths == list(range(len(counters))) and legs == truths
    assert counters.index(95) in truths               # the phase-15 answer kept its cycle
