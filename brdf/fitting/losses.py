"""Error metrics for fitting BRDF models to measured samples, sample weights and the cutoff.

Every metric is a weighted mean of squared residuals over the samples and channels kept,

    L = sum_k sum_c w_k r_kc^2 / sum_k sum_c w_k [y_kc measured],
    r_kc = g(s_kc f_kc) - g(s_kc y_kc),

with f the model, y the measurement, a per-entry scale s and g the identity or a logarithm
(:data:`LOSSES` lists them with their sources). ``w_k`` is the solid-angle measure the sample
stands for (:func:`sample_weights`), normalised to sum 1, so that on a non-uniform table such as
MERL's, whose nodes crowd near the specular peak, L approximates an integral over direction
pairs instead of over table indices. The chi-square metric is the exception: it keeps its
statistical meaning (unweighted, divided by the degrees of freedom).

Samples beyond the grazing cutoff (:func:`prepare`, default 80 degrees on both theta_i and
theta_o) are left out, as are missing (NaN) values: a sample with some channels missing keeps
the others.
"""

import math
from dataclasses import dataclass

import numpy as np

from ..arguments import real, shown
from ..errors import InputError

__all__ = ["LOSSES", "DEFAULT_CUTOFF", "LOG_OFFSET", "RELATIVE_FLOOR", "SIGMA_FLOOR", "Samples",
           "Terms", "prepare", "sample_weights", "merl_solid_angles", "terms", "evaluate",
           "channel_values",
           "check_loss"]

#: The metrics and where they come from.
LOSSES = {
    "cosine-l2": "Ngan et al. 2005, Experimental Analysis of BRDF Models: residuals of "
                 "f cos(theta_i)",
    "l2": "plain least squares on f",
    "relative-l2": "least squares on (f - y) / y, y floored (see RELATIVE_FLOOR)",
    "log": "Loew et al. 2012, BRDF Models for Accurate and Efficient Rendering of Glossy "
           "Surfaces, metric E2: residuals of log(1 + f cos(theta_i))",
    "chi-square": "reduced chi-square sum((f - y) / sigma)^2 / (values - free parameters), "
                  "with the table's per-sample sigma",
}
#: Grazing cutoff in degrees. Near grazing, gonioreflectometer errors (the footprint spreading
#: beyond the sample, detector alignment) grow, and the Fresnel and shadowing factors of models
#: and materials alike vary fastest; these few samples would otherwise dominate a squared-error
#: fit. Ngan et al. 2005 leave out the MERL samples beyond 80 degrees for this reason.
DEFAULT_CUTOFF = 80.0
#: The offset inside the logarithm of the ``log`` metric, in 1/sr: Loew et al. 2012 (E2) use
#: log(1 + f cos(theta_i)), which is close to linear for dim samples and compresses highlights.
LOG_OFFSET = 1.0
#: ``relative-l2`` divides by max(|y|, RELATIVE_FLOOR x the channel's mean |y|): a sample that
#: measured zero would otherwise get an infinite weight.
RELATIVE_FLOOR = 1e-3
#: ``chi-square`` raises sigma to at least SIGMA_FLOOR x the channel's mean sigma: a relative
#: noise model states sigma = 0 for a zero value, which would make that sample infinitely sure.
SIGMA_FLOOR = 1e-3


@dataclass(frozen=True)
class Samples:
    """The measured samples a fit uses, after the cutoff and with weights.

    Attributes
    ----------
    wi, wo : ndarray, shape (n, 3)
        Contiguous directions of the samples kept.
    values : ndarray, shape (n, C)
        Measured BRDF in 1/sr; NaN where a channel is missing.
    sigma : ndarray, shape (n, C) or None
        Standard deviations, when the table has them.
    weights : ndarray, shape (n,)
        Solid-angle weights of the samples (:func:`sample_weights`), summing to 1.
    total : int
        Samples in the table before the cutoff.
    cutoff : float
        Grazing cutoff in degrees.
    weighting : str
        ``"merl-solid-angle"`` or ``"uniform"``.
    """

    wi: np.ndarray
    wo: np.ndarray
    values: np.ndarray
    sigma: object
    weights: np.ndarray
    total: int
    cutoff: float
    weighting: str

    @property
    def channels(self):
        return self.values.shape[1]

    @property
    def measured(self):
        """Mask (n, C) of the values that were measured (not NaN)."""
        return np.isfinite(self.values)

    def describe(self):
        """JSON-ready summary for fit reports."""
        return {"samples_total": self.total, "samples_used": len(self.values),
                "values_used": int(self.measured.sum()), "channels": self.channels,
                "cutoff_deg": self.cutoff, "weighting": self.weighting}


@dataclass(frozen=True)
class Terms:
    """A metric reduced to arrays: ``sum_k sum_c weight_k (g(scale_kc f_kc) - target_kc)^2 /
    norm`` with g the identity when ``offset`` is 0, else ``log(offset + .)``."""

    scale: np.ndarray
    target: np.ndarray
    weight: np.ndarray
    offset: float
    norm: float


def _cell_edges(n):
    """Edges 0, 1/2, 3/2, ..., n - 3/2, n of the index cells of nodes 0 .. n-1 on [0, n]."""
    return np.concatenate([[0.0], np.arange(1, n) - 0.5, [float(n)]])


def merl_solid_angles():
    """Measure (sr^2) of the set of direction pairs each MERL grid node stands for.

    The pair measure in half/difference angles is
    d(wi) d(wo) = 4 cos(theta_d) sin(theta_h) sin(theta_d) d(theta_h) d(phi_h) d(theta_d) d(phi_d)
    (d(wo) = 4 (wi.h) d(h) for a fixed wi, Walter et al. 2007 eq. 14; wi -> d, wi seen from the
    half vector's frame, is a rotation for each h, Rusinkiewicz 1998). A node stands for the
    index cell [i - 1/2, i + 1/2] on each axis, clipped to the grid, with theta_h =
    (u / 90)^2 pi/2 (docs/conventions.md §6); isotropy gives phi_h its full 2 pi, and reciprocity
    lets the node stand for phi_d + pi too. The integrals over each cell are exact, so the
    weights of all 1,458,000 nodes sum to 8 pi^2, the measure of every (wi, wo) with theta_h and
    theta_d below 90 degrees (half of them have wi or wo below the horizon).

    Returns
    -------
    ndarray, shape (1458000,)
        In the index order ``i_phi_d + 180 i_theta_d + 16200 i_theta_h``.
    """
    from ..io.merl import SHAPE
    n_h, n_d, n_p = SHAPE
    half_pi = 0.5 * math.pi
    theta_h = (_cell_edges(n_h) / n_h) ** 2 * half_pi
    sin_h = -np.diff(np.cos(theta_h))                     # integral of sin(theta_h)
    theta_d = _cell_edges(n_d) * (half_pi / n_d)
    cos_sin_d = 0.5 * np.diff(np.sin(theta_d) ** 2)       # integral of cos(theta_d) sin(theta_d)
    phi = 2.0 * math.pi * 2.0 * (math.pi / n_p)           # phi_h, and phi_d with phi_d + pi
    cell = 4.0 * phi * sin_h[:, None] * cos_sin_d[None, :]
    return np.repeat(cell.reshape(-1), n_p)


def sample_weights(data):
    """Solid-angle weights of a table's samples, ``((N,), name)``.

    A MERL table gets the measure of each node's cell (:func:`merl_solid_angles`). Other tables
    get uniform weights: each sample stands for an equal share. That is exact for samples drawn
    uniformly in solid angle (``random:N`` geometries), and a plain average, without a
    density estimate to second-guess, for the scattered layouts of real gonioreflectometers.
    """
    from ..io.merl import MerlTable
    if isinstance(data, MerlTable):
        return merl_solid_angles(), "merl-solid-angle"
    return np.ones(len(data.values)), "uniform"


def _array(data, name, n=None):
    """``data.name`` as a float64 2-D array: (N, 3) directions or (N, C) values."""
    a = np.asarray(getattr(data, name), dtype=np.float64)
    if a.ndim == 1 and name in ("values", "sigma"):
        a = a[:, None]
    direction = name in ("wi", "wo")
    if a.ndim != 2 or (direction and a.shape[1] != 3) or (n is not None and len(a) != n):
        expected = "(N, 3)" if direction else f"({n}, C)"
        raise InputError(f"fit data: {name} must be shaped {expected}, got {a.shape}")
    return a


def prepare(data, cutoff=DEFAULT_CUTOFF):
    """The samples of ``data`` a fit uses: above the horizon, within ``cutoff`` degrees of the
    normal for both directions, with at least one measured channel.

    Parameters
    ----------
    data : Table or object with ``wi``, ``wo``, ``values`` (and optionally ``sigma``)
    cutoff : float
        Largest theta_i and theta_o in degrees, in (0, 90]; see :data:`DEFAULT_CUTOFF`.

    Returns
    -------
    Samples
    """
    cutoff = real(cutoff, "cutoff (degrees)", 0.0, 90.0, low_open=True)
    if not all(hasattr(data, a) for a in ("wi", "wo", "values")):
        raise InputError(f"fit data must be a table (or have wi, wo and values), got "
                         f"{type(data).__name__}")
    wi, wo = _array(data, "wi"), _array(data, "wo")
    values = _array(data, "values", len(wi))
    sigma = None if getattr(data, "sigma", None) is None else _array(data, "sigma", len(wi))
    weights, weighting = sample_weights(data)
    lowest = math.cos(math.radians(cutoff)) - 1e-12  # theta <= cutoff, rounding allowed
    keep = (wi[:, 2] >= lowest) & (wo[:, 2] >= lowest) & (wi[:, 2] > 0.0) & (wo[:, 2] > 0.0)
    measured = np.zeros(len(wi), dtype=bool)
    for column in values.T:  # a column at a time: any(axis=1) is 5x slower on (N, 3)
        measured |= np.isfinite(column)
    # indices and take(): boolean indexing of (N, C) rows is 3x slower on MERL-size tables
    keep = np.flatnonzero(keep & measured)
    if not len(keep):
        raise InputError(f"fit data: no measured sample within {cutoff:g} degrees of the normal")
    w = weights[keep]
    return Samples(wi.take(keep, axis=0), wo.take(keep, axis=0), values.take(keep, axis=0),
                   None if sigma is None else sigma.take(keep, axis=0),
                   w / w.sum(), len(wi), cutoff, weighting)


def check_loss(name, samples=None):
    """Raise InputError unless ``name`` is a metric that ``samples`` can be scored with."""
    if not isinstance(name, str) or name not in LOSSES:
        raise InputError(f"unknown loss {shown(name)}; losses: {', '.join(LOSSES)}")
    if name == "chi-square" and samples is not None and samples.sigma is None:
        raise InputError("loss chi-square needs per-sample sigma, and this table has none; "
                         f"use one of {', '.join(n for n in LOSSES if n != 'chi-square')}")


def _floored(a, valid, fraction):
    """|a| raised per channel to at least ``fraction`` x the channel's mean |a| over the
    ``valid`` entries (1 where there is none); invalid entries count as 0."""
    if valid.all():
        mag = np.abs(a)
        mean = mag.mean(axis=0)
    else:
        mag = np.where(valid, np.abs(np.where(valid, a, 0.0)), 0.0)
        mean = mag.sum(axis=0) / np.maximum(valid.sum(axis=0), 1)
    floor = np.where(mean > 0.0, fraction * mean, 1.0)
    return np.maximum(mag, floor)


def terms(name, samples, n_free=0):
    """Arrays of metric ``name`` on ``samples`` (see :class:`Terms`); missing values get scale
    and target 0, so they add nothing, and are not counted in the norm.

    Parameters
    ----------
    name : str
        A key of :data:`LOSSES`.
    samples : Samples
    n_free : int
        Free parameters of the fit (the chi-square degrees of freedom subtract them).
    """
    check_loss(name, samples)
    y = samples.values
    valid = np.isfinite(y)
    if name == "chi-square":
        valid &= np.isfinite(samples.sigma)
    complete = bool(valid.all())
    cos_i = samples.wi[:, 2:3]
    weight, offset = samples.weights, 0.0
    if name == "l2":
        scale = np.ones_like(y)
    elif name == "cosine-l2":
        scale = np.repeat(cos_i, y.shape[1], axis=1)      # Ngan et al. 2005: f cos(theta_i)
    elif name == "relative-l2":
        scale = 1.0 / _floored(y, valid, RELATIVE_FLOOR)  # (f - y) / y
    elif name == "log":
        scale = np.repeat(cos_i, y.shape[1], axis=1)      # Loew et al. 2012, E2
        offset = LOG_OFFSET
    else:
        scale = 1.0 / _floored(samples.sigma, valid, SIGMA_FLOOR)  # (f - y) / sigma
        weight = np.ones(len(y))
    if complete:
        target = scale * y
    else:
        scale[~valid] = 0.0
        target = scale * np.where(valid, y, 0.0)
    if offset:
        target = np.log(offset + target)
    count = np.full(len(y), y.shape[1]) if complete else valid.sum(axis=1)
    if name == "chi-square":
        norm = float(count.sum() - n_free)
        if norm <= 0:
            raise InputError(f"chi-square needs more measured values ({int(count.sum())}) than "
                             f"free parameters ({n_free})")
    else:
        norm = float(weight @ count)
    return Terms(scale, target, np.ascontiguousarray(weight, dtype=np.float64), offset, norm)


def evaluate(t, f):
    """Metric value of model values ``f`` (n, C) against :class:`Terms` ``t``, in numpy."""
    return float(channel_values(t, f).sum())


def channel_values(t, f):
    """Per-channel contributions ``(C,)`` to :func:`evaluate`, in numpy."""
    v = t.scale * f
    if t.offset:
        v = np.log(t.offset + v)
    r = v - t.target
    return (t.weight[:, None] * r * r).sum(axis=0) / t.norm
