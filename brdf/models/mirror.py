"""Perfect specular reflection: a delta lobe in the mirror direction (2 (wi.n) n - wi)."""

import math

from .._jit import OPTIMISED, kernel
from . import _kinds
from ._registry import FRESNEL, register
from .base import Model, Nested, Param
from .fresnel import fresnel


@register
class Mirror(Model):
    """Ideal mirror with reflectance ``reflectance`` times an optional Fresnel term.

    ``eval`` is 0 everywhere (the lobe is a Dirac delta); ``sample`` returns the mirror direction
    with ``pdf = inf`` and the weight ``reflectance * F(cos theta_i)``.
    """

    name = "mirror"
    aliases = ("specular", "perfect-specular")
    summary = "perfect specular reflection (delta lobe)"
    citation = "Fresnel reflection in the mirror direction; PBR 4th ed. 9.3"
    kind = _kinds.MIRROR
    mirror_symmetric = True  # the mirror direction of M wi is M times that of wi
    delta = True
    PARAMS = (Param("reflectance", 1.0, (0.0, 1.0), per_channel=True, aliases=("ks", "r"),
                    doc="reflectance scale"),
              Nested("fresnel", "none", FRESNEL, doc="Fresnel term at cos(theta_i)"))


@kernel(linked=OPTIMISED)
def sample_(q, nch, ix, iy, iz, u1, u2):
    if iz <= 0.0:
        return -ix, -iy, iz, 0.0
    return -ix, -iy, iz, math.inf


@kernel(linked=OPTIMISED)
def reflectance_(q, nch, ch, iz):
    """Energy the delta lobe reflects in channel ``ch`` (its albedo at cos(theta_i) = iz)."""
    if iz <= 0.0:
        return 0.0
    return q[ch] * fresnel(q, nch, nch, ch, iz)


@kernel(linked=OPTIMISED)
def hint_(q, nch, ix, iy, iz):
    s = 0.0
    for c in range(nch):
        s += reflectance_(q, nch, c, iz)
    return s / nch

