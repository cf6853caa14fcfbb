"""What a stretch of steady cycles allocates: the tests' one tracemalloc harness."""

from __future__ import annotations

import gc
import tracemalloc
from collections.abc import Callable

import numpy as np


def allocations(run: Callable[[], None]) -> tuple[list, int]:
    """Run `run()` with the garbage collector off under tracemalloc: (the NumPy-domain traces
    that grew, by line; the traced bytes gained). A cycle that allocates nothing gives ([], ~0)."""
    gc.collect()
    gc.disable()
    tracemalloc.start()
    try:
        numpy_only = [tracemalloc.DomainFilter(True, np.lib.tracemalloc_domain)]
        baseline = tracemalloc.take_snapshot().filter_traces(numpy_only)
        before, _ = tracemalloc.get_traced_memory()
        run()
        after, _ = tracemalloc.get_traced_memory()
        grown = tracemalloc.take_snapshot().filter_traces(numpy_only).compare_to(baseline, "lineno")
    finally:
        tracemalloc.stop()
        gc.enable()
    return [s for s in grown if s.count_diff > 0 or s.size_diff > 0], after - before
