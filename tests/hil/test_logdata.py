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


def test_frames_of_a_killed_emulator_keep_their_sync_not_the_next_processes_first_truth():
    """The fault matrix's case 3a: the emulator killed after its LEG_STATE, before its
    EMU_TRUTH. Its frames went to the restarted emulator's first truth, 2 s later, and the
    case read "SENSOR_TIMEOUT -1014 cycles after the last LEG_STATE"."""
    frames = []
    for k in range(10):                               # answered normally
        t = k * 0.002
        frames += [(SYNC, bytes([k + 1]), t), (LEG, bytes(6), t + 2e-4),
                   (TRUTH, bytes([0, ((k + 1) % 16) << 4, 0, 0, 0, 0, 0, 0]), t + 3e-4)]
    frames += [(SYNC, bytes([11]), 0.020), (LEG, bytes(6), 0.0202)]      # killed: no truth
    for k in range(11, 1011):                         # 2 s of SYNC without the emulator
        frames.append((SYNC, bytes([k % 240 + 1]), k * 0.002))
    restart = 1011 * 0.002
    frames += [(SYNC, bytes([1011 % 240 + 1]), restart), (LEG, bytes(6), restart + 2e-4),
               (TRUTH, bytes([0, ((1011 % 240 + 1) % 16) << 4, 0, 0, 0, 0, 0, 0]), restart + 3e-4)]
    cycles = _assign_cycles(frames)
    legs = [int(c) for (frame_id, *_), c in zip(frames, cycles) if frame_id == LEG]
    assert legs == list(range(11)) + [1011]


def test_an_emulator_stalled_for_48_cycles_answers_each_sync_in_its_own_cycle():
    """Realtime: the emulator's process was not run for ~100 ms, then answered the 48 SYNCs
    it had missed in one burst. Matched by phase near the SYNC they came after, those answers
    went to recent cycles (48 = 3 x 16), so they looked neither late nor ever sent, and the
    SENSOR_TIMEOUT the stall caused read as a fault without a stall before it."""
    stall = range(31, 79)
    frames = []

    def answer(k, t):
        frames.extend([(LEG, bytes(6), t), (TRUTH, bytes([0, ((k + 1) % 16) << 4, 0, 0, 0, 0, 0, 0]), t + 1e-4)])

    for k in range(120):
        t = k * 0.002
        frames.append((SYNC, bytes([k % 240 + 1]), t))
        if k == stall.stop:                           # back: the backlog, then this SYNC's answer
            for j, late in enumerate(stall):
                answer(late, t + 1e-3 + j * 4e-4)
        if k not in stall:
            answer(k, t + (0.025 if k == stall.stop else 2e-4))
    cycles = _assign_cycles(frames)
    legs = [int(c) for (frame_id, *_), c in zip(frames, cycles) if frame_id == LEG]
    assert sorted(legs) == list(range(120)) and legs[31:79] == list(stall)
