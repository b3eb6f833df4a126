"""Timing helpers shared by the benchmark scripts: pin to one core, median of repeated calls."""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Callable
from typing import Any


def pin_one_core() -> None:
    """Run this process on CPU 0 only (where the OS allows it), so figures read as one core's cost."""
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {0})
    try:
        import cv2
    except ImportError:
        return
    cv2.setNumThreads(1)  # OpenCV's own worker pool would contend for that one core


def median_ms(fn: Callable[[], Any], reps: int) -> float:
    """Median wall time of ``fn()`` in milliseconds over ``reps`` calls, after one warm-up call."""
    fn()  # warm caches
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)
