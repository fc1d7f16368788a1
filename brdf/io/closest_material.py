"""The closest material a format can hold, for models it has no exact counterpart for.

Phong, Ward, Lafortune, Ashikhmin-Shirley and Oren-Nayar lobes have no counterpart among
Mitsuba 3's BSDFs or glTF's metallic-roughness material, and a bright ``lambert + ggx`` fit
can need a glTF base colour above 1. :mod:`brdf.io.export` then writes the closest material of
the format's family: the model is measured at seeded random direction pairs (cosine-weighted,
:func:`brdf.measure`) and the family is fitted with the library's default fit (the
``cosine-l2`` metric of Ngan et al. 2005, multi-start, cutoff 80 degrees).

How close it is, :func:`relative_rms`: the root-mean-square difference of f over pairs of
directions up to 80 degrees weighted by projected solid angle (cos_i cos_o dwi dwo, the
measure under which reflected energy adds up), relative to the RMS of the model itself. It
complements :func:`brdf.io.export.relative_deviation`, the largest pointwise ratio, which a
fitted approximation can exceed by a lot in a dim tail that no picture shows.
"""

import math

import numpy as np

__all__ = ["relative_rms", "weighted_pairs", "fit_lambert_ggx", "smooth_part", "MAX_ERROR",
           "RMS_PAIRS", "SEED"]

#: Largest :func:`relative_rms` of a closest material that :func:`brdf.export` still writes;
#: beyond it the model has no reasonable counterpart in the format and is refused.
MAX_ERROR = 0.75
#: Seed of the measurement and of the fit (same model, same file).
SEED = 0
#: Pairs of :func:`relative_rms`.
RMS_PAIRS = 200_000
#: Polar cutoff of both measures, as the fits' default (Ngan et al. 2005 leave out > 80 deg).
CUTOFF_COS = math.cos(math.radians(80.0))


def smooth_part(model):
    """``(smooth, deltas)``: the model without its delta lobes (None if nothing is left) and
    the list of those lobes."""
    from ..models.base import Sum
    deltas = [lobe for lobe in model.lobes if lobe.delta]
    rest = [lobe for lobe in model.lobes if not lobe.delta]
    smooth = None if not rest else rest[0] if len(rest) == 1 else Sum(rest)
    return smooth, deltas


def _cosine_directions(u):
    """Cosine-weighted directions from uniform numbers ``u`` (n, 2) (Malley's method)."""
    r, phi = np.sqrt(u[:, 0]), 2.0 * math.pi * u[:, 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - u[:, 0])], axis=1)


def weighted_pairs(model, pairs=RMS_PAIRS, seed=SEED):
    """Direction pairs up to 80 degrees and their weights, ``(wi, wo, weight)``, such that
    ``sum(weight * h(wi, wo))`` is proportional to the integral of h cos_i cos_o dwi dwo.

    wi is cosine-distributed; wo is drawn half from cosine and half from the smooth part of
    ``model``'s own sampler, and weighted by cos_o over the mixture density (one-sample
    multiple importance sampling with the balance heuristic, Veach 1997, eq. 9.13), so that
    sharp lobes are resolved.
    """
    smooth, _ = smooth_part(model)
    rng = np.random.default_rng(seed)
    wi = _cosine_directions(rng.random((pairs, 2)))
    wo = _cosine_directions(rng.random((pairs, 2)))
    if smooth is not None:
        half = pairs // 2
        wo[half:], _ = smooth.sample(wi[half:], rng.random((pairs - half, 2)))
    ok = (wi[:, 2] >= CUTOFF_COS) & (wo[:, 2] >= CUTOFF_COS)
    wi, wo = wi[ok], wo[ok]
    density = wo[:, 2] / math.pi
    if smooth is not None:
        density = 0.5 * density + 0.5 * smooth.pdf(wi, wo)
    return wi, wo, wo[:, 2] / density


def relative_rms(model, other, pairs=RMS_PAIRS, seed=SEED + 1):
    """RMS of ``other(wi, wo) - model.eval(wi, wo)`` relative to the RMS of the model, over
    direction pairs up to 80 degrees weighted by projected solid angle and summed over
    channels (a seeded Monte Carlo estimate on :func:`weighted_pairs`; delta lobes, whose f
    is 0, do not count). The default seed differs from the fits' so that the figure is not
    measured on the pairs a fit was made on."""
    wi, wo, weight = weighted_pairs(model, pairs, seed)
    f, g = np.broadcast_arrays(np.asarray(model.eval(wi, wo), float),
                               np.asarray(other(wi, wo), float))
    total = float(np.sum(weight[:, None] * f * f))
    if total <= 0.0:
        return 0.0 if not np.any(g) else math.inf
    return math.sqrt(float(np.sum(weight[:, None] * (g - f) ** 2)) / total)


def _scales(basis, y, weight):
    """Per channel, the non-negative (a, k) minimising sum w (a b0 + k b1 - y)^2, and the
    summed residual: 2 x 2 normal equations, or one basis function when a scale would be
    negative (the non-negative least squares solution has one of the two at 0)."""
    b = basis * np.sqrt(weight)[:, None]
    t = y * np.sqrt(weight)[:, None]
    gram, rhs = b.T @ b, b.T @ t  # (2, 2), (2, C)
    scales = np.zeros((2, y.shape[1]))
    for c in range(y.shape[1]):
        try:
            x = np.linalg.solve(gram, rhs[:, c])
        except np.linalg.LinAlgError:
            x = np.array([-1.0, -1.0])
        if np.any(x < 0.0):
            single = [np.array([max(rhs[0, c] / gram[0, 0], 0.0), 0.0]),
                      np.array([0.0, max(rhs[1, c] / gram[1, 1], 0.0)])]
            x = min(single, key=lambda s: float(np.sum((b @ s - t[:, c]) ** 2)))
        scales[:, c] = x
    return scales, float(np.sum((b @ scales - t) ** 2))


def fit_lambert_ggx(model, masking="separable", pairs=RMS_PAIRS, seed=SEED):
    """The ``lambert + ggx`` (Fresnel none, ``masking`` as given; anisotropic when ``model``
    is) closest to ``model``'s smooth part in the weighted L2 norm of :func:`relative_rms`.

    Given the roughness, f = albedo / pi + ks g(alpha) is linear in the scales, which are
    solved exactly (variable projection, Golub & Pereyra 1973); the roughness is searched on
    a log grid and refined by bounded Brent (Nelder-Mead for alpha and alpha_y).
    """
    from scipy.optimize import minimize, minimize_scalar
    from ..models.base import Sum
    from ..models.lambert import Lambert
    from ..models.microfacet import GGXModel as GGX
    smooth, _ = smooth_part(model)
    wi, wo, weight = weighted_pairs(model, pairs, seed)
    y = np.broadcast_to(np.asarray(smooth.eval(wi, wo), float), (len(wi), model.channels))
    anisotropic = model.is_anisotropic

    def lobe(log_a):
        ax, ay = np.exp(log_a[0]), np.exp(log_a[-1])
        extra = {"alpha_y": ay} if anisotropic else {}
        return GGX(ks=1.0, alpha=ax, masking=masking, fresnel="none", **extra)

    def solve(log_a):
        g = lobe(log_a).eval(wi, wo)[:, 0]
        return _scales(np.stack([np.full(len(wi), 1.0 / math.pi), g], axis=1), y, weight)

    grid = np.log(np.geomspace(2e-3, 2.0, 31))
    if anisotropic:
        starts = [(a, b) for a in grid[::3] for b in grid[::3]]
        best = min(starts, key=lambda s: solve(np.array(s))[1])
        log_a = minimize(lambda s: solve(s)[1], np.array(best), method="Nelder-Mead",
                         options={"xatol": 1e-4, "fatol": 0.0, "maxiter": 400}).x
    else:
        k = int(np.argmin([solve(np.array([a]))[1] for a in grid]))
        low, high = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
        log_a = np.array([minimize_scalar(lambda a: solve(np.array([a]))[1],
                                          bounds=(low, high), method="bounded",
                                          options={"xatol": 1e-5}).x])
    log_a = np.clip(log_a, math.log(1e-4), math.log(4.0))  # GGX's declared alpha bounds
    scales, _ = solve(log_a)
    one = model.channels == 1
    albedo, ks = (scales[0, 0], scales[1, 0]) if one else (scales[0], scales[1])
    return Sum([Lambert(albedo=albedo), lobe(log_a).replace(ks=ks)])
