"""Ideal diffuse reflection: f = rho / pi (Lambert 1760, Photometria)."""

import math

from .._jit import OPTIMISED, inline_kernel, kernel
from ..sampling import square_to_cosine_hemisphere
from . import _kinds
from ._registry import register
from .base import Model, Param, Start
from .packed import channel_mean

INV_PI = 1.0 / math.pi


@register
class Lambert(Model):
    """Lambertian (ideal diffuse) reflector with per-channel albedo ``rho``."""

    name = "lambert"
    aliases = ("diffuse", "lambertian")
    summary = "ideal diffuse, f = albedo / pi"
    citation = "Lambert 1760, Photometria; f = rho / pi"
    kind = _kinds.LAMBERT
    mirror_symmetric = True  # f is a constant
    PARAMS = (Param("albedo", 0.5, (0.0, 1.0), per_channel=True, aliases=("rho", "rho_d", "kd"),
                    doc="directional-hemispherical reflectance", fit_bounds=(0.0, 1.0)),)
    START = Start(scale=("albedo",))  # f = albedo / pi


@kernel(linked=OPTIMISED)
def per_albedo(iz, oz):
    """f per unit albedo: 1 / pi above the horizon (a select keeps the array loop vectorised)."""
    return INV_PI if (iz > 0.0 and oz > 0.0) else 0.0


@inline_kernel
def eval_(q, nch, ix, iy, iz, ox, oy, oz, out, k):
    v = per_albedo(iz, oz)
    for c in range(nch):
        out[k, c] += q[c] * v  # f = rho / pi


@inline_kernel
def grad_(q, nch, ix, iy, iz, ox, oy, oz, out, k, d):
    """Add f to ``out[k, :nch]``, set ``d[c, k, c]`` = df_c / drho_c = 1 / pi (f = rho / pi)."""
    v = per_albedo(iz, oz)
    for c in range(nch):
        out[k, c] += q[c] * v
        d[c, k, c] = v


@inline_kernel
def sample_in_lanes(iz, u1, u2):
    """The cosine-weighted draw and its density z / pi (0 below either horizon), with selects
    where it could branch, inlined into its caller: a loop over items that calls it runs in
    SIMD lanes."""
    x, y, z = square_to_cosine_hemisphere(u1, u2)
    return x, y, z, density_in_lanes(iz, z)


@inline_kernel
def density_in_lanes(iz, oz):
    """:func:`pdf_`, the cosine-weighted density oz / pi, with a select where it branches."""
    return oz * INV_PI if (iz > 0.0 and oz > 0.0) else 0.0


@kernel(linked=OPTIMISED)
def sample_(q, nch, ix, iy, iz, u1, u2):
    return sample_in_lanes(iz, u1, u2)


@kernel(linked=OPTIMISED)
def pdf_(q, nch, ix, iy, iz, ox, oy, oz):
    if iz <= 0.0 or oz <= 0.0:
        return 0.0
    return oz * INV_PI


@kernel(linked=OPTIMISED)
def hint_(q, nch, ix, iy, iz):
    return channel_mean(q, 0, nch) if iz > 0.0 else 0.0
