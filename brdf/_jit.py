"""The one place that decides how numba compiles the library's kernels.

Kernels are cached to disk (``cache=True``) so only the first run in an environment pays for
compilation. Fast-math flags exclude ``nnan`` and ``ninf``: kernels test for NaN and rely on
``inf`` (the pdf of a delta lobe), which the full fast-math set would let LLVM discard.
"""

import numba

FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


def kernel(fn):
    """Compile a scalar or serial kernel (cached, fast-math without nnan/ninf)."""
    return numba.njit(fn, cache=True, fastmath=FASTMATH)


def parallel_kernel(fn):
    """Compile an array kernel whose ``prange`` loops run on all cores."""
    return numba.njit(fn, cache=True, fastmath=FASTMATH, parallel=True)
