"""Fitting models that hold numpy-written lobes (:class:`~brdf.models.custom.CustomModel`).

:class:`Problem` scores parameter vectors in compiled passes over the lobes' kernels, which a
custom lobe does not have. :class:`MixedProblem` keeps everything else of it (free parameters,
bounds, log scaling, the x -> model map, the loss terms) and evaluates the model instead: the
model rebuilt from x, its ``eval`` on the samples (built-in lobes still through their kernels),
scored in numpy (:func:`brdf.fitting.losses.channel_values`). Its gradient comes from central
differences (:meth:`Problem.difference_rows`, 2 G + 1 evaluations for G groups of coordinates),
so the gradient-based optimizers (LD_LBFGS, the default, and LD_SLSQP) work unchanged, as do the
derivative-free and global ones, and ``brdf.mcmc``. :func:`problem_for` picks the class.
"""

import numbers

import numpy as np

from .. import arguments
from .._threads import serial_below
from ..errors import InputError
from . import losses
from .problem import Problem

__all__ = ["MixedProblem", "problem_for"]


def problem_for(data, spec, **options):
    """The fitting problem of ``spec`` on ``data``: a :class:`Problem` when every lobe has
    kernels, else a :class:`MixedProblem` (same arguments as :class:`Problem`)."""
    from ..spec import parse
    model = parse(spec)
    return (Problem if model.uses_kernels else MixedProblem)(data, model, **_checked(options))


def _checked(options):
    """``shared`` as a tuple of names (one name may be a plain string), ``fix`` and ``bounds``
    as dicts keyed by names, their values numbers (``fix``: one or one per channel;
    ``bounds``: a pair); InputError otherwise."""
    options = dict(options)
    if "shared" in options:
        options["shared"] = arguments.names(options["shared"], "shared")
    if "fix" in options:
        options["fix"] = arguments.mapping(options["fix"], "fix", "value")
        for name, value in options["fix"].items():
            if not (_is_number(value) or _numbers(value)):
                raise InputError(f"fix {name}: expected a number or a list of per-channel "
                                 f"numbers, got {arguments.shown(value)}")
    if "bounds" in options:
        options["bounds"] = arguments.mapping(options["bounds"], "bounds", "(lower, upper)")
        for name, box in options["bounds"].items():
            if not (_numbers(box) and len(box) == 2):
                raise InputError(f"bounds {name}: expected (lower, upper), two numbers, got "
                                 f"{arguments.shown(box)}")
    return options


def _is_number(value):
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _numbers(value):
    """Whether ``value`` is a flat list, tuple or 1-D array of numbers."""
    return (isinstance(value, (list, tuple)) or (isinstance(value, np.ndarray)
                                                 and value.ndim == 1)) \
        and all(_is_number(v) for v in value)


class MixedProblem(Problem):
    """A :class:`Problem` whose model holds custom lobes: losses from ``model(x).eval``, the
    gradient from central differences (see the module docstring)."""

    def model_values(self, x):
        """The model's values ``(n, C)`` at the samples for parameter vector ``x``."""
        s = self.samples
        model = self.model(x)
        with serial_below(len(s.wi)):  # a fit evaluates a small table thousands of times
            f = model.eval(s.wi, s.wo)
        return np.broadcast_to(f, s.values.shape)

    @staticmethod
    def score(f, terms):
        """Per-channel loss ``(C,)`` of model values ``f`` under ``terms``."""
        return losses.channel_values(terms, f)

    def channel_losses(self, X, terms=None):
        """Per-channel contributions ``(K, C)`` to the loss of each row of ``X``."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        t = terms or self.terms
        refused = self._refused(self.packed(X)) if self._admissible else np.zeros(len(X), bool)
        return np.array([np.full(self.channels, np.inf) if no else
                         self.score(self.model_values(x), t) for x, no in zip(X, refused)])

    def loss_and_gradient(self, x, terms=None):
        """``(loss, gradient)`` at ``x``; the gradient by central differences."""
        rows, width = self.difference_rows(np.asarray(x, dtype=float))
        out = self.channel_losses(rows, terms)
        return float(out[0].sum()), self.difference_jacobian(out, width).sum(axis=0)
