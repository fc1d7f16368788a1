"""The compiled screen of direction arrays for :func:`brdf.geometry.direction_array`.

Kept out of :mod:`brdf.geometry` so that importing the package does not import numba. In
numpy the screen took 20 ms of a 140 ms ``eval`` of 1.46 million pairs (``einsum`` over rows
of three); this loop takes 3 ms, about what the finite-value screen it replaces cost.
"""

from ._jit import kernel

__all__ = ["first_outside"]


@kernel
def first_outside(low, high, a):
    """Index of the first row of ``a`` (n, 3) whose squared length is outside [low, high]
    (NaN and inf included), or -1."""
    for k in range(a.shape[0]):
        s = a[k, 0] * a[k, 0] + a[k, 1] * a[k, 1] + a[k, 2] * a[k, 2]
        if not (s >= low and s <= high):
            return k
    return -1
