"""The ``path`` method of :func:`brdf.fit_images`: image-space least squares through the path
tracer.

Each evaluation renders every view with the candidate BRDF on its ``@material`` shapes
(:func:`brdf.render.render`: interreflection, shadows and every light the renderer has) and
compares the render with the photograph on the pixels used. The same render gives the
derivatives of those pixels in the free parameters (:class:`brdf.render.Derivatives`:
forward-mode derivatives carried along the paths, the families' analytic gradients).

The random streams are the same in every render (one ``seed``), and within a solve the paths
are drawn as for a fixed proposal, the parameters the solve started from, while f is evaluated
at the candidate (detached sampling): the objective is then a smooth function of the
parameters, which the derivatives differentiate exactly, and its Monte Carlo error does not
change from one evaluation to the next. Each solve starts again from where the last ended,
with the proposal moved there, until the parameters stop moving (by less than half their
standard error, or :data:`TOLERANCE`).

A solve is Gauss-Newton with a trust region (:func:`scipy.optimize.least_squares`, ``trf``,
Branch, Coleman & Li 1999) on the residuals ``(k I(theta) - y) / sigma``: ``k`` is the free
scale (exposure or light power, fitted jointly when asked: the render predicts the reference
pixels of known materials as well as the material's), ``sigma`` the stated photograph noise
(:mod:`brdf.capture.inverse`) at the solve's start and the render's own Monte Carlo error in
quadrature (iteratively reweighted). The covariance at the optimum is the Gauss-Newton
(Laplace) one made robust to pixels noisier than their weights say, the sandwich ``H^-1 J^T
diag(r^2) J H^-1`` of the weighted residuals r (``H = J^T J`` from two Jacobians on independent
streams; Nocedal & Wright 2006, Numerical Optimization, 10.3; White 1980), and the report gives each
parameter's standard error and 95 % interval from it.

The start is the direct method's fit where the direct method applies (it is fast, and close
whenever interreflection is weak), else the spec's values.
"""

import copy
import math
import time

import numpy as np

from ..errors import InputError

__all__ = ["PATHS", "default_spp", "DEFAULT_MAX_DEPTH", "PathFit", "fit_path",
           "render_views", "render_derivatives", "material_pixels"]

#: Paths per view of each render when ``spp`` is not given: spp = PATHS / pixels, within
#: [MIN_SPP, MAX_SPP]. The fit's error from the frozen Monte Carlo noise falls with the paths
#: of a view, not with its spp (a 64 x 48 view of the interreflection scene, four seeds: 1 M
#: paths, up to 0.6-1.9 % off; 3 M, 0.7 %).
PATHS = 1 << 21
MIN_SPP, MAX_SPP = 16, 1024
#: Longest path when not given (the renderer's default, Mitsuba 3's count).
DEFAULT_MAX_DEPTH = 8
#: Gauss-Newton iterations of a solve at most (each costs one render per view).
MAX_ITERATIONS = 30
#: Solves at most, each with the proposal and the weights taken again where the last ended,
#: and the change of x (relative, or absolute below 0.05) below which they stop whatever the
#: standard errors.
ROUNDS = 6
TOLERANCE = 2e-3
#: Renders at the optimum on independent streams (seeds offset by multiples of
#: COVARIANCE_STREAMS), for the covariance: the first gives the second Jacobian of J^T J, and
#: each one's Gauss-Newton step from the optimum a draw of where a fit on its streams would
#: have ended (the spread of the fit's own Monte Carlo error).
STREAM_DRAWS = 4
COVARIANCE_STREAMS = 1 << 20
#: Two-sided 95 % quantile of the standard normal.
Z95 = 1.959963984540054


def default_spp(views):
    """Samples per pixel for ``views`` when not given (:data:`PATHS`)."""
    pixels = max(v.size[0] * v.size[1] for v in views)
    return int(np.clip(math.ceil(PATHS / pixels), MIN_SPP, MAX_SPP))


def scene_with(view, model):
    """A copy of the view's scene with ``model`` on its ``@material`` shapes."""
    sc = copy.copy(view.scene)
    sc.shapes = [copy.copy(s) for s in view.scene.shapes]
    for k in view.material_shapes:
        sc.shapes[k].material = model
    return sc


def material_pixels(view, compiled, shapes):
    """``(yx (n, 2), shape (n,))``: the view's pixels, inside its mask and not saturated, whose
    centre and four corners all see one of ``shapes`` (a set of scene shape indices), the same
    one: pixels a silhouette crosses mix two surfaces and are left out."""
    from ..render.rays import camera_rays, first_hits
    w, h = view.size
    points = [(0.5, 0.5), (0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)]
    allowed = view.mask & ~view.photo.saturated
    ys, xs = np.nonzero(allowed)
    if not len(ys):
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0, dtype=np.int64)
    dirs, origin = camera_rays(view.scene.camera, w, h, points)
    hits = first_hits(compiled, origin, dirs[:, ys, xs].reshape(-1, 3))
    shape = hits.shape.reshape(len(points), len(ys))
    keep = np.all(np.isin(shape, list(shapes)), axis=0) & np.all(shape == shape[0], axis=0)
    return np.stack([ys[keep], xs[keep]], axis=1), shape[0][keep]


def render_views(views, model, yx, spp, max_depth, seed, layers=False):
    """Render every view with ``model`` on its ``@material`` shapes; per view the values at its
    pixels ``yx`` (n, 3), and with ``layers`` also their Monte Carlo variance."""
    from ..render import render
    out = []
    for v, p in zip(views, yx):
        r = render(scene_with(v, model), spp=spp, size=v.size, seed=seed, max_depth=max_depth,
                   layers=layers, progress=False)
        vals = r.image[p[:, 0], p[:, 1]]
        out.append((vals, r.variance[p[:, 0], p[:, 1]]) if layers else vals)
    return out


def render_derivatives(views, proposal, evaluate, slots, yx, spp, max_depth, seed):
    """Render every view with paths drawn as for ``proposal`` on its ``@material`` shapes and f
    evaluated with ``evaluate`` there (:class:`brdf.render.Derivatives`); per view the values
    at its pixels ``yx`` (n, 3), their Monte Carlo variance, and their derivatives (n, 3, K)
    in the packed parameters ``slots`` (K entries)."""
    from ..render import Derivatives, render
    out = []
    for v, p in zip(views, yx):
        r = render(scene_with(v, proposal), spp=spp, size=v.size, seed=seed,
                   max_depth=max_depth, progress=False,
                   derivatives=Derivatives(proposal, slots, evaluate=evaluate))
        ys, xs = p[:, 0], p[:, 1]
        out.append((r.image[ys, xs], r.variance[ys, xs], r.derivatives[ys, xs]))
    return out


class PathFit:
    """The outcome of :func:`fit_path`.

    Attributes
    ----------
    x : ndarray
        The optimum in the problem's coordinates (last: log k when the scale is free).
    model : Model
    scale, scale_sigma : float
        k and its standard error (0 when fixed).
    covariance : ndarray
        Gauss-Newton covariance of x.
    predictions : list of ndarray
        k I at each view's pixels.
    loss : float
        Sum of squared weighted residuals at the optimum.
    renders, iterations, rounds, status, converged, seconds :
        What the fit cost (renders of a view, Gauss-Newton iterations, solves) and how it
        ended.
    """

    def __init__(self, **kw):
        self.__dict__.update(kw)

    def percentiles(self, problem):
        """``{free name: {percentile: value}}`` of the Laplace approximation (normal in x,
        log-normal in the values of log-scaled parameters)."""
        out = {}
        std = np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))
        for i, p in enumerate(problem.free):
            out[p.name] = {f"{q:g}": float(p.from_x(self.x[i] + z * std[i]))
                           for q, z in ((2.5, -Z95), (16, -1.0), (50, 0.0), (84, 1.0),
                                        (97.5, Z95))}
        return out

    def standard_errors(self, problem):
        """``{free name: standard error of the value}`` (delta method for log parameters)."""
        std = np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))
        return {p.name: float(std[i] * (p.from_x(self.x[i]) if p.log else 1.0))
                for i, p in enumerate(problem.free)}


def fit_path(problem, views, yx, values, *, scale=1.0, free_scale=False, noise=None,
             steps=None, spp=None, max_depth=DEFAULT_MAX_DEPTH, seed=0, progress=None):
    """Fit the free parameters of ``problem`` (a :class:`brdf.fitting.problem.Problem`, whose
    model is the start) to the views' pixel ``values`` through renders (module docstring).

    Parameters
    ----------
    problem : Problem
        Its ``x0`` is the start; its bounds bound the fit.
    views : list of View
    yx : list of ndarray (n_v, 2)
        The pixels used in each view.
    values : list of ndarray (n_v, 3)
        The photograph's linear values there.
    scale : float
        The starting (or, without ``free_scale``, fixed) scale k.
    free_scale : bool
    noise : callable, optional
        ``noise(value, step)`` standard deviation of a pixel value (None: unit weights).
    steps : list, optional
        Per view, the code width of each value (integer photographs) or None.
    spp : int, optional
        Samples per pixel (default :func:`default_spp`).
    max_depth, seed : int
    progress : bool, optional

    Returns
    -------
    PathFit
    """
    from scipy.optimize import least_squares
    from ..progress import task
    began = time.perf_counter()
    spp = default_spp(views) if spp is None else spp
    n = len(problem.free)
    steps = steps or [None] * len(views)
    y = np.concatenate([np.asarray(v, float).ravel() for v in values])
    slots = [p.slots for p in problem.free]
    renders = [0]

    def rendered(proposal, z, streams=seed):
        """``(k-free values, variance, d values / dx)`` of every view's pixels, flattened."""
        renders[0] += len(views)
        meter.update(len(views))
        got = render_derivatives(views, proposal, problem.model(z[:n]), slots, yx, spp,
                                 max_depth, streams)
        # d/dx of a log-scaled coordinate is the value times d/d(value)
        chain = np.array([p.from_x(z[i]) if p.log else 1.0 for i, p in enumerate(problem.free)])
        vals = np.concatenate([g[0].ravel() for g in got])
        var = np.concatenate([g[1].ravel() for g in got])
        jac = np.concatenate([g[2].reshape(-1, n) for g in got]) * chain
        return vals, var, jac

    x0 = np.concatenate([problem.x0, [math.log(scale)]]) if free_scale else problem.x0.copy()
    lower = np.concatenate([problem.lower, [-50.0]]) if free_scale else problem.lower
    upper = np.concatenate([problem.upper, [50.0]]) if free_scale else problem.upper
    x0 = np.clip(x0, lower, upper)

    def k_of(z):
        return math.exp(z[n]) if free_scale else scale

    def weights(z, vals, var):
        """The stated noise at the prediction and the render's Monte Carlo variance, in
        quadrature (unit weights when no noise is stated)."""
        if noise is None:
            return np.ones_like(y)
        k = k_of(z)
        pred, a = k * vals, 0
        photo = []
        for v, st in zip(values, steps):
            m = np.asarray(v).size
            photo.append(noise(np.maximum(pred[a:a + m].reshape(-1, 3), 0.0), st).ravel())
            a += m
        sig = np.sqrt(np.concatenate(photo) ** 2 + k * k * var)
        return np.maximum(sig, 1e-12 * max(float(np.abs(y).max()), 1e-300))

    def jacobian_at(z, vals, jac, sigma):
        k = k_of(z)
        J = np.empty((len(y), len(z)))
        J[:, :n] = k * jac / sigma[:, None]
        if free_scale:
            J[:, n] = k * vals / sigma   # d(k I)/d(log k) = k I
        return J

    budget = len(views) * (ROUNDS * (1 + MAX_ITERATIONS) + 1 + STREAM_DRAWS)
    with task(budget, "fit-images: path", "render", progress) as meter:
        z, nfev, rounds = x0, 0, 0
        for rounds in range(1, ROUNDS + 1):
            proposal = problem.model(z[:n])
            cache = {}

            def at(x):
                key = x[:n].tobytes()
                if key not in cache:
                    cache.clear()
                    cache[key] = rendered(proposal, x)
                return cache[key]

            vals0, var0, _ = at(z)
            sigma = weights(z, vals0, var0)

            def residuals(x):
                return (k_of(x) * at(x)[0] - y) / sigma

            def jacobian(x):
                vals, _, jac = at(x)
                return jacobian_at(x, vals, jac, sigma)

            fit = least_squares(residuals, z, jac=jacobian, bounds=(lower, upper),
                                method="trf", x_scale="jac", xtol=1e-6, ftol=1e-10, gtol=1e-10,
                                max_nfev=MAX_ITERATIONS)
            step = np.abs(fit.x - z)
            z, nfev = fit.x, nfev + fit.nfev
            # the standard errors of this solve (Gauss-Newton): a move well within them is
            # the Monte Carlo error of the proposal, which another solve would only reshuffle
            se = np.sqrt(np.clip(np.diag(np.linalg.pinv(fit.jac.T @ fit.jac)), 0.0, None))
            if noise is None:
                se = se * math.sqrt(2.0 * fit.cost / max(len(y) - len(z), 1))
            if (np.max(step / np.maximum(np.abs(z), 0.05)) < TOLERANCE
                    or np.all(step < 0.5 * se)):
                break
        # at the optimum, its own proposal, and renders on independent streams (see
        # STREAM_DRAWS): the first one's Jacobian and the optimum's have independent noise, so
        # that their cross product estimates J^T J without the noise's inflation
        proposal = problem.model(z[:n])
        vals, var, jac = rendered(proposal, z)
        sigma = weights(z, vals, var)
        J = jacobian_at(z, vals, jac, sigma)
        draws = [z]
        for j in range(1, STREAM_DRAWS + 1):
            vals_j, _, jac_j = rendered(proposal, z, seed + j * COVARIANCE_STREAMS)
            J_j = jacobian_at(z, vals_j, jac_j, sigma)
            J2 = J_j if j == 1 else J2
            r_j = (k_of(z) * vals_j - y) / sigma
            draws.append(z - np.linalg.lstsq(J_j, r_j, rcond=None)[0])
    r = (k_of(z) * vals - y) / sigma
    loss = float(r @ r)
    dof = max(len(y) - len(z), 1)
    H = 0.5 * (J.T @ J2 + J2.T @ J)
    if np.any(np.linalg.eigvalsh(H) <= 0.0):
        H = 0.5 * (J.T @ J + J2.T @ J2)   # the noise dominates some direction: bounded below
    try:
        Hi = np.linalg.pinv(H)
    except np.linalg.LinAlgError:
        Hi = np.full((len(z), len(z)), np.inf)
    # the sandwich H^-1 J^T diag(r_i^2 / (1 - h_ii)^2) J H^-1 with leverages h_ii (HC3 of
    # MacKinnon & White 1985, "Some heteroskedasticity-consistent covariance matrix estimators
    # with improved finite sample properties", J. Econometrics 29; White 1980): each pixel's
    # error is what its residual shows, the frozen Monte Carlo noise of the fit's renders
    # included, and that is largest in the highlight that decides ks and alpha. (J^T J)^-1
    # times the mean square residual left them 2-4 standard errors off on the interreflection
    # scene, where this gives 0-1.2 (three seeds)
    lev = np.clip(np.einsum("ij,jk,ik->i", J, Hi, J), 0.0, 0.99)
    cov = Hi @ ((J * (r / (1.0 - lev))[:, None] ** 2).T @ J) @ Hi
    # the fit's own Monte Carlo error, from where fits on other streams would have ended: the
    # residuals show a render's noise per pixel, but not how much of it the fit follows (the
    # same paths give a pixel's value and its derivatives). In the demo's capture at 128 spp
    # the optimum moved 0.14 % (alpha, six streams) against a sandwich error of 0.08 %
    cov = cov + np.cov(np.array(draws).T, ddof=1)
    k = k_of(z)
    sk = k * math.sqrt(max(cov[n, n], 0.0)) if free_scale else 0.0
    pred = k * vals
    if not np.all(np.isfinite(pred)):
        raise InputError("fit-images: path: the render gave non-finite values")
    preds, a = [], 0
    for v in values:
        preds.append(pred[a:a + np.asarray(v).size].reshape(-1, 3))
        a += np.asarray(v).size
    return PathFit(x=z, model=problem.model(z[:n]), scale=k, scale_sigma=sk,
                   covariance=cov[:n, :n], predictions=preds, loss=loss, sigma=sigma,
                   renders=renders[0], iterations=int(nfev), rounds=rounds,
                   status=str(fit.message), converged=bool(fit.status > 0),
                   seconds=time.perf_counter() - began, chi2_per_value=loss / dof, spp=spp)
