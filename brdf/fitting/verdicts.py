"""Warnings on a fitted optimum: what a converged optimiser does not say.

:func:`warnings_of` returns a list of ``{"parameter", "kind", "detail"}`` objects, ``kind`` one of
:data:`KINDS`:

``at-bound``
    a free parameter within :data:`BOUND_TOL` of its fit box's width from a bound (in x, so
    relative to the box in log space for log-scaled parameters);
``collapsed``
    a lobe (``parameter`` is its flat-name prefix) contributing less than
    :data:`COLLAPSE_SHARE` of the fitted reflectance (the loss-weighted sum of f cos(theta_i)
    over the samples); delta lobes, which no sample sees, are left out;
``undetermined``
    a parameter that the data do not constrain: the loss's Hessian at the optimum (central
    differences of the analytic gradient, in x scaled by the box widths) has an eigenvector
    along which a move of :data:`PROBE_STEP` of the box raises the loss by less than
    :data:`UNDETERMINED_RISE` of its value; the parameters that dominate that eigenvector
    (|component| >= :data:`EIGEN_SHARE`) are named;
``multimodal``
    a local run that ended at a different optimum (see ``nlopt_fit.MODE_SEPARATION``: some
    determined coordinate of x off by more than that fraction of its box width) within
    ``nlopt_fit.MULTIMODAL_GAP`` of the best loss.
"""

import math

import numpy as np

from .._threads import serial_below

__all__ = ["KINDS", "warnings_of", "BOUND_TOL", "COLLAPSE_SHARE", "UNDETERMINED_RISE",
           "PROBE_STEP", "EIGEN_SHARE"]

KINDS = ("at-bound", "collapsed", "undetermined", "multimodal")
#: Distance to a bound, as a fraction of the box width in x, that counts as at the bound.
BOUND_TOL = 1e-6
#: A lobe contributing less than this share of the fitted reflectance has collapsed.
COLLAPSE_SHARE = 1e-3
#: Move along a Hessian eigenvector, as a fraction of the box widths, that probes a direction.
PROBE_STEP = 0.1
#: A direction whose probe raises the loss by less than this fraction of it is undetermined.
UNDETERMINED_RISE = 1e-3
#: Components of a weak eigenvector at least this large (it has unit length) name parameters.
EIGEN_SHARE = 0.3
#: Step of the Hessian's central differences, as a fraction of the box width in x.
HESSIAN_STEP = 1e-4


def _warning(parameter, kind, detail):
    return {"parameter": parameter, "kind": kind, "detail": detail}


def at_bound(problem, x):
    out = []
    width = problem.upper - problem.lower
    for i, p in enumerate(problem.free):
        for side, b in (("lower", problem.lower[i]), ("upper", problem.upper[i])):
            if abs(x[i] - b) <= BOUND_TOL * width[i]:
                bound = p.lower if side == "lower" else p.upper
                out.append(_warning(p.name, "at-bound",
                                    f"{float(p.from_x(x[i])):.6g} is at its {side} fit bound "
                                    f"{bound:g}"))
    return out


def collapsed(problem, x):
    """Lobes whose share of sum_k w_k cos(theta_i,k) sum_c f_c is below COLLAPSE_SHARE."""
    from ..models.base import Sum
    model = problem.model(x)
    lobes = model.lobes
    names = model.lobe_names() if isinstance(model, Sum) else [model.name]
    s = problem.samples
    w = s.weights * s.wi[:, 2]
    shares = []
    with serial_below(len(s.wi)):
        for lobe in lobes:
            f = np.asarray(lobe.eval(s.wi, s.wo), dtype=float).reshape(len(s.wi), -1)
            shares.append(float(w @ np.abs(f).sum(axis=1)))
    total = sum(shares)
    out = []
    for name, lobe, share in zip(names, lobes, shares):
        if lobe.delta:
            continue
        fraction = share / total if total > 0 else 0.0
        if fraction < COLLAPSE_SHARE:
            out.append(_warning(name, "collapsed",
                                f"the {lobe.name} lobe carries {fraction:.2%} of the fitted "
                                f"reflectance (below {COLLAPSE_SHARE:.1%})"))
    return out


def hessian(problem, x):
    """The loss's Hessian in x ``(n, n)``, symmetrised, from central differences of the
    gradient (one-sided where a bound is closer than the step)."""
    n = len(x)
    width = problem.upper - problem.lower
    h = HESSIAN_STEP * width
    H = np.empty((n, n))
    with serial_below(len(problem.samples.wi)):
        for j in range(n):
            up = x.copy()
            down = x.copy()
            up[j] = min(problem.upper[j], x[j] + h[j])
            down[j] = max(problem.lower[j], x[j] - h[j])
            g_up = problem.loss_and_gradient(up)[1]
            g_down = problem.loss_and_gradient(down)[1]
            H[:, j] = (g_up - g_down) / (up[j] - down[j])
    return 0.5 * (H + H.T)


def undetermined(problem, x, loss):
    """Parameters along the Hessian's weak directions (see the module docstring); returns
    ``(warnings, names)``."""
    width = problem.upper - problem.lower
    H = hessian(problem, x) * np.outer(width, width)  # in units of the box widths
    if not np.all(np.isfinite(H)):
        return [], set()
    values, vectors = np.linalg.eigh(H)
    rise_floor = UNDETERMINED_RISE * max(loss, 0.0)
    # eigenvalues within rounding of the largest are 0: an exactly flat direction comes out
    # as +-1e-15 of it, with a sign that the last bits of the gradients decide
    noise = len(values) * np.finfo(float).eps * np.abs(values).max()
    out, names = [], set()
    for lam, v in zip(values, vectors.T):
        rise = 0.5 * (lam if lam > noise else 0.0) * PROBE_STEP ** 2
        if rise > rise_floor:  # at a zero loss only an exactly flat direction counts
            continue
        for i in np.flatnonzero(np.abs(v) >= EIGEN_SHARE):
            name = problem.free[i].name
            if name in names:
                continue
            names.add(name)
            rel = rise / loss if loss > 0 else 0.0
            out.append(_warning(name, "undetermined",
                                f"moving it by {PROBE_STEP:.0%} of its fit box (with the "
                                f"parameters it trades off against) changes the loss by "
                                f"{rel:.2g} of its value: the data do not constrain it"))
    return out, names


def multimodal(problem, x, loss, ends, gap, separation, skip=()):
    """Run ends at a different optimum within ``gap`` of ``loss`` (coordinates named in
    ``skip``, undetermined ones, do not count towards the difference)."""
    width = problem.upper - problem.lower
    keep = np.array([p.name not in skip for p in problem.free])
    out = []
    seen = []
    for xe, le, feasible in ends:
        if not feasible or not math.isfinite(le) or le > loss * (1.0 + gap) + 1e-300:
            continue
        d = np.where(keep, np.abs(xe - x) / width, 0.0)
        if d.max() <= separation or any(np.max(np.where(keep, np.abs(xe - o) / width, 0.0))
                                        <= separation for o in seen):
            continue
        seen.append(xe)
        i = int(np.argmax(d))
        p = problem.free[i]
        out.append(_warning(p.name, "multimodal",
                            f"another local optimum with loss {le:.6g} (best {loss:.6g}, "
                            f"+{(le / loss - 1) if loss > 0 else 0.0:.2%}) has {p.name} = "
                            f"{float(p.from_x(xe[i])):.6g} against {float(p.from_x(x[i])):.6g}"))
    return out


def warnings_of(problem, x, loss, ends, gap, separation, screen=None):
    """Every warning on the optimum ``x`` of ``problem`` (loss ``loss``); ``ends`` are the
    local runs' ``(x, loss, feasible)`` on the same samples; ``screen`` a problem on a
    subsample for the lobe shares and the Hessian (default: ``problem``)."""
    x = np.asarray(x, dtype=float)
    probe = problem if screen is None else screen
    out = at_bound(problem, x) + collapsed(probe, x)
    probe_loss = loss if screen is None or screen is problem else float(
        probe.channel_losses(x).sum())
    weak, names = undetermined(probe, x, probe_loss)
    out += weak
    out += multimodal(problem, x, loss, ends, gap, separation, skip=names)
    return out
