"""Phong lobes: a cos^n(alpha) lobe about the mirror direction of wi.

Two forms share one kernel, told apart by a flag:

- ``phong``, Phong's 1975 specular term written as a BRDF: the shading term ks cos^n(alpha) is
  reflected light per unit of incident light, not per unit of irradiance, so as a BRDF it is
  divided by the irradiance cosine, f = ks cos^n(alpha) / cos(theta_i) (the "original Phong
  BRDF" of Lafortune & Willems 1994, section 3). The 1/cos(theta_i) makes it neither reciprocal
  nor energy conserving.
- ``modified-phong``, f = ks (n + 2) / (2 pi) cos^n(alpha) (Lafortune & Willems 1994, section
  3): reciprocal, and its albedo is at most ks, reached at normal incidence.

Both are sampled from the density (n + 1) / (2 pi) cos^n(alpha) about the mirror direction
(Lafortune & Willems 1994, section 3, importance sampling); samples below the horizon are
rejected (pdf 0), so the density integrates to less than 1 over the hemisphere away from normal
incidence.
"""

import math

from .._jit import OPTIMISED, inline_kernel, kernel
from ..sampling import cosine_power_pdf, from_axis_frame, square_to_cosine_power
from . import _kinds
from ._registry import register
from .base import Model, Param, Start
from .packed import channel_mean

ORIGINAL, MODIFIED = 0, 1

_CITATION = ("Phong 1975, Illumination for Computer Generated Pictures; Lafortune & Willems "
             "1994, Using the Modified Phong Reflectance Model for Physically Based Rendering, "
             "KU Leuven report CW197, section 3")

#: The Phong exponent, shared by every Phong-like family (Blinn-Phong too).
EXPONENT = Param("n", 20.0, (0.0, math.inf), prior="log", aliases=("exponent", "shininess"),
                 doc="lobe exponent (larger is sharper)", fit_bounds=(1.0, 1e4))


@register
class Phong(Model):
    """Phong's original specular lobe as a BRDF, f = ks cos^n(alpha) / cos(theta_i).

    ``alpha`` is the angle between ``wo`` and the mirror direction of ``wi``. Kept for fitting
    and comparing legacy data; it violates reciprocity and, for large ``ks`` or grazing light,
    energy conservation. Use ``modified-phong`` for a physically plausible lobe.
    """

    name = "phong"
    summary = "Phong 1975 specular lobe, f = ks cos^n(alpha) / cos(theta_i) (not reciprocal)"
    citation = _CITATION
    kind = _kinds.PHONG
    mirror_symmetric = True  # a function of wo.reflect(wi) and cos(theta_i) only
    reciprocal = False
    energy_conserving = False
    PARAMS = (Param("ks", 1.0, (0.0, math.inf), per_channel=True, aliases=("rho_s",),
                    doc="specular scale", fit_bounds=(0.0, 1.0)),
              EXPONENT)
    START = Start(scale=("ks",), shape=("n",))  # f = ks N(n) cos^n(alpha)


@register
class ModifiedPhong(Model):
    """Energy-normalised Phong lobe, f = ks (n + 2) / (2 pi) cos^n(alpha).

    ``ks`` is the directional albedo at normal incidence, the largest albedo over all incident
    directions, so ``ks <= 1`` conserves energy.
    """

    name = "modified-phong"
    aliases = ("phong-normalized", "lafortune-willems")
    summary = "normalised Phong lobe, f = ks (n+2)/(2 pi) cos^n(alpha)"
    citation = _CITATION
    kind = _kinds.MODIFIED_PHONG
    mirror_symmetric = True  # a function of wo.reflect(wi) only
    PARAMS = (Param("ks", 1.0, (0.0, 1.0), per_channel=True, aliases=("rho_s",),
                    doc="specular albedo at normal incidence", fit_bounds=(0.0, 1.0)),
              EXPONENT)
    START = Start(scale=("ks",), shape=("n",))  # f = ks N(n) cos^n(alpha)


# --- lobe kernels (layout: ks[C], n) ---------------------------------------------------------

@kernel(linked=OPTIMISED)
def cos_alpha(ix, iy, iz, ox, oy, oz):
    """Cosine between ``wo`` and the mirror direction (-ix, -iy, iz) of ``wi``."""
    return -ix * ox - iy * oy + iz * oz


@inline_kernel
def _lobe(form, q, nch, ix, iy, iz, ox, oy, oz):
    """f per unit ks and its derivative in n (0 below the horizon or behind the lobe)."""
    if iz <= 0.0 or oz <= 0.0:
        return 0.0, 0.0
    ca = cos_alpha(ix, iy, iz, ox, oy, oz)
    if ca <= 0.0:
        return 0.0, 0.0
    n = q[nch]
    p = ca ** n
    if form == ORIGINAL:
        scale = 1.0 / iz  # Phong 1975 over cos(theta_i): Lafortune & Willems 1994, sec. 3
        scale_n = 0.0
    else:
        scale = (n + 2.0) / (2.0 * math.pi)  # Lafortune & Willems 1994, sec. 3
        scale_n = 1.0 / (2.0 * math.pi)
    # Lafortune & Willems 1994, sec. 3, differentiated: d(scale ca^n)/dn = scale' ca^n
    # + scale ca^n ln(ca)
    return scale * p, scale_n * p + scale * p * math.log(ca)


@inline_kernel
def eval_(form, q, nch, ix, iy, iz, ox, oy, oz, out, k):
    v, _ = _lobe(form, q, nch, ix, iy, iz, ox, oy, oz)
    for c in range(nch):
        out[k, c] += q[c] * v


@inline_kernel
def grad_(form, q, nch, ix, iy, iz, ox, oy, oz, out, k, d):
    """Add f = ks scale(n) cos^n(alpha) to ``out[k]``; its derivatives in ks and n into ``d``."""
    v, v_n = _lobe(form, q, nch, ix, iy, iz, ox, oy, oz)
    for c in range(nch):
        out[k, c] += q[c] * v
        d[c, k, c] = v
        d[nch, k, c] = q[c] * v_n


@kernel(linked=OPTIMISED)
def pdf_(q, nch, ix, iy, iz, ox, oy, oz):
    if iz <= 0.0 or oz <= 0.0:
        return 0.0
    return cosine_power_pdf(cos_alpha(ix, iy, iz, ox, oy, oz), q[nch])


@kernel(linked=OPTIMISED)
def sample_(q, nch, ix, iy, iz, u1, u2):
    if iz <= 0.0:
        return 0.0, 0.0, 1.0, 0.0
    n = q[nch]
    x, y, z = square_to_cosine_power(u1, u2, n)
    ox, oy, oz = from_axis_frame(x, y, z, -ix, -iy, iz)
    if oz <= 0.0:
        return ox, oy, oz, 0.0
    return ox, oy, oz, cosine_power_pdf(z, n)


@kernel(linked=OPTIMISED)
def hint_(form, q, nch, ix, iy, iz):
    """Mean ks times the lobe's albedo per unit ks at normal incidence."""
    if iz <= 0.0:
        return 0.0
    # integral of cos^(n+1) over the hemisphere is 2 pi / (n + 2); the modified form divides it out
    per_ks = 2.0 * math.pi / (q[nch] + 2.0) if form == ORIGINAL else 1.0
    return channel_mean(q, 0, nch) * per_ks

