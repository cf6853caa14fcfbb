"""The codecs' per-cycle path allocates no NumPy memory and does not grow traced memory."""

import gc
import tracemalloc

import numpy as np

from protocol.codec import CODECS, FrameDecoder

LEGS = range(1, 7)


def test_one_cycle_of_frames_allocates_nothing():
    sensors = [CODECS[f"LEG_STATE_{n}"] for n in LEGS]
    commands = [CODECS[f"VALVE_CMD_{n}"] for n in LEGS]
    decoder = FrameDecoder([c.name for c in sensors])
    expected = decoder.expected_mask(decoder.names)
    tx = {c.name: c.new_buffer() for c in sensors + commands}
    values = {c.name: c.new_values() for c in sensors + commands}
    immutable = bytes(sensors[0].dlc)                      # a frame from a log: the scratch path

    def cycle(k: int):
        decoder.begin_cycle()
        for c in sensors:
            values[c.name][4] = k * 1e-6
            c.encode_into(values[c.name], tx[c.name])
            decoder.receive(c.frame_id, tx[c.name])
        decoder.receive(sensors[0].frame_id, immutable)
        for c in commands:
            values[c.name][6] = (k % 100) / 100
            c.encode_into(values[c.name], tx[c.name])
        return decoder.end_cycle(expected)

    for k in range(200):                                   # warm-up: caches, interned ints
        cycle(k)
    gc.collect()
    tracemalloc.start()
    try:
        numpy_filter = tracemalloc.DomainFilter(True, np.lib.tracemalloc_domain)
        baseline = tracemalloc.take_snapshot().filter_traces([numpy_filter])
        before, _ = tracemalloc.get_traced_memory()
        for k in range(200, 5200):
            cycle(k)
        after, _ = tracemalloc.get_traced_memory()
        grown = tracemalloc.take_snapshot().filter_traces([numpy_filter]).compare_to(baseline, "lineno")
    finally:
        tracemalloc.stop()
    numpy_allocations = [s for s in grown if s.count_diff > 0 or s.size_diff > 0]
    assert numpy_allocations == [], numpy_allocations[:5]
    assert after - before < 4096, f"traced memory grew by {after - before} bytes over 5000 cycles"
    assert decoder.counts[:, 0].sum() == 6 * 5200      # every sensor frame accepted
