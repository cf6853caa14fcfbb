"""What a stretch of steady cycles allocates: the tests' one tracemalloc harness."""

from __future__ import annotations

import gc
import tracemalloc
from collections.abc import Callable

import numpy as np

TRACE_FRAMES = 6                  # deep enough to see that an allocation is the plant's own work


def allocations(run: Callable[[], None], sources: tuple[str, ...] | None = None,
                outside: str = "*/plant_emulator/*") -> tuple[list, int]:
    """Run `run()` with the garbage collector off under tracemalloc: (the NumPy-domain traces
    that grew, by line; the traced bytes gained). A cycle that allocates nothing gives ([], ~0).
    `sources` (path patterns): count the bytes gained only in those files, and not what code
    called from `outside` made there (a plant stepped in the same process keeps its own
    garbage, through the protocol's helpers too)."""
    gc.collect()
    gc.disable()
    tracemalloc.start(TRACE_FRAMES)
    try:
        numpy_only = [tracemalloc.DomainFilter(True, np.lib.tracemalloc_domain)]
        ours = [tracemalloc.Filter(True, pattern) for pattern in sources or ()]
        ours += [tracemalloc.Filter(False, outside, all_frames=True)] if ours else []
        full = tracemalloc.take_snapshot()
        baseline = full.filter_traces(numpy_only)
        before, _ = tracemalloc.get_traced_memory()
        run()
        after, _ = tracemalloc.get_traced_memory()
        end = tracemalloc.take_snapshot()
        grown = end.filter_traces(numpy_only).compare_to(baseline, "lineno")
        if ours:
            gained = sum(s.size_diff for s in end.filter_traces(ours).compare_to(full.filter_traces(ours), "lineno"))
        else:
            gained = after - before
    finally:
        tracemalloc.stop()
        gc.enable()
    return [s for s in grown if s.count_diff > 0 or s.size_diff > 0], gained
