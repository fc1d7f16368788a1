"""Compiled evaluation of any model: lobe dispatch and the array drivers.

A model reaches the kernels as ``(kinds, offsets, params, nch)`` (see ``Model.compile``): lobe
``l`` has family ``kinds[l]`` and reads its packed parameters ``params[offsets[l]:offsets[l+1]]``.
Every family module provides scalar kernels with these signatures (wi, wo in the local frame):

- ``eval_(q, nch, ix, iy, iz, ox, oy, oz, out, k)``: add f(wi, wo) to ``out[k, :nch]``;
- ``sample_(q, nch, ix, iy, iz, u1, u2) -> (ox, oy, oz, pdf)``: pdf 0 marks an invalid sample;
- ``pdf_(q, nch, ix, iy, iz, ox, oy, oz) -> pdf`` (solid angle, 0 below the horizon);
- ``hint_(q, nch, ix, iy, iz) -> float``: a cheap estimate of the albedo (channel mean), used only
  to choose lobes when sampling a sum, so it changes variance, never the expected value.

The same scalar functions serve checks, fitting, plots and the renderer: there is no second copy
of any formula.
"""

import numpy as np
from numba import prange

from .._jit import kernel, parallel_kernel
from . import _kinds as K
from . import lambert, microfacet, mirror


@kernel
def lobe_eval(kind, q, nch, ix, iy, iz, ox, oy, oz, out, k):
    if kind == K.LAMBERT:
        lambert.eval_(q, nch, ix, iy, iz, ox, oy, oz, out, k)
    elif kind == K.GGX:
        microfacet.eval_(microfacet.GGX, q, nch, ix, iy, iz, ox, oy, oz, out, k)
    elif kind == K.BECKMANN:
        microfacet.eval_(microfacet.BECKMANN, q, nch, ix, iy, iz, ox, oy, oz, out, k)


@kernel
def lobe_sample(kind, q, nch, ix, iy, iz, u1, u2):
    if kind == K.LAMBERT:
        return lambert.sample_(q, nch, ix, iy, iz, u1, u2)
    if kind == K.MIRROR:
        return mirror.sample_(q, nch, ix, iy, iz, u1, u2)
    if kind == K.GGX:
        return microfacet.sample_(microfacet.GGX, q, nch, ix, iy, iz, u1, u2)
    if kind == K.BECKMANN:
        return microfacet.sample_(microfacet.BECKMANN, q, nch, ix, iy, iz, u1, u2)
    return 0.0, 0.0, 1.0, 0.0


@kernel
def lobe_pdf(kind, q, nch, ix, iy, iz, ox, oy, oz):
    if kind == K.LAMBERT:
        return lambert.pdf_(q, nch, ix, iy, iz, ox, oy, oz)
    if kind == K.GGX:
        return microfacet.pdf_(microfacet.GGX, q, nch, ix, iy, iz, ox, oy, oz)
    if kind == K.BECKMANN:
        return microfacet.pdf_(microfacet.BECKMANN, q, nch, ix, iy, iz, ox, oy, oz)
    return 0.0


@kernel
def lobe_hint(kind, q, nch, ix, iy, iz):
    if kind == K.LAMBERT:
        return lambert.hint_(q, nch, ix, iy, iz)
    if kind == K.MIRROR:
        return mirror.hint_(q, nch, ix, iy, iz)
    if kind == K.GGX or kind == K.BECKMANN:
        return microfacet.hint_(q, nch, ix, iy, iz)
    return 0.0


@kernel
def is_delta(kind):
    return kind == K.MIRROR


@kernel
def delta_reflectance(kind, q, nch, ch, iz):
    """Reflectance of a delta lobe in channel ``ch`` (its albedo and its sampling weight)."""
    if kind == K.MIRROR:
        return mirror.reflectance_(q, nch, ch, iz)
    return 0.0


# --- mixtures --------------------------------------------------------------------------------

@kernel
def _selection(kinds, offs, p, nch, ix, iy, iz, l):
    """Probability of picking lobe ``l`` at wi: its hint over the sum (uniform if all are 0)."""
    total = 0.0
    mine = 0.0
    for j in range(kinds.shape[0]):
        h = max(0.0, lobe_hint(kinds[j], p[offs[j]:offs[j + 1]], nch, ix, iy, iz))
        total += h
        if j == l:
            mine = h
    if total <= 0.0:
        return 1.0 / kinds.shape[0]
    return mine / total


@kernel
def material_eval(kinds, offs, p, nch, ix, iy, iz, ox, oy, oz, out, k):
    for l in range(kinds.shape[0]):
        lobe_eval(kinds[l], p[offs[l]:offs[l + 1]], nch, ix, iy, iz, ox, oy, oz, out, k)


@kernel
def material_pdf(kinds, offs, p, nch, ix, iy, iz, ox, oy, oz):
    """Density of the continuous part of a mixture (delta lobes have none)."""
    if kinds.shape[0] == 1:
        return lobe_pdf(kinds[0], p, nch, ix, iy, iz, ox, oy, oz)
    pdf = 0.0
    for l in range(kinds.shape[0]):
        if not is_delta(kinds[l]):
            w = _selection(kinds, offs, p, nch, ix, iy, iz, l)
            if w > 0.0:
                pdf += w * lobe_pdf(kinds[l], p[offs[l]:offs[l + 1]], nch, ix, iy, iz, ox, oy, oz)
    return pdf


@kernel
def material_sample(kinds, offs, p, nch, ix, iy, iz, u1, u2, weight, k):
    """Pick a lobe with ``u1`` (then reuse ``u1`` rescaled), sample it with ``(u1', u2)``.

    Writes f cos / pdf into ``weight[k]`` and returns ``(ox, oy, oz, pdf)``; for a delta lobe
    ``pdf`` is inf and the weight is its reflectance over the probability of picking it.
    """
    nl = kinds.shape[0]
    chosen = nl - 1
    w = 1.0
    lo = 0.0
    for l in range(nl):
        w = _selection(kinds, offs, p, nch, ix, iy, iz, l)
        if u1 < lo + w or l == nl - 1:
            chosen = l
            break
        lo += w
    u1 = min(max((u1 - lo) / w, 0.0), 0.9999999999999999) if w > 0.0 else u1
    kind = kinds[chosen]
    q = p[offs[chosen]:offs[chosen + 1]]
    ox, oy, oz, pdf = lobe_sample(kind, q, nch, ix, iy, iz, u1, u2)
    for c in range(nch):
        weight[k, c] = 0.0
    if pdf == 0.0 or w <= 0.0:
        return ox, oy, oz, 0.0
    if is_delta(kind):
        for c in range(nch):
            weight[k, c] = delta_reflectance(kind, q, nch, c, iz) / w
        return ox, oy, oz, pdf
    if nl > 1:
        pdf = material_pdf(kinds, offs, p, nch, ix, iy, iz, ox, oy, oz)
    material_eval(kinds, offs, p, nch, ix, iy, iz, ox, oy, oz, weight, k)
    for c in range(nch):
        weight[k, c] *= oz / pdf
    return ox, oy, oz, pdf


# --- array drivers ---------------------------------------------------------------------------

@parallel_kernel
def eval_array(kinds, offs, p, nch, wi, wo, out):
    n = wi.shape[0]
    for l in range(kinds.shape[0]):
        q = p[offs[l]:offs[l + 1]]
        kind = kinds[l]
        for k in prange(n):
            lobe_eval(kind, q, nch, wi[k, 0], wi[k, 1], wi[k, 2], wo[k, 0], wo[k, 1], wo[k, 2],
                      out, k)


@parallel_kernel
def pdf_array(kinds, offs, p, nch, wi, wo, out):
    for k in prange(wi.shape[0]):
        out[k] = material_pdf(kinds, offs, p, nch, wi[k, 0], wi[k, 1], wi[k, 2],
                              wo[k, 0], wo[k, 1], wo[k, 2])


@parallel_kernel
def sample_array(kinds, offs, p, nch, wi, u, wo, pdf, weight):
    for k in prange(wi.shape[0]):
        ox, oy, oz, pk = material_sample(kinds, offs, p, nch, wi[k, 0], wi[k, 1], wi[k, 2],
                                         u[k, 0], u[k, 1], weight, k)
        wo[k, 0] = ox
        wo[k, 1] = oy
        wo[k, 2] = oz
        pdf[k] = pk


@parallel_kernel
def albedo_array(kinds, offs, p, nch, wi, nodes, weights, out):
    """Sum over lobes of the integral of f cos / pdf over each lobe's own sampling square."""
    for k in prange(wi.shape[0]):
        ix, iy, iz = wi[k, 0], wi[k, 1], wi[k, 2]
        f = np.zeros((1, nch))
        for l in range(kinds.shape[0]):
            kind = kinds[l]
            q = p[offs[l]:offs[l + 1]]
            if is_delta(kind):
                for c in range(nch):
                    out[k, c] += delta_reflectance(kind, q, nch, c, iz)
                continue
            for j in range(nodes.shape[0]):
                ox, oy, oz, pdf = lobe_sample(kind, q, nch, ix, iy, iz, nodes[j, 0], nodes[j, 1])
                if pdf > 0.0 and oz > 0.0:
                    for c in range(nch):
                        f[0, c] = 0.0
                    lobe_eval(kind, q, nch, ix, iy, iz, ox, oy, oz, f, 0)
                    s = weights[j] * oz / pdf
                    for c in range(nch):
                        out[k, c] += f[0, c] * s
