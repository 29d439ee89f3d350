"""Timing of repeated runs, shared by the benchmarks (their figures are medians: the
machine's speed varies by ±10 % from run to run, more from hour to hour)."""

from __future__ import annotations

import time

__all__ = ["timed_runs"]


def timed_runs(fn, repeats, clock=time.perf_counter):
    """([fn()'s result per run], [wall time (s) per run]) of ``repeats`` ≥ 1 calls of
    ``fn``, each timed alone by ``clock`` (s)."""
    results, walls = [], []
    for _ in range(max(int(repeats), 1)):
        t0 = clock()
        results.append(fn())
        walls.append(float(clock() - t0))
    return results, walls
