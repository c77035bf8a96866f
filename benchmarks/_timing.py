"""Timing shared by the benchmark scripts (run them as ``python benchmarks/NAME.py``)."""

from __future__ import annotations

import time

import numpy as np


def median_ms(fn, min_time_s: float = 1.0, min_calls: int = 10) -> float:
    """Median wall time of one call, in ms (the median resists other load on the machine)."""
    fn()  # warm-up
    times, t_start = [], time.perf_counter()
    while len(times) < min_calls or time.perf_counter() - t_start < min_time_s:
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)) * 1e3
