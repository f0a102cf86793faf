"""Timing for the benchmarks: medians over repeats after one warm-up call."""

import time

import numpy as np


def median_ms(fn, repeats: int) -> float:
    """Median wall time of fn() in milliseconds over `repeats` calls, after a warm-up."""
    fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return 1e3 * float(np.median(times))
