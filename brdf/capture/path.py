"""The ``path`` method of :func:`brdf.fit_images`: image-space least squares through the path
tracer.

Each evaluation renders every view with the candidate BRDF on its ``@material`` shapes
(:func:`brdf.render.render`: interreflection, shadows and every light the renderer has) and
compares the render with the photograph on the pixels used. The random streams are the same in
every render (one ``seed``: common random numbers), so the objective is a fixed function of
the parameters whose Monte Carlo error does not change from one evaluation to the next, and
differences of two renders measure the change of the image, not of the noise.

The fit is Gauss-Newton with a trust region (:func:`scipy.optimize.least_squares`, ``trf``,
Branch, Coleman & Li 1999) on the residuals ``(k I(theta) - y) / sigma``: ``k`` is the free
scale (exposure or light power, fitted jointly when asked: the render predicts the reference
pixels of known materials as well as the material's), ``sigma`` the stated photograph noise
(:mod:`brdf.capture.inverse`) and the render's own Monte Carlo error in quadrature. The
Jacobian is central differences of renders with the same streams, a step of
:data:`RELATIVE_STEP` of each coordinate (the log of a roughness). The covariance at the
optimum is the Gauss-Newton (Laplace) one, ``(J^T J)^-1`` of the weighted residuals, J^T J
from two Jacobians on independent streams (times the
residual variance per degree of freedom when no noise is stated; Nocedal & Wright 2006,
Numerical Optimization, 10.3), and the report gives each parameter's standard error and 95 %
interval from it.

The start is the direct method's fit where the direct method applies (it is fast, and close
whenever interreflection is weak), else the spec's values.
"""

import copy
import math
import time

import numpy as np

from ..errors import InputError

__all__ = ["RELATIVE_STEP", "PATHS", "default_spp", "DEFAULT_MAX_DEPTH", "PathFit", "fit_path",
           "render_views", "material_pixels"]

#: Central-difference step of each coordinate of x, relative (at least 0.05 absolute times it).
#: A render with the same streams is piecewise smooth in the parameters: a changed parameter
#: moves some samples across a lobe choice or a Russian-roulette test, and each pixel's
#: difference quotient carries that noise, about 1 / sqrt(spp h) of a jump. It inflates J^T J,
#: which shortens the Gauss-Newton steps and shrinks the covariance; the truncation error of a
#: central difference grows as h^2 instead. The sphere beside a floor under a point light,
#: 64 x 48, 256 spp: at 2 % the fit crept to a stop 1 % short (11 iterations), at 10 % it
#: converged in 4 and half as far off.
RELATIVE_STEP = 0.1
#: Paths per view of each render when ``spp`` is not given: spp = PATHS / pixels, within
#: [MIN_SPP, MAX_SPP]. The fit's error from the frozen Monte Carlo noise falls with the paths
#: of a view, not with its spp (a 64 x 48 view of the interreflection scene, four seeds: 1 M
#: paths, up to 0.6-1.9 % off; 3 M, 0.7 %).
PATHS = 1 << 21
MIN_SPP, MAX_SPP = 16, 1024
#: Longest path when not given (the renderer's default, Mitsuba 3's count).
DEFAULT_MAX_DEPTH = 8
#: Gauss-Newton iterations at most (each costs one render per view for the residuals and
#: two per view and coordinate for the Jacobian).
MAX_ITERATIONS = 30
#: Solves at most with the weights taken again at the last solve's prediction (the noise of a
#: pixel is that of its expected value, which the observed one would bias; iteratively
#: reweighted least squares), and the largest change of x (relative, or absolute below 0.05)
#: that ends them. From the direct start of a noisy photograph with a floor of known albedo
#: beside the sphere, 25-53 % off, the first solve's weights left the albedo 3-7 % off.
WEIGHT_ROUNDS = 4
WEIGHT_TOL = 2e-3
#: Offset of the seed of the second Jacobian at the optimum (the covariance's).
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
    renders, iterations, status, converged, seconds :
        What the fit cost and how it ended.
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
    renders = [0]

    def predict(x, streams=seed):
        renders[0] += len(views)
        meter.update(len(views))
        return np.concatenate([p.ravel() for p in render_views(
            views, problem.model(x), yx, spp, max_depth, streams)])

    x0 = np.concatenate([problem.x0, [math.log(scale)]]) if free_scale else problem.x0.copy()
    lower = np.concatenate([problem.lower, [-50.0]]) if free_scale else problem.lower
    upper = np.concatenate([problem.upper, [50.0]]) if free_scale else problem.upper
    x0 = np.clip(x0, lower, upper)

    def k_of(z):
        return math.exp(z[n]) if free_scale else scale

    budget = len(views) * (WEIGHT_ROUNDS * (1 + MAX_ITERATIONS * (1 + 2 * n)) + 4 * n)
    with task(budget, "fit-images: path", "render", progress) as meter:
        # the weights: stated noise at the prediction and the render's Monte Carlo variance,
        # in quadrature; held fixed during a solve, so that the objective is a fixed function
        # (unit weights when no noise is stated)
        def weights(z):
            if noise is None:
                return np.ones_like(y)
            got = render_views(views, problem.model(z[:n]), yx, spp, max_depth, seed,
                               layers=True)
            renders[0] += len(views)
            meter.update(len(views))
            k = k_of(z)
            photo = np.concatenate([noise(np.maximum(k * vals, 0.0), st).ravel()
                                    for (vals, _), st in zip(got, steps)])
            mc = np.concatenate([(k * k * var).ravel() for _, var in got])
            sig = np.sqrt(photo ** 2 + mc)
            return np.maximum(sig, 1e-12 * max(float(np.abs(y).max()), 1e-300))

        cache = {}

        def rendered(z):
            key = z[:n].tobytes()
            if key not in cache:
                cache.clear()
                cache[key] = predict(z[:n])
            return cache[key]

        def residuals(z):
            return (k_of(z) * rendered(z) - y) / sigma

        def jacobian(z, streams=seed):
            k = k_of(z)
            J = np.empty((len(y), len(z)))
            here = rendered(z)
            for i in range(n):
                h = RELATIVE_STEP * max(abs(z[i]), 0.05)
                up, down = min(z[i] + h, upper[i]), max(z[i] - h, lower[i])
                zu, zd = z[:n].copy(), z[:n].copy()
                zu[i], zd[i] = up, down
                J[:, i] = k * (predict(zu, streams) - predict(zd, streams)) / (
                    (up - down) * sigma)
            if free_scale:
                J[:, n] = k * here / sigma   # d(k I)/d(log k) = k I
            return J

        z, nfev = x0, 0
        for _ in range(WEIGHT_ROUNDS if noise is not None else 1):
            sigma = weights(z)
            fit = least_squares(residuals, z, jac=jacobian, bounds=(lower, upper),
                                method="trf", x_scale="jac", xtol=1e-4, ftol=1e-8, gtol=1e-8,
                                max_nfev=MAX_ITERATIONS)
            moved = np.max(np.abs(fit.x - z) / np.maximum(np.abs(z), 0.05))
            z, nfev = fit.x, nfev + fit.nfev
            if moved < WEIGHT_TOL:
                break
        # two Jacobians on independent streams: their noise is independent, so their cross
        # product estimates J^T J without the noise's inflation (each one's own square adds
        # its noise's variance; on a noisy photograph of the sphere beside the floor, at 256
        # spp, the standard errors grew by 15-25 %)
        J = jacobian(z)
        J2 = jacobian(z, seed + COVARIANCE_STREAMS)
    r = residuals(z)
    loss = float(r @ r)
    dof = max(len(y) - len(z), 1)
    H = 0.5 * (J.T @ J2 + J2.T @ J)
    if np.any(np.linalg.eigvalsh(H) <= 0.0):
        H = 0.5 * (J.T @ J + J2.T @ J2)   # the noise dominates some direction: bounded below
    try:
        cov = np.linalg.pinv(H)
    except np.linalg.LinAlgError:
        cov = np.full((len(z), len(z)), np.inf)
    # no stated noise: the residuals' own scatter; stated noise the fit exceeds (reduced
    # chi-square above 1, e.g. noise in the image the photograph was made from): widened by it
    cov = cov * (loss / dof if noise is None else max(1.0, loss / dof))
    k = k_of(z)
    sk = k * math.sqrt(max(cov[n, n], 0.0)) if free_scale else 0.0
    preds, pred = [], k * rendered(z)
    a = 0
    for v in values:
        preds.append(pred[a:a + np.asarray(v).size].reshape(-1, 3))
        a += np.asarray(v).size
    if not np.all(np.isfinite(pred)):
        raise InputError("fit-images: path: the render gave non-finite values")
    return PathFit(x=z, model=problem.model(z[:n]), scale=k, scale_sigma=sk,
                   covariance=cov[:n, :n], predictions=preds, loss=loss, sigma=sigma,
                   renders=renders[0], iterations=int(nfev), status=str(fit.message),
                   converged=bool(fit.status > 0), seconds=time.perf_counter() - began,
                   chi2_per_value=loss / dof, spp=spp)
