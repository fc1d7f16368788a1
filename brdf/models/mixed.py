"""Sums whose lobes include numpy-written families (:class:`~brdf.models.custom.CustomModel`).

Such a sum is evaluated lobe by lobe: its built-in lobes together by the compiled kernels (one
sub-sum, so Lambertian lobes still fold into the others' pass), its custom lobes by their numpy
formulas. Sampling follows the kernels' mixture rule (``_kernels.mixture_draw``) exactly:

    at wi, lobe l is picked with probability hint_l(wi) / sum_j hint_j(wi) (uniformly when every
    hint is 0), where a hint is a cheap albedo estimate (the kernels' ``lobe_hint`` for built-in
    lobes, :meth:`CustomModel.hint` for custom ones) clamped at 0; u1 picks the lobe and is
    reused rescaled; the mixture's density is the hint-weighted sum of the continuous lobes'
    densities, and a delta lobe's weight is its reflectance over its probability.

Hints change the variance of the estimates, never their expected values.
"""

import numpy as np

from ..geometry import direction_array, flat_pairs
from .custom import CustomModel

__all__ = ["eval", "pdf", "sample_weighted", "albedo", "selection"]


def _parts(model):
    """``(built-in sub-model or None, [custom lobes])`` of a model with a custom lobe, kept on
    the model (models do not change; ``replace`` makes new ones)."""
    cached = model.__dict__.get("_mixed_parts")
    if cached is None:
        cached = model.__dict__["_mixed_parts"] = _split(model)
    return cached


def _split(model):
    builtin = [lobe for lobe in model.lobes if lobe.kind >= 0]
    custom = [lobe for lobe in model.lobes if lobe.kind < 0]
    for lobe in custom:
        if not isinstance(lobe, CustomModel):
            raise TypeError(f"{lobe.name}: a lobe without a kernel must subclass "
                            "brdf.CustomModel")
    if not builtin:
        return None, custom
    from .base import Sum
    return (builtin[0] if len(builtin) == 1 else Sum(builtin)), custom


def _add(out, values):
    out += values  # (n, 1) lobes broadcast over a sum's channels


def eval(model, wi, wo):
    """f_r of the sum, ``(..., C)``: the built-in lobes through their kernels, plus the rest."""
    wi, wo, shape = flat_pairs(wi, wo)
    out = np.zeros((len(wi), model.channels))
    builtin, custom = _parts(model)
    if builtin is not None:
        _add(out, builtin.eval(wi, wo))
    for lobe in custom:
        _add(out, lobe._eval_flat(wi, wo))
    return out.reshape(shape + (model.channels,))


def _hints(lobe, wi):
    """A lobe's hint at each row of ``wi`` ``(n, 3)``, computed once per distinct direction (a
    sampler's callers mostly hold one wi)."""
    unique, inverse = np.unique(wi, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    if isinstance(lobe, CustomModel):
        h = np.asarray(lobe.hint(unique), dtype=float).reshape(-1)
    else:
        from ._kernels import lobe_hint
        c = lobe.compile()
        q = np.ascontiguousarray(c.params)
        h = np.array([lobe_hint(int(c.kinds[0]), q, c.nch, float(x), float(y), float(z))
                      for x, y, z in unique])
    return h[inverse]


def selection(model, wi):
    """Probability ``(L, n)`` of picking each lobe at each row of ``wi`` (the module's rule)."""
    h = np.maximum(0.0, np.array([_hints(lobe, wi) for lobe in model.lobes]))
    total = h.sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(total > 0.0, h / total, 1.0 / len(h))


def pdf(model, wi, wo):
    """Density of the mixture's continuous part, ``(...)``."""
    wi, wo, shape = flat_pairs(wi, wo)
    return _pdf(model, wi, wo, selection(model, wi) if len(model.lobes) > 1 else None) \
        .reshape(shape)


def _pdf(model, wi, wo, picks):
    if picks is None:
        return np.asarray(model.lobes[0].pdf(wi, wo), dtype=float)
    out = np.zeros(len(wi))
    for lobe, w in zip(model.lobes, picks):
        if not lobe.delta:
            out += np.where(w > 0.0, w * lobe.pdf(wi, wo), 0.0)
    return out


def sample_weighted(model, wi, u):
    """``(wo (n, 3), pdf (n,), weight (n, C))`` for flat ``wi`` and ``u`` (the module's rule)."""
    n, nch = len(wi), model.channels
    lobes = model.lobes
    if len(lobes) == 1:
        wo, p, w = lobes[0].sample_weighted(wi, u)
        return wo, p, np.broadcast_to(w, (n, nch)).copy()
    picks = selection(model, wi)
    cum = np.cumsum(picks, axis=0)
    u1 = u[:, 0]
    chosen = np.where((u1[None, :] < cum).any(axis=0), np.argmax(u1[None, :] < cum, axis=0),
                      len(lobes) - 1)
    cols = np.arange(n)
    w = picks[chosen, cols]
    lo = cum[chosen, cols] - w
    with np.errstate(divide="ignore", invalid="ignore"):
        rescaled = np.where(w > 0.0, np.clip((u1 - lo) / w, 0.0, 0.9999999999999999), u1)
    wo = np.zeros((n, 3))
    wo[:, 2] = 1.0
    p = np.zeros(n)
    weight = np.zeros((n, nch))
    continuous = np.zeros(n, dtype=bool)
    for l, lobe in enumerate(lobes):
        idx = np.flatnonzero(chosen == l)
        if not len(idx):
            continue
        lwo, lp, lw = lobe.sample_weighted(wi[idx], np.stack([rescaled[idx], u[idx, 1]], -1))
        wo[idx] = lwo
        ok = (lp > 0.0) & (w[idx] > 0.0)
        if lobe.delta:
            p[idx] = np.where(ok, lp, 0.0)
            weight[idx] = np.where(ok[:, None], lw / np.where(ok, w[idx], 1.0)[:, None], 0.0)
        else:
            continuous[idx[ok]] = True
    k = np.flatnonzero(continuous)
    if len(k):
        p[k] = _pdf(model, wi[k], wo[k], picks[:, k])
        f = eval(model, wi[k], wo[k])
        with np.errstate(divide="ignore", invalid="ignore"):
            weight[k] = np.where((p[k] > 0.0)[:, None], f * (wo[k, 2] / p[k])[:, None], 0.0)
    return wo, p, weight


def albedo(model, wi, tol, max_panels):
    """``(albedo, error)`` ``(..., C)``: the lobes' albedos and error estimates add up."""
    wi = direction_array(wi, "wi")
    shape = wi.shape[:-1] + (model.channels,)
    out, err = np.zeros(shape), np.zeros(shape)
    builtin, custom = _parts(model)
    for part in ([builtin] if builtin is not None else []) + custom:
        a, e = part.albedo(wi, tol=tol, return_error=True, max_panels=max_panels)
        out += a
        err += e
    return out, err
