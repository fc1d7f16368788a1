"""Blinn-Phong lobe: f = ks N(n) cos^n(theta_h), theta_h the angle of the half vector to the normal.

The normalisation N makes the albedo at normal incidence equal ks:

- ``exact``: N = (n + 2)(n + 4) / (8 pi (2^(-n/2) + n)) (F. Giesen 2009, "Derivation of Phong
  and Blinn-Phong BRDF normalization factors", Blinn-Phong BRDF section);
- ``approx``: N = (n + 8) / (8 pi) (Akenine-Moller, Haines & Hoffman 2008, Real-Time Rendering
  3rd ed., section 7.6), slightly too large, so the albedo exceeds ks (about 7.5 % at n = 10).

Sampling draws the half vector from (n + 1) / (2 pi) cos^n(theta_h) about the normal and reflects
wi about it, so pdf(wo) = pdf_h / (4 wi.h) (Walter 2005, "Notes on the Ward BRDF"; Jacobian
from Walter et al. 2007, eq. 14).
"""

import math

from .._jit import OPTIMISED, inline_kernel, kernel
from ..sampling import cosine_power_pdf, half_unit, reflect_about, square_to_cosine_power
from . import _kinds
from ._registry import register
from .base import Choice, Model, Param, Start
from .packed import channel_mean
from .phong import EXPONENT

EXACT, APPROX = 0, 1  # indices of the ``normalization`` choices, as packed for the kernels


@register
class BlinnPhong(Model):
    """Normalised Blinn-Phong lobe, f = ks N(n) cos^n(theta_h).

    With ``normalization=exact`` ``ks`` is the albedo at normal incidence (the largest over all
    incident directions); ``approx`` uses the common (n + 8) / (8 pi), which overshoots.
    """

    name = "blinn-phong"
    aliases = ("blinn",)
    summary = "normalised Blinn-Phong lobe, f = ks N(n) cos^n(theta_h)"
    citation = ("Blinn 1977, Models of Light Reflection for Computer Synthesized Pictures; "
                "exact normalisation: Giesen 2009; approx: Real-Time Rendering 3rd ed. 7.6")
    kind = _kinds.BLINN_PHONG
    mirror_symmetric = True  # a function of cos(theta_h) only
    PARAMS = (Param("ks", 1.0, (0.0, 1.0), per_channel=True, aliases=("rho_s",),
                    doc="specular albedo at normal incidence (exact normalisation)",
                    fit_bounds=(0.0, 1.0)),
              EXPONENT,
              Choice("normalization", "exact", ("exact", "approx"), aliases=("normalisation",),
                     doc="exact (Giesen 2009) or the (n+8)/(8 pi) approximation"))
    START = Start(scale=("ks",), shape=("n",))  # f = ks N(n) cos^n(theta_h)

    @property
    def energy_conserving(self):
        """The approximate normalisation gives albedos above ks, so above 1 for ks = 1."""
        return self["normalization"] == "exact"


# --- lobe kernels (layout: ks[C], n, normalization) ------------------------------------------

@kernel(linked=OPTIMISED)
def normalization_d(n, which):
    """N(n) such that the albedo at normal incidence is ks (``EXACT``) or about ks (``APPROX``),
    and dN/dn."""
    if which == APPROX:
        return (n + 8.0) / (8.0 * math.pi), 1.0 / (8.0 * math.pi)  # Real-Time Rendering 3rd ed. 7.6
    p = 2.0 ** (-0.5 * n)
    v = (n + 2.0) * (n + 4.0) / (8.0 * math.pi * (p + n))  # Giesen 2009
    # Giesen 2009 differentiated: d ln N / dn = 1/(n+2) + 1/(n+4) - (1 - p ln(2) / 2) / (p + n)
    return v, v * (1.0 / (n + 2.0) + 1.0 / (n + 4.0) - (1.0 - 0.5 * math.log(2.0) * p) / (p + n))


@kernel(linked=OPTIMISED)
def normalization(n, which):
    """N(n) such that the albedo at normal incidence is ks (``EXACT``) or about ks (``APPROX``)."""
    return normalization_d(n, which)[0]


@inline_kernel
def _lobe(q, nch, ix, iy, iz, ox, oy, oz):
    """f per unit ks, N(n) cos^n(theta_h), and its derivative in n (0 below the horizon)."""
    if iz <= 0.0 or oz <= 0.0:
        return 0.0, 0.0
    n = q[nch]
    _, _, hz, _ = half_unit(ix, iy, iz, ox, oy, oz)
    norm, norm_n = normalization_d(n, q[nch + 1])
    p = hz ** n
    # Blinn 1977's cos^n times N, differentiated: d(N hz^n)/dn = N' hz^n + N hz^n ln(hz);
    # hz^n = 0 where hz = 0, and so is the derivative
    return norm * p, (norm_n * p + norm * p * math.log(hz)) if p > 0.0 else 0.0


@inline_kernel
def eval_(q, nch, ix, iy, iz, ox, oy, oz, out, k):
    v, _ = _lobe(q, nch, ix, iy, iz, ox, oy, oz)
    for c in range(nch):
        out[k, c] += q[c] * v


@inline_kernel
def grad_(q, nch, ix, iy, iz, ox, oy, oz, out, k, d):
    """Add f = ks N(n) cos^n(theta_h) to ``out[k]``; its derivatives in ks and n into ``d``."""
    v, v_n = _lobe(q, nch, ix, iy, iz, ox, oy, oz)
    for c in range(nch):
        out[k, c] += q[c] * v
        d[c, k, c] = v
        d[nch, k, c] = q[c] * v_n


@kernel(linked=OPTIMISED)
def pdf_(q, nch, ix, iy, iz, ox, oy, oz):
    if iz <= 0.0 or oz <= 0.0:
        return 0.0
    _, _, hz, cos_d = half_unit(ix, iy, iz, ox, oy, oz)
    return cosine_power_pdf(hz, q[nch]) / (4.0 * cos_d)  # |dh/dwo| = 1/(4 wo.h): Walter 2007 eq. 14


@kernel(linked=OPTIMISED)
def sample_(q, nch, ix, iy, iz, u1, u2):
    if iz <= 0.0:
        return 0.0, 0.0, 1.0, 0.0
    n = q[nch]
    hx, hy, hz = square_to_cosine_power(u1, u2, n)
    ox, oy, oz = reflect_about(ix, iy, iz, hx, hy, hz)
    cos_d = ix * hx + iy * hy + iz * hz
    if oz <= 0.0 or cos_d <= 0.0:
        return ox, oy, oz, 0.0
    return ox, oy, oz, cosine_power_pdf(hz, n) / (4.0 * cos_d)


@kernel(linked=OPTIMISED)
def hint_(q, nch, ix, iy, iz):
    """Mean ks times the albedo per unit ks at normal incidence (1 when exact)."""
    if iz <= 0.0:
        return 0.0
    n = q[nch]
    return channel_mean(q, 0, nch) * normalization(n, q[nch + 1]) / normalization(n, float(EXACT))
