"""Starting points of a fit: a data-driven start computed from the table, and a space-filling
design over the fit box for the multi-start.

:func:`data_driven` uses what each family declares in its ``START``
(:class:`brdf.models.base.Start`): f is linear in a lobe's scale parameters (albedo, ks, rho_s),
so for given values of the nonlinear shape parameters (widths, exponents) the best scales follow
from bounded linear least squares in the fit's own weighting: variable projection (Golub &
Pereyra 1973, "The Differentiation of Pseudo-Inverses and Nonlinear Least Squares Problems
Whose Variables Separate", SIAM J. Numer. Anal. 10). The shape parameters are searched on a
grid over their fit box (log spaced for a log prior, which spans every lobe width from a
near-mirror to a near-diffuse one), the scales projected out for each grid point on a
subsample of the table, and the grid point whose model scores the lowest loss is the start.
The ``log`` metric is linearised about the data (its residual's derivative s / (offset + s y)
weights f - y), a Gauss-Newton view that is exact to first order near a good fit.

:func:`design` gives scrambled Sobol points (Owen 1998 scrambling, seeded) in the box of x, so
log-scaled parameters are spread in log space.
"""

import math

import numpy as np

from .._threads import serial_below
from . import losses

__all__ = ["data_driven", "design", "subsample", "START_SAMPLES", "GRID_PER_DECADE",
           "GRID_POINTS", "LINEAR_GRID", "MAX_CANDIDATES"]

#: Samples the start's least squares and the screening of design points use (a fixed
#: subsample of larger tables): enough to pin a lobe's width, cheap on a MERL-size table.
START_SAMPLES = 8192
#: Grid points per decade of a log-scaled shape parameter's box, and their least and most.
GRID_PER_DECADE, GRID_POINTS = 4, (6, 20)
#: Grid points of a linearly scaled shape parameter (Lafortune coefficients have none).
LINEAR_GRID = 7
#: Above this many grid points in all (several shape parameters), a Sobol subset of the grid's
#: box stands for the product.
MAX_CANDIDATES = 256
#: Seed of the fixed subsample: the same samples whatever the fit's seed.
SUBSAMPLE_SEED = 20_250_721


def subsample(samples, n=START_SAMPLES):
    """``samples`` itself when it holds at most ``n`` samples, else a fixed random subset of
    ``n`` of them (in their order) with the weights renormalised to sum 1."""
    m = len(samples.wi)
    if m <= n:
        return samples
    keep = np.sort(np.random.default_rng(SUBSAMPLE_SEED).choice(m, n, replace=False))
    w = samples.weights[keep]
    return losses.Samples(np.ascontiguousarray(samples.wi[keep]),
                          np.ascontiguousarray(samples.wo[keep]),
                          np.ascontiguousarray(samples.values[keep]),
                          None if samples.sigma is None else samples.sigma[keep],
                          w / w.sum(), samples.total, samples.cutoff, samples.weighting)


def design(problem, n, seed):
    """``n`` scrambled Sobol points ``(n, len(x))`` in the box of x (log-scaled parameters in
    log space), from ``scipy.stats.qmc.Sobol`` seeded with ``seed``."""
    from scipy.stats import qmc
    d = len(problem.free)
    if n <= 0:
        return np.zeros((0, d))
    sobol = qmc.Sobol(d, scramble=True, seed=np.random.default_rng(seed))
    u = sobol.random_base2(max(0, math.ceil(math.log2(n))))[:n]
    return problem.lower + (problem.upper - problem.lower) * u


def _grid(lo, hi, log):
    if log:
        k = int(np.clip(round(GRID_PER_DECADE * math.log10(hi / lo)) + 1, *GRID_POINTS))
        return np.geomspace(lo, hi, k)
    return np.linspace(lo, hi, LINEAR_GRID)


class _Lobe:
    """One lobe of the problem's model, as the start sees it: its scale parameters (free or
    not, per channel) and its free shape parameters with their grids."""

    def __init__(self, lobe, prefix, free, values, nch):
        hints = type(lobe).START
        self.lobe, self.nch, self.power = lobe, nch, hints.power
        present = [n for n in hints.scale if f"{prefix}.{n}" in values]
        self.scale = present if len(present) == len(hints.scale) else []
        self.scale_names = [f"{prefix}.{n}" for n in self.scale]
        # a channel's scale is projected out when every scale parameter is free there
        self.free_channels = np.array([
            bool(self.scale) and all(any(p.declared == d and p.channel in (None, c)
                                         for p in free) for d in self.scale_names)
            for c in range(nch)])
        self.shape = []
        for n in hints.shape:
            d = f"{prefix}.{n}"
            ps = [p for p in free if p.declared == d]
            if ps:
                self.shape.append((n, d, _grid(ps[0].lower, ps[0].upper, ps[0].log)))
        # declared orientations of a power law: one more grid dimension, the pattern's index
        # (named None), where every channel's coefficients are free to take it
        self.directions = hints.directions if self.power is not None else ()
        if self.directions and self.free_channels.all():
            self.shape.append(("direction", None,
                               np.arange(len(self.directions), dtype=float)))
        self.prefix = prefix

    def unit(self, values):
        """Scale parameter values that give the lobe unit scale (per channel): 1 for a linear
        scale; for a power law, the working coefficients divided by their largest magnitude."""
        if self.power is None:
            return {n: np.ones(self.nch) for n in self.scale}
        c = np.array([np.broadcast_to(values[d], (self.nch,)) for d in self.scale_names])
        top = np.abs(c).max(axis=0)
        fallback = np.array([-1.0, -1.0, 1.0])[:len(c), None] if len(c) == 3 else np.ones_like(c)
        c = np.where(top > 0.0, c / np.where(top > 0.0, top, 1.0), fallback)
        return {n: c[i] for i, n in enumerate(self.scale)}


def _linearised(terms):
    """Row factors e (n, C) and targets z (n, C): the metric's residual is about
    e (f - y) and z = e y (exact for the linear metrics; the ``log`` metric linearised)."""
    if not terms.offset:
        return terms.scale, terms.target
    sy = np.exp(terms.target) - terms.offset
    level = np.exp(terms.target)
    return terms.scale / level, sy / level


#: Up to this many scales in a channel, :func:`_solve` enumerates the faces of the box.
FACE_SCALES = 4


def _solve(a, b, lo, hi):
    """Bounded linear least squares min |a k - b|^2 with lo <= k <= hi.

    The problem is a convex quadratic on a box, so its minimum is the unconstrained minimum on
    one face of the box (each k_j free, at lo_j or at hi_j) that is feasible; for a few scales
    every face is tried on the normal equations (3^m small solves), else scipy's BVLS."""
    m = a.shape[1]
    if m == 0:
        return np.zeros(0)
    if np.all(lo == 0.0):  # the usual case: non-negative least squares, then the upper bounds
        from scipy.optimize import nnls
        k = nnls(a, b)[0]
        if np.all(k <= hi):
            return k
    if m > FACE_SCALES:
        from scipy.optimize import lsq_linear
        return lsq_linear(a, b, bounds=(lo, hi), method="bvls").x
    import itertools
    gram, rhs, bb = a.T @ a, a.T @ b, float(b @ b)
    best, best_k = math.inf, np.clip(np.zeros(m), lo, hi)
    for face in itertools.product((0, 1, 2), repeat=m):  # free, at lower, at upper
        k = np.where(np.array(face) == 1, lo, hi).astype(float)
        free = np.array(face) == 0
        if free.any():
            g = gram[np.ix_(free, free)]
            r = rhs[free] - gram[np.ix_(free, ~free)] @ k[~free]
            try:
                k[free] = np.linalg.solve(g, r)
            except np.linalg.LinAlgError:
                k[free] = np.linalg.lstsq(g, r, rcond=None)[0]
            if np.any(k < lo - 1e-12) or np.any(k > hi + 1e-12):
                continue
        with np.errstate(over="ignore", invalid="ignore"):
            value = float(k @ gram @ k - 2.0 * k @ rhs + bb)
        if value < best:
            best, best_k = value, np.clip(k, lo, hi)
    return best_k


def _shape_points(lobes):
    """Every combination of the lobes' shape grids ``(K, m)``, or a Sobol subset of their box
    when the product exceeds :data:`MAX_CANDIDATES`; ``m`` may be 0 (one empty point)."""
    grids = [g for lobe in lobes for _, _, g in lobe.shape]
    if not grids:
        return np.zeros((1, 0))
    if math.prod(len(g) for g in grids) <= MAX_CANDIDATES:
        mesh = np.meshgrid(*grids, indexing="ij")
        return np.stack([m.ravel() for m in mesh], axis=-1)
    from scipy.stats import qmc
    u = qmc.Sobol(len(grids), scramble=True, seed=np.random.default_rng(0)).random_base2(
        int(math.log2(MAX_CANDIDATES)))
    return np.stack([np.exp(np.log(g[0]) + u[:, i] * np.log(g[-1] / g[0])) if g[0] > 0
                     and np.allclose(np.diff(np.log(g)), np.log(g[1] / g[0]))
                     else g[0] + u[:, i] * (g[-1] - g[0]) for i, g in enumerate(grids)], axis=-1)


def candidates(problem, samples=None):
    """The data-driven candidates ``(K, len(x))``: for each point of the shape grid, the
    scales projected out by bounded least squares on ``samples`` (default: a subsample of the
    problem's, :func:`subsample`); the other parameters at their working values."""
    from ..models.base import Sum
    samples = subsample(problem.samples) if samples is None else samples
    model, nch = problem.base, problem.channels
    prefixes = model.lobe_names() if isinstance(model, Sum) else [model.name]
    x0 = problem.x0
    values = problem.values(x0)
    lobes = [_Lobe(lobe, prefix, problem.free, values, nch)
             for lobe, prefix in zip(model.lobes, prefixes)]
    terms = losses.terms(problem.loss_name, samples, len(problem.free))
    e, z = _linearised(terms)
    root_w = np.sqrt(samples.weights)[:, None]
    e, z = root_w * e, root_w * z
    bounds = {p.declared: (p.lower, p.upper) for p in problem.free}
    out, cache = [], {}
    for point in _shape_points(lobes):
        trial = {k: np.array(v, dtype=float) for k, v in values.items()}
        i, keys = 0, []
        for lobe in lobes:
            keys.append(tuple(point[i:i + len(lobe.shape)]))
            for _, d, _ in lobe.shape:
                if d is None:  # a declared pattern of the coefficients (Sobol: nearest index)
                    pattern = lobe.directions[int(round(point[i]))]
                    for name, v in zip(lobe.scale_names, pattern):
                        trial[name] = np.full(np.shape(trial[name]), v)
                else:
                    trial[d] = np.broadcast_to(point[i], np.shape(trial[d])).copy()
                i += 1
        columns, fixed = [], np.zeros_like(z)
        for l, lobe in enumerate(lobes):
            key = (l, keys[l])  # a lobe's unit values depend on its own shape only
            if key not in cache:
                cache[key] = _lobe_values(lobe, trial, samples, nch, unit=bool(lobe.scale))
            f = cache[key]
            if lobe.scale:
                current = _scale_of(lobe, trial, nch)
                fixed += np.where(lobe.free_channels, 0.0, current) * f
                columns.append(f)
            else:
                fixed += f
        free_lobes = [l for l in lobes if l.scale]
        for c in range(nch):
            cols = [k for k, l in enumerate(free_lobes) if l.free_channels[c]]
            a = np.stack([e[:, c] * columns[k][:, c] for k in cols], axis=-1) if cols \
                else np.zeros((len(z), 0))
            lo = np.array([_scale_box(free_lobes[k], bounds, trial, c)[0] for k in cols])
            hi = np.array([_scale_box(free_lobes[k], bounds, trial, c)[1] for k in cols])
            k = _solve(a, z[:, c] - e[:, c] * fixed[:, c], lo, hi)
            for kk, coef in zip(cols, k):
                _set_scale(free_lobes[kk], trial, c, coef, bounds)
        out.append(_to_x(problem, trial))
    return np.array(out)


def _lobe_values(lobe, trial, samples, nch, unit):
    """The lobe's values (n, C) at ``trial`` (scale parameters at unit scale when ``unit``)."""
    changes = {}
    for name in type(lobe.lobe).PARAMS:
        d = f"{lobe.prefix}.{name.name}"
        if d in trial and not isinstance(lobe.lobe.values.get(name.name), str):
            changes[name.name] = trial[d]
    if unit:
        changes.update(lobe.unit(trial))
    built = lobe.lobe.replace(**changes)
    f = np.asarray(built.eval(samples.wi, samples.wo), dtype=float)
    return np.broadcast_to(f.reshape(len(samples.wi), -1), (len(samples.wi), nch))


def _scale_of(lobe, trial, nch):
    """The lobe's current scale factor per channel (C,): the linear scale, or for a power law
    |C|^n of its working coefficients."""
    if lobe.power is None:
        return np.broadcast_to(trial[lobe.scale_names[0]], (nch,))
    c = np.array([np.broadcast_to(trial[d], (nch,)) for d in lobe.scale_names])
    n = np.broadcast_to(trial[f"{lobe.prefix}.{lobe.power}"], (nch,))
    return np.abs(c).max(axis=0) ** n


def _scale_box(lobe, bounds, trial, c):
    """Bounds of the scale factor in channel c: the scale parameter's fit box, or for a power
    law [0, (largest coefficient magnitude the box allows)^n]."""
    lo, hi = bounds[lobe.scale_names[0]]
    if lobe.power is None:
        return lo, hi
    n = float(np.broadcast_to(trial[f"{lobe.prefix}.{lobe.power}"], (lobe.nch,))[c])
    top = min(max(abs(lo), abs(hi)) for lo, hi in (bounds[d] for d in lobe.scale_names))
    return 0.0, math.exp(min(n * math.log(top), losses_max_log := 690.0)) if top > 0 else 0.0


#: A power-law lobe's scale factor is kept at least this: a zero factor would zero its
#: coefficients, where the gradient in them vanishes too.
POWER_FLOOR = 1e-6


def _set_scale(lobe, trial, c, coef, bounds):
    """Write the projected scale factor of channel c into ``trial``."""
    if lobe.power is None:
        d = lobe.scale_names[0]
        trial[d] = np.array(trial[d], dtype=float)
        if trial[d].ndim == 0:
            trial[d] = np.full(lobe.nch, float(trial[d]))
        trial[d][c] = coef
        return
    n = float(np.broadcast_to(trial[f"{lobe.prefix}.{lobe.power}"], (lobe.nch,))[c])
    unit = lobe.unit(trial)
    factor = max(coef, POWER_FLOOR) ** (1.0 / n)
    for name, d in zip(lobe.scale, lobe.scale_names):
        trial[d] = np.broadcast_to(trial[d], (lobe.nch,)).astype(float)
        lo, hi = bounds.get(d, (-np.inf, np.inf))
        trial[d][c] = np.clip(unit[name][c] * factor, lo, hi)


def _to_x(problem, trial):
    """x of the declared values ``trial`` (a shared parameter takes its channels' mean)."""
    named = {}
    for p in problem.free:
        v = np.asarray(trial[p.declared], dtype=float)
        value = float(v.mean()) if p.channel is None else float(np.broadcast_to(
            v, (problem.channels,))[p.channel])
        named[p.name] = float(np.clip(value, p.lower, p.upper))
    return problem.to_x(named)


def data_driven(problem, screen=None):
    """The data-driven start: the candidate of :func:`candidates` with the lowest loss on the
    subsample (``screen``, a problem on it; default built here). Returns ``(x, loss)``."""
    screen = problem.restricted(subsample(problem.samples)) if screen is None else screen
    X = candidates(problem, screen.samples)
    with serial_below(len(screen.samples.wi)):
        scores = screen.channel_losses(X).sum(axis=1)
    scores = np.where(np.isfinite(scores), scores, np.inf)
    best = int(np.argmin(scores))
    return X[best], float(scores[best])
