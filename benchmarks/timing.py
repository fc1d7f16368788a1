"""Shared by the benchmark scripts: best-of-N timing after a warm-up, and random directions."""

import statistics
import time

import numpy as np


def best_time(fn, repeats):
    """``(best, median)`` seconds of ``repeats`` calls of ``fn`` after one warm-up call (numba
    compilation, page cache, lazily built grids and interpolants)."""
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times), statistics.median(times)


def random_pairs(n, seed=0):
    """``n`` pairs of directions uniform on the upper hemisphere."""
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(2, n, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[..., 2] = np.abs(v[..., 2])
    return np.ascontiguousarray(v[0]), np.ascontiguousarray(v[1])
