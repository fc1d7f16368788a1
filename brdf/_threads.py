"""How many threads a kernel call gets (kept apart from :mod:`brdf._jit` so that importing
it does not import numba)."""

import contextlib


#: Kernel calls on fewer directions than this run on one thread (see :func:`serial_below`).
SERIAL_SAMPLES = 1 << 15


@contextlib.contextmanager
def serial_below(n):
    """Run this thread's kernel calls on one thread while they handle ``n`` < SERIAL_SAMPLES
    directions: waking numba's other threads then costs more than the work, and far more on a
    busy machine (``lambert + ggx`` on 1,305 pairs: 23 ms on 2 threads, 0.17 ms on one, 2
    shared cores under load). A fit or a chain evaluates its table thousands of times. numba's
    thread count is per calling thread, so other threads are unaffected."""
    if n >= SERIAL_SAMPLES:
        yield
        return
    import numba
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(before)
