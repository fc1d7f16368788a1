"""Checks of the arguments of library functions: counts, tolerances, seeds, names and mappings.

Compiled kernels trust the sizes they are given (numba does not check array bounds), so every
size or count that reaches one passes through :func:`integer` in its Python driver first. Each
refusal is an :class:`~brdf.errors.InputError` whose one line names the function, the argument,
what it takes and what it got.
"""

import math
import numbers
import reprlib
from collections.abc import Iterable, Mapping

import numpy as np

from .errors import InputError

__all__ = ["integer", "is_integer", "real", "seed", "rng", "names", "mapping", "shown"]

_REPR = reprlib.Repr()
_REPR.maxstring = _REPR.maxother = 60


def shown(value):
    """A short repr of ``value`` for a message (long strings and arrays are cut)."""
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} and dtype {value.dtype}"
    return _REPR.repr(value)


def is_integer(value):
    """True for an integer (Python or numpy), not a bool."""
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))


def integer(value, name, low, high=None):
    """``value`` as an ``int`` if it is an integer (not a bool, not a float) in
    ``[low, high]``; otherwise InputError naming ``name``."""
    if not is_integer(value) or value < low or (high is not None and value > high):
        span = f">= {low}" if high is None else f"from {low} to {high:,}"
        raise InputError(f"{name} must be an integer {span}, got {shown(value)}")
    return int(value)


def real(value, name, low=-math.inf, high=math.inf, *, low_open=False):
    """``value`` as a ``float`` if it is a finite real number (not a bool) in ``[low, high]``
    (``(low, high]`` with ``low_open``); otherwise InputError naming ``name``."""
    ok = isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))
    if ok:
        v = float(value)
        ok = math.isfinite(v) and (v > low if low_open else v >= low) and v <= high
    if not ok:
        parts = ([f"> {low:g}" if low_open else f">= {low:g}"] if low > -math.inf else []) + \
                ([f"<= {high:g}"] if high < math.inf else [])
        raise InputError(f"{name} must be a finite number{' ' if parts else ''}"
                         f"{' and '.join(parts)}, got {shown(value)}")
    return v


def seed(value, name="seed"):
    """``value`` unchanged if it is an integer >= 0 (not a bool) or a
    :class:`numpy.random.Generator`; otherwise InputError naming ``name``."""
    if isinstance(value, np.random.Generator) or (is_integer(value) and value >= 0):
        return value
    raise InputError(f"{name} must be an integer >= 0 or a numpy.random.Generator, got "
                     f"{shown(value)}")


def rng(value, name="seed"):
    """The :class:`numpy.random.Generator` a checked :func:`seed` stands for."""
    return np.random.default_rng(seed(value, name))


def names(value, name):
    """A tuple of parameter names from one name (a ``str``) or an iterable of them."""
    if isinstance(value, str):
        return (value,)
    if isinstance(value, Iterable) and not isinstance(value, (bytes, Mapping)):
        try:
            items = tuple(value)
        except TypeError:  # a 0-d array
            items = None
        if items is not None and all(isinstance(v, str) for v in items):
            return items
    raise InputError(f"{name} must be a parameter name or a list of names, got {shown(value)}")


def mapping(value, name, what):
    """``value`` as a ``dict`` keyed by parameter names (``None``: empty); ``what`` says what
    its values are, for the message."""
    if value is None:
        return {}
    if isinstance(value, Mapping) and all(isinstance(k, str) for k in value):
        return dict(value)
    raise InputError(f"{name} must be a dict {{parameter name: {what}}}, got {shown(value)}")
