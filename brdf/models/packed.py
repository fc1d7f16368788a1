"""Helpers for reading a lobe's packed parameter block inside kernels."""

from .._jit import OPTIMISED, kernel


@kernel(linked=OPTIMISED)
def channel_mean(q, start, nch):
    """Mean of the per-channel parameter stored at ``q[start:start + nch]``."""
    s = 0.0
    for c in range(nch):
        s += q[start + c]
    return s / nch
