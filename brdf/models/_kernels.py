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

from .._jit import inline_kernel, kernel, parallel_kernel
from . import _kinds as K
from . import lambert, microfacet, mirror
from . import blinn_phong, phong
from . import ward
from . import ashikhmin_shirley, lafortune


@inline_kernel
def lobe_eval(kind, q, nch, ix, iy, iz, ox, oy, oz, out, k):
    if kind == K.LAMBERT:
        lambert.eval_(q, nch, ix, iy, iz, ox, oy, oz, out, k)
    elif kind == K.GGX:
        microfacet.eval_(microfacet.GGX, q, nch, ix, iy, iz, ox, oy, oz, out, k)
    elif kind == K.BECKMANN:
        microfacet.eval_(microfacet.BECKMANN, q, nch, ix, iy, iz, ox, oy, oz, out, k)
    elif kind == K.PHONG:
        phong.eval_(phong.ORIGINAL, q, nch, ix, iy, iz, ox, oy, oz, out, k)
    elif kind == K.MODIFIED_PHONG:
        phong.eval_(phong.MODIFIED, q, nch, ix, iy, iz, ox, oy, oz, out, k)
    elif kind == K.BLINN_PHONG:
        blinn_phong.eval_(q, nch, ix, iy, iz, ox, oy, oz, out, k)
    elif kind == K.WARD:
        ward.eval_(q, nch, ix, iy, iz, ox, oy, oz, out, k)
    elif kind == K.LAFORTUNE:
        lafortune.eval_(q, nch, ix, iy, iz, ox, oy, oz, out, k)
    elif kind == K.ASHIKHMIN_SHIRLEY:
        ashikhmin_shirley.eval_(q, nch, ix, iy, iz, ox, oy, oz, out, k)


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
    if kind == K.PHONG or kind == K.MODIFIED_PHONG:
        return phong.sample_(q, nch, ix, iy, iz, u1, u2)
    if kind == K.BLINN_PHONG:
        return blinn_phong.sample_(q, nch, ix, iy, iz, u1, u2)
    if kind == K.WARD:
        return ward.sample_(q, nch, ix, iy, iz, u1, u2)
    if kind == K.LAFORTUNE:
        return lafortune.sample_(q, nch, ix, iy, iz, u1, u2)
    if kind == K.ASHIKHMIN_SHIRLEY:
        return ashikhmin_shirley.sample_(q, nch, ix, iy, iz, u1, u2)
    return 0.0, 0.0, 1.0, 0.0


@kernel
def lobe_pdf(kind, q, nch, ix, iy, iz, ox, oy, oz):
    if kind == K.LAMBERT:
        return lambert.pdf_(q, nch, ix, iy, iz, ox, oy, oz)
    if kind == K.GGX:
        return microfacet.pdf_(microfacet.GGX, q, nch, ix, iy, iz, ox, oy, oz)
    if kind == K.BECKMANN:
        return microfacet.pdf_(microfacet.BECKMANN, q, nch, ix, iy, iz, ox, oy, oz)
    if kind == K.PHONG or kind == K.MODIFIED_PHONG:
        return phong.pdf_(q, nch, ix, iy, iz, ox, oy, oz)
    if kind == K.BLINN_PHONG:
        return blinn_phong.pdf_(q, nch, ix, iy, iz, ox, oy, oz)
    if kind == K.WARD:
        return ward.pdf_(q, nch, ix, iy, iz, ox, oy, oz)
    if kind == K.LAFORTUNE:
        return lafortune.pdf_(q, nch, ix, iy, iz, ox, oy, oz)
    if kind == K.ASHIKHMIN_SHIRLEY:
        return ashikhmin_shirley.pdf_(q, nch, ix, iy, iz, ox, oy, oz)
    return 0.0


@kernel
def lobe_hint(kind, q, nch, ix, iy, iz):
    if kind == K.LAMBERT:
        return lambert.hint_(q, nch, ix, iy, iz)
    if kind == K.MIRROR:
        return mirror.hint_(q, nch, ix, iy, iz)
    if kind == K.GGX or kind == K.BECKMANN:
        return microfacet.hint_(q, nch, ix, iy, iz)
    if kind == K.PHONG:
        return phong.hint_(phong.ORIGINAL, q, nch, ix, iy, iz)
    if kind == K.MODIFIED_PHONG:
        return phong.hint_(phong.MODIFIED, q, nch, ix, iy, iz)
    if kind == K.BLINN_PHONG:
        return blinn_phong.hint_(q, nch, ix, iy, iz)
    if kind == K.WARD:
        return ward.hint_(q, nch, ix, iy, iz)
    if kind == K.LAFORTUNE:
        return lafortune.hint_(q, nch, ix, iy, iz)
    if kind == K.ASHIKHMIN_SHIRLEY:
        return ashikhmin_shirley.hint_(q, nch, ix, iy, iz)
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


HORIZON_MARGIN = 1e-9

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
    """Add f(wi, wo) to ``out``: one parallel pass per lobe, so that each pass is a loop over a
    single formula the compiler can vectorise."""
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


@kernel
def _smoothstep(t):
    """u = 3t^2 - 2t^3 and du/dt: samplers often have sqrt-like behaviour at the edges of their
    square (e.g. theta_h ~ sqrt(1 - u)); this change of variables makes it smooth there and
    spreads the thin edge strips where a grazing lobe meets the horizon over more nodes."""
    return t * t * (3.0 - 2.0 * t), 6.0 * t * (1.0 - t)


@kernel
def _panel(kind, q, nch, ix, iy, iz, x0, y0, h, xs, ws, f, acc):
    """Tensor Gauss rule (xs, ws on [0, 1]) of f cos / pdf over one square panel into ``acc``.

    Returns the number of nodes mapped above and below the horizon and the largest integrand
    value seen, from which the caller tells a panel that the horizon cuts through. (Samplers map
    the square's edges onto the horizon itself, so "below" needs a margin.)
    """
    for c in range(nch):
        acc[c] = 0.0
    valid = 0
    below = 0
    gmax = 0.0
    for a in range(xs.shape[0]):
        u1, j1 = _smoothstep(x0 + h * xs[a])
        for b in range(xs.shape[0]):
            u2, j2 = _smoothstep(y0 + h * xs[b])
            ox, oy, oz, pdf = lobe_sample(kind, q, nch, ix, iy, iz, u1, u2)
            below += oz < -HORIZON_MARGIN
            if pdf > 0.0 and oz > 0.0:
                valid += 1
                for c in range(nch):
                    f[0, c] = 0.0
                lobe_eval(kind, q, nch, ix, iy, iz, ox, oy, oz, f, 0)
                s = oz / pdf * j1 * j2
                for c in range(nch):
                    gmax = max(gmax, abs(f[0, c] * s))
                    acc[c] += f[0, c] * s * ws[a] * ws[b] * h * h
    return valid, below, gmax


@kernel
def _estimate(kind, q, nch, ix, iy, iz, x0, y0, h, rules, f, val, lo, e):
    """High-order value of a panel into ``val``, its per-channel error estimate into ``e``.

    The estimate is the difference to the embedded low-order rule; where the nodes and the
    panel's corners disagree on validity the lobe is cut by the horizon inside the panel, the
    integrand jumps, and the estimate becomes at least a tenth of the panel's area times the
    largest integrand value (a jump costs at most the full product), so such panels are split.
    """
    xs_hi, ws_hi, xs_lo, ws_lo = rules
    v1, n1, g1 = _panel(kind, q, nch, ix, iy, iz, x0, y0, h, xs_hi, ws_hi, f, val)
    v2, n2, g2 = _panel(kind, q, nch, ix, iy, iz, x0, y0, h, xs_lo, ws_lo, f, lo)
    valid = v1 + v2
    invalid = n1 + n2
    eps = 1e-9 * h
    for corner in range(4):
        u1, _ = _smoothstep(x0 + eps + (h - 2.0 * eps) * (corner % 2))
        u2, _ = _smoothstep(y0 + eps + (h - 2.0 * eps) * (corner // 2))
        _, _, oz, pdf = lobe_sample(kind, q, nch, ix, iy, iz, u1, u2)
        if pdf > 0.0 and oz > 0.0:
            valid += 1
        invalid += oz < -HORIZON_MARGIN
    jump = 0.1 * h * h * max(g1, g2) if (valid > 0 and invalid > 0) else 0.0
    worst = 0.0
    for c in range(nch):
        e[c] = max(abs(val[c] - lo[c]), jump)
        worst = max(worst, e[c])
    return worst


@kernel
def _lobe_albedo(kind, q, nch, ix, iy, iz, rules, tol, capacity, out, err):
    """Adaptive cubature of one lobe's albedo over its sampling square.

    Panels carry a high-order and an embedded low-order Gauss-Legendre estimate; the panel with
    the largest error estimate (see ``_estimate``) is split in four until the summed estimates
    fall below ``tol`` times max(1, albedo) or ``capacity`` panels are used. A lobe cut by the
    horizon (grazing wi) makes the integrand jump along a curve in the square: refinement
    follows that curve.
    """
    geo = np.empty((capacity, 3))
    val = np.empty((capacity, nch))
    perr = np.empty(capacity)
    pe = np.empty((capacity, nch))
    f = np.zeros((1, nch))
    lo = np.empty(nch)
    side = 4
    n = side * side
    for j in range(n):
        geo[j, 0] = (j // side) / side
        geo[j, 1] = (j % side) / side
        geo[j, 2] = 1.0 / side
        perr[j] = _estimate(kind, q, nch, ix, iy, iz, geo[j, 0], geo[j, 1], geo[j, 2], rules,
                            f, val[j], lo, pe[j])
    while n + 3 <= capacity:
        total = 0.0
        worst = 0
        for j in range(n):
            total += perr[j]
            if perr[j] > perr[worst]:
                worst = j
        peak = 0.0
        for c in range(nch):
            s = 0.0
            for j in range(n):
                s += val[j, c]
            peak = max(peak, abs(s))
        if total <= tol * max(1.0, peak):
            break
        x0, y0, h = geo[worst, 0], geo[worst, 1], 0.5 * geo[worst, 2]
        for child in range(4):
            j = worst if child == 0 else n + child - 1
            geo[j, 0] = x0 + h * (child % 2)
            geo[j, 1] = y0 + h * (child // 2)
            geo[j, 2] = h
            perr[j] = _estimate(kind, q, nch, ix, iy, iz, geo[j, 0], geo[j, 1], h, rules,
                                f, val[j], lo, pe[j])
        n += 3
    for j in range(n):
        for c in range(nch):
            out[c] += val[j, c]
            err[c] += pe[j, c]


@parallel_kernel
def albedo_array(kinds, offs, p, nch, wi, rules, tol, capacity, out, err):
    """Directional albedo per incident direction: delta lobes exactly, others adaptively."""
    for k in prange(wi.shape[0]):
        ix, iy, iz = wi[k, 0], wi[k, 1], wi[k, 2]
        for l in range(kinds.shape[0]):
            kind = kinds[l]
            q = p[offs[l]:offs[l + 1]]
            if is_delta(kind):
                for c in range(nch):
                    out[k, c] += delta_reflectance(kind, q, nch, c, iz)
            elif iz > 0.0:
                _lobe_albedo(kind, q, nch, ix, iy, iz, rules, tol, capacity, out[k], err[k])
