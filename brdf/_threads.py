"""How many threads a kernel call gets (kept apart from :mod:`brdf._jit` so that importing
it does not import numba).

The package's kernels run in Python threads (:mod:`brdf._jit`), never in numba's parallel
loops, so numba's threading layer runs nothing of theirs; its count of threads is still the
user's setting (``numba.set_num_threads``, ``NUMBA_NUM_THREADS``), which :func:`thread_count`
reads without starting the layer when nothing has set it (starting it took 0.003 s of every
command, and set the count of a layer that runs nothing)."""

import contextlib
import threading

#: Kernel calls on fewer directions than this run on one thread (see :func:`serial_below`).
SERIAL_SAMPLES = 1 << 15
#: The fewest rows an array kernel gives each thread (``brdf._jit.threaded_kernel``), unless
#: its rows cost far more than a model's evaluation: with fewer, waking the threads costs
#: more than they save (see :func:`serial_below`).
ROWS_PER_THREAD = SERIAL_SAMPLES // 2

_set = threading.local()


def thread_count():
    """The number of threads this thread's kernel calls use: the count :func:`using_threads`
    set, or else numba's (``numba.get_num_threads``: all ``NUMBA_NUM_THREADS`` until
    ``numba.set_num_threads`` is called, which starts numba's threading layer)."""
    count = getattr(_set, "count", None)
    if count is not None:
        return count
    import numba
    from numba.np.ufunc import parallel
    if parallel._is_initialized:
        return numba.get_num_threads()
    return numba.config.NUMBA_NUM_THREADS


@contextlib.contextmanager
def using_threads(count):
    """This thread's kernel calls use ``count`` threads while the block runs (at least one,
    at most ``NUMBA_NUM_THREADS``, the size of the pool they run in)."""
    import numba
    before = getattr(_set, "count", None)
    _set.count = max(1, min(int(count), numba.config.NUMBA_NUM_THREADS))
    try:
        yield
    finally:
        _set.count = before


@contextlib.contextmanager
def serial_below(n):
    """Run this thread's kernel calls on one thread while they handle ``n`` < SERIAL_SAMPLES
    directions: waking other threads then costs more than the work, and far more on a
    busy machine (``lambert + ggx`` on 1,305 pairs: 23 ms on 2 threads, 0.17 ms on one, 2
    shared cores under load). A fit or a chain evaluates its table thousands of times. The
    count is per calling thread, so other threads are unaffected."""
    if n >= SERIAL_SAMPLES:
        yield
        return
    with using_threads(1):
        yield
