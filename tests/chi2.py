"""Pearson chi-square goodness-of-fit test of a direction sampler against its density.

The method follows the sampling tests of Mitsuba 3 (Jakob et al., ``chi2.py``): draw many samples,
histogram them on a grid in a measure-preserving parametrisation of the hemisphere, integrate the
claimed density over the same cells, pool cells with small expected counts, and compare with
Pearson's statistic. Differences from Mitsuba: the grid is ``(cos theta, phi)`` over the upper
hemisphere only, whose area element equals solid angle, so a solid-angle pdf needs no Jacobian;
cells are integrated by adaptive Gauss-Legendre quadrature rather than a fixed trapezoid rule,
because sharp lobes (exponent 1000) vary many orders of magnitude inside one cell; and samples the
density does not cover (invalid samples with pdf 0 and delta-lobe samples with pdf inf) form one
extra cell whose expected count is ``N (1 - integral of pdf)``, so a sampler that drops or adds
mass is caught too.

The cells are uniform in ``(cos theta, phi)`` by default; :meth:`Grid.focused` crowds them
toward one direction (the mirror direction at grazing incidence, where the sharpest lobes pile
up against the horizon), as Mitsuba's SphericalDomain resolves lobes about its pole.
"""

import dataclasses
import math

import numpy as np
from scipy import stats

#: Cells with fewer expected samples are pooled (Cochran's rule of thumb for Pearson's test).
POOL_THRESHOLD = 5.0


@dataclasses.dataclass
class Chi2Result:
    """Outcome of :func:`chi2_test`; ``observed`` and ``expected`` hold the grid cells (rows
    cos theta, columns phi) and the extra cell holds samples the density does not cover."""

    statistic: float
    dof: int
    p_value: float
    pdf_integral: float
    observed: np.ndarray
    expected: np.ndarray
    observed_extra: int
    expected_extra: float
    problems: list

    def rejected(self, significance):
        """Whether the null hypothesis (samples follow the pdf) is rejected."""
        return bool(self.problems) or not self.p_value >= significance

    def describe(self):
        """One paragraph for assertion messages: statistic, worst cells, sanity problems."""
        resid = (self.observed - self.expected) / np.sqrt(np.maximum(self.expected, 1.0))
        worst = zip(*np.unravel_index(np.argsort(-np.abs(resid), axis=None)[:3], resid.shape))
        cells = "; ".join(f"cell (cos {i}, phi {j}): observed {self.observed[i, j]:.0f}, "
                          f"expected {self.expected[i, j]:.1f}" for i, j in worst)
        return (f"chi2 = {self.statistic:.1f} with {self.dof} dof, p = {self.p_value:.3g}; "
                f"pdf integral {self.pdf_integral:.6f}; uncovered samples "
                f"{self.observed_extra} vs {self.expected_extra:.1f} expected; worst {cells}; "
                f"problems: {self.problems or 'none'}")


@dataclasses.dataclass(frozen=True)
class Grid:
    """Cell edges: ``cos_edges`` rising from 0 to 1, ``phi_edges`` rising over one turn from
    any start (azimuths are taken modulo 2 pi from ``phi_edges[0]``)."""

    cos_edges: np.ndarray
    phi_edges: np.ndarray

    @property
    def shape(self):
        return len(self.cos_edges) - 1, len(self.phi_edges) - 1

    @classmethod
    def uniform(cls, shape):
        """``shape`` = (cells in cos theta over [0, 1], cells in phi over [-pi, pi])."""
        n_c, n_p = shape
        return cls(np.linspace(0.0, 1.0, n_c + 1), np.linspace(-math.pi, math.pi, n_p + 1))

    @classmethod
    def focused(cls, shape, toward):
        """Cells whose size falls quadratically toward the direction ``toward`` (3,): in cos
        theta on both sides of its cos theta (each side's share of the cells in proportion to
        the square root of its length, so the smallest cells on the two sides match), and in
        phi on both sides of its azimuth. The smallest cells are 1/n^2 of their side, where a
        uniform grid's are 1/n: a lobe of width 0.03 rad at the horizon spans several cells in
        each coordinate."""
        n_c, n_p = shape
        c0 = float(min(max(toward[2], 0.0), 1.0))
        below = int(round(n_c * math.sqrt(c0) / (math.sqrt(c0) + math.sqrt(1.0 - c0))))
        below = min(max(below, 1 if c0 > 0.0 else 0), n_c - (1 if c0 < 1.0 else 0))
        s_lo = np.linspace(1.0, 0.0, below + 1)
        s_hi = np.linspace(0.0, 1.0, n_c - below + 1)
        cos_edges = np.concatenate([c0 - c0 * s_lo ** 2, (c0 + (1.0 - c0) * s_hi ** 2)[1:]])
        cos_edges[0], cos_edges[-1] = 0.0, 1.0
        phi0 = math.atan2(toward[1], toward[0])
        s = np.linspace(-1.0, 1.0, n_p + 1)
        return cls(cos_edges, phi0 + math.pi * np.sign(s) * s * s)


def _as_grid(grid):
    return grid if isinstance(grid, Grid) else Grid.uniform(grid)


def sidak(significance, n_tests):
    """Per-test level so that ``n_tests`` independent tests reject with ``significance`` overall
    (Sidak 1967, "Rectangular confidence regions for the means of multivariate normal
    distributions")."""
    return 1.0 - (1.0 - significance) ** (1.0 / n_tests)


def directions(cos_theta, phi):
    """Unit vectors ``(..., 3)`` on the upper hemisphere from ``cos theta`` and ``phi``."""
    sin_theta = np.sqrt(np.maximum(0.0, 1.0 - cos_theta * cos_theta))
    return np.stack([sin_theta * np.cos(phi), sin_theta * np.sin(phi), cos_theta], -1)


def _gauss_legendre(order):
    x, w = np.polynomial.legendre.leggauss(order)
    return 0.5 * (x + 1.0), 0.5 * w


def _rect_integrals(density, rects, nodes, weights):
    """Integral over each ``(theta0, theta1, phi0, phi1)`` rectangle of ``density sin(theta)``
    (solid angle) by a product Gauss-Legendre rule.

    Integrating in theta rather than cos(theta) keeps the integrand smooth at the pole, where
    sin(theta) = sqrt(1 - cos^2) has an infinite derivative with respect to cos(theta). The
    rule's points form a product, so the sines and cosines are taken per row and per column
    of nodes and only multiplied out: an adaptive integration evaluates hundreds of millions
    of points, and the trigonometry over every point was most of its time.
    """
    t0, t1, p0, p1 = rects.T
    k = len(nodes)
    t = t0[:, None] + (t1 - t0)[:, None] * nodes
    p = p0[:, None] + (p1 - p0)[:, None] * nodes
    cos_t, sin_t = np.cos(t), np.sin(t)
    cos_p, sin_p = np.cos(p), np.sin(p)
    d = np.empty((len(rects), k, k, 3))
    np.multiply(sin_t[:, :, None], cos_p[:, None, :], out=d[..., 0])
    np.multiply(sin_t[:, :, None], sin_p[:, None, :], out=d[..., 1])
    d[..., 2] = cos_t[:, :, None]
    values = np.asarray(density(d.reshape(-1, 3))).reshape(len(rects), k, k)
    return ((values @ weights) * sin_t) @ weights * (t1 - t0) * (p1 - p0)


def _split(rects):
    """The four quarters of each rectangle, in blocks of four."""
    t0, t1, p0, p1 = rects.T
    tm, pm = 0.5 * (t0 + t1), 0.5 * (p0 + p1)
    quarters = [(t0, tm, p0, pm), (t0, tm, pm, p1), (tm, t1, p0, pm), (tm, t1, pm, p1)]
    return np.stack([np.stack(q, -1) for q in quarters], 1).reshape(-1, 4)


def integrate_cells(density, shape, order=5, atol=1e-8, rtol=1e-4, max_level=10):
    """Integral of a solid-angle density over each cell of a ``(cos theta, phi)`` grid.

    Adaptive Gauss-Legendre: a rectangle's estimate is accepted when splitting it in four
    changes it by less than ``atol`` times its size relative to the grid (the square root of
    its share of the ``(theta, phi)`` area) plus ``rtol`` of its value; otherwise its quarters
    are refined in turn, up to ``max_level`` splits. Scaling by size, not area, lets kinks
    along curves (a clamped cosine lobe) converge: there the error of a rectangle of size h
    falls like h^3 while an area-scaled tolerance would fall like h^2.

    Parameters
    ----------
    density : callable
        Maps directions ``(m, 3)`` to densities ``(m,)``.
    shape : (int, int) or Grid
        Number of cells of a uniform grid in ``cos theta`` (over [0, 1]) and in ``phi`` (over
        [-pi, pi]), or the cells' edges.

    Returns
    -------
    cells : ndarray, shape ``grid.shape``
    converged : bool
        False when some rectangle hit ``max_level`` without meeting the tolerance.
    """
    grid = _as_grid(shape)
    shape = n_c, n_p = grid.shape
    nodes, weights = _gauss_legendre(order)
    te = np.arccos(grid.cos_edges)  # theta edges of the cos-theta cells
    pe = grid.phi_edges
    ic, ip = np.meshgrid(np.arange(n_c), np.arange(n_p), indexing="ij")
    rects = np.stack([te[ic + 1], te[ic], pe[ip], pe[ip + 1]], -1).reshape(-1, 4)
    owner = np.arange(n_c * n_p)
    coarse = _rect_integrals(density, rects, nodes, weights)
    total = np.zeros(n_c * n_p)
    for _ in range(max_level):
        children = _split(rects)
        fine_parts = _rect_integrals(density, children, nodes, weights)
        fine = fine_parts.reshape(-1, 4).sum(1)
        area = (rects[:, 1] - rects[:, 0]) * (rects[:, 3] - rects[:, 2])
        done = np.abs(fine - coarse) <= atol * np.sqrt(area) / math.pi + rtol * np.abs(fine)
        np.add.at(total, owner[done], fine[done])
        again = np.repeat(~done, 4)
        rects, coarse, owner = children[again], fine_parts[again], np.repeat(owner, 4)[again]
        if rects.shape[0] == 0:
            return total.reshape(shape), True
    np.add.at(total, owner, coarse)
    return total.reshape(shape), False


def histogram(wo, shape):
    """Counts of directions ``(m, 3)`` in the ``(cos theta, phi)`` cells of a grid (``shape``
    as for :func:`integrate_cells`)."""
    grid = _as_grid(shape)
    n_c, n_p = grid.shape
    i = np.clip(np.searchsorted(grid.cos_edges, wo[:, 2], side="right") - 1, 0, n_c - 1)
    phi0 = grid.phi_edges[0]
    phi = phi0 + np.mod(np.arctan2(wo[:, 1], wo[:, 0]) - phi0, 2.0 * math.pi)
    j = np.clip(np.searchsorted(grid.phi_edges, phi, side="right") - 1, 0, n_p - 1)
    return np.bincount(i * n_p + j, minlength=n_c * n_p).reshape(n_c, n_p).astype(float)


def _pool(observed, expected, threshold):
    """Merge consecutive cells into groups expecting at least ``threshold`` samples each; a
    short remainder joins the last group."""
    groups_obs, groups_exp = [], []
    acc_obs = acc_exp = 0.0
    for o, e in zip(observed, expected):
        acc_obs += o
        acc_exp += e
        if acc_exp >= threshold:
            groups_obs.append(acc_obs)
            groups_exp.append(acc_exp)
            acc_obs = acc_exp = 0.0
    if acc_exp > 0.0 or acc_obs > 0.0:
        if groups_exp:
            groups_obs[-1] += acc_obs
            groups_exp[-1] += acc_exp
        else:
            groups_obs.append(acc_obs)
            groups_exp.append(acc_exp)
    return np.array(groups_obs), np.array(groups_exp)


def pearson(observed, expected, threshold=POOL_THRESHOLD):
    """Pearson's statistic and degrees of freedom after pooling small cells.

    Cells are sorted by expected count and those below ``threshold`` pooled in that order (as
    Mitsuba 3 does). Cells with nothing expected and nothing observed carry no information and
    are dropped.
    """
    observed = np.asarray(observed, float).ravel()
    expected = np.asarray(expected, float).ravel()
    keep = (expected > 0.0) | (observed > 0.0)
    order = np.argsort(expected[keep], kind="stable")
    observed, expected = observed[keep][order], expected[keep][order]
    small = expected < threshold
    pooled_obs, pooled_exp = _pool(observed[small], expected[small], threshold)
    obs = np.concatenate([pooled_obs, observed[~small]])
    exp = np.concatenate([pooled_exp, expected[~small]])
    with np.errstate(divide="ignore"):
        stat = float(np.sum((obs - exp) ** 2 / exp))
    return stat, obs.size - 1


def chi2_test(sample, pdf, n_samples=1_000_000, shape=(50, 100), seed=0):
    """Test that ``sample`` draws directions with the solid-angle density ``pdf``.

    Parameters
    ----------
    sample : callable
        Maps uniform numbers ``(n, 2)`` in [0, 1) to ``(wo (n, 3), pdf (n,))``; a pdf of 0 marks
        an invalid sample and ``inf`` a sample of a delta lobe.
    pdf : callable
        Maps directions ``(m, 3)`` to the density ``(m,)`` that ``sample`` claims to follow.
    n_samples : int
    shape : (int, int) or Grid
        Cells of a uniform grid in ``cos theta`` and in ``phi``, or the cells' edges.
    seed : int

    Returns
    -------
    Chi2Result
    """
    u = np.random.default_rng(seed).random((n_samples, 2))
    wo, pdf_sampled = sample(u)
    problems = []
    covered = np.isfinite(pdf_sampled) & (pdf_sampled > 0.0)
    if np.any(np.isnan(pdf_sampled)) or np.any(pdf_sampled < 0.0):
        problems.append("sample returned NaN or negative pdfs")
    if np.any(wo[covered, 2] <= 0.0):
        problems.append(f"{np.sum(wo[covered, 2] <= 0.0)} valid samples below the horizon")
    if not np.allclose(np.linalg.norm(wo[covered], axis=-1), 1.0, atol=1e-9):
        problems.append("sampled directions are not unit vectors")
    observed = histogram(wo[covered], shape)
    cells, converged = integrate_cells(pdf, shape)
    if not converged:
        problems.append("the cell integrals of the pdf did not converge")
    if np.any(cells < 0.0):
        problems.append("the pdf is negative somewhere")
    integral = float(cells.sum())
    expected = n_samples * cells
    observed_extra = int(n_samples - covered.sum())
    expected_extra = n_samples * max(0.0, 1.0 - integral)
    if np.any((expected == 0.0) & (observed > 0.0)):
        problems.append("samples fell in cells where the pdf is 0")
    stat, dof = pearson(np.append(observed.ravel(), observed_extra),
                        np.append(expected.ravel(), expected_extra))
    if dof < 1:
        problems.append("too few degrees of freedom")
    p_value = float(stats.chi2.sf(stat, max(dof, 1)))
    return Chi2Result(stat, dof, p_value, integral, observed, expected, observed_extra,
                      expected_extra, problems)
