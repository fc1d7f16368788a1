"""Rough diffuse reflection: the qualitative Oren-Nayar model (Oren & Nayar 1994, eq. 30).

Oren & Nayar 1994, "Generalization of Lambert's Reflectance Model", SIGGRAPH, model a rough
diffuse surface (clay, plaster, the Moon) as V-cavities of Lambertian facets whose slope angles
have standard deviation ``sigma``; their qualitative model (eq. 30) keeps the main effect, a
surface that grows brighter towards the light at grazing angles:

f = rho / pi (A + B max(0, cos(phi_i - phi_o)) sin(alpha) tan(beta)), alpha = max(theta_i,
theta_o), beta = min(theta_i, theta_o), A = 1 - 0.5 sigma^2 / (sigma^2 + 0.33),
B = 0.45 sigma^2 / (sigma^2 + 0.09).

sigma = 0 is Lambert's law exactly. f is symmetric in wi and wo (reciprocal), but not energy
conserving: at grazing incidence the albedo tends to rho (A + B / 2), above rho for small
sigma (1.011 rho at sigma = 0.2). Sampling is cosine-weighted, as Lambert's.
"""

from .._jit import OPTIMISED, inline_kernel, kernel
from . import _kinds, lambert
from ._registry import register
from .base import Model, Param, Start
from .packed import channel_mean


@register
class OrenNayar(Model):
    """Oren-Nayar rough diffuse reflector: per-channel ``albedo``, facet slope deviation
    ``sigma`` (radians)."""

    name = "oren-nayar"
    aliases = ("oren_nayar", "rough-diffuse")
    summary = "rough diffuse (V-cavities of Lambertian facets), qualitative model"
    citation = ("Oren & Nayar 1994, Generalization of Lambert's Reflectance Model, SIGGRAPH, "
                "eq. 30")
    kind = _kinds.OREN_NAYAR
    energy_conserving = False  # the albedo exceeds rho at grazing incidence for small sigma
    mirror_symmetric = True  # x and y enter only as wi_x wo_x + wi_y wo_y
    PARAMS = (
        Param("albedo", 0.5, (0.0, 1.0), per_channel=True, aliases=("rho",),
              doc="albedo of the Lambertian facets", fit_bounds=(0.0, 1.0)),
        Param("sigma", 0.3, (0.0, 1.5707963267948966), units="rad", fit_bounds=(0.0, 1.0),
              doc="standard deviation of the facet slope angle, in [0, pi/2)"),
    )
    START = Start(scale=("albedo",), shape=("sigma",))  # f is linear in albedo


# --- lobe kernels (layout: albedo[C], sigma) --------------------------------------------------

@inline_kernel
def _lobe(q, nch, ix, iy, iz, ox, oy, oz):
    """f per unit albedo and its derivative in sigma (0 below the horizon)."""
    if iz <= 0.0 or oz <= 0.0:
        return 0.0, 0.0
    s = q[nch]
    s2 = s * s
    a = 1.0 - 0.5 * s2 / (s2 + 0.33)  # Oren & Nayar 1994, eq. 30
    b = 0.45 * s2 / (s2 + 0.09)
    # max(0, cos(phi_i - phi_o)) sin(alpha) tan(beta) without angles: sin(theta_i) sin(theta_o)
    # cos(phi_i - phi_o) is the dot product of the directions' xy parts, and sin(alpha)
    # tan(beta) / (sin(theta_i) sin(theta_o)) = 1 / cos(beta), the larger cosine
    g = max(0.0, ix * ox + iy * oy) / max(iz, oz)
    # eq. 30 differentiated: dA/dsigma = -0.33 sigma / (sigma^2 + 0.33)^2,
    # dB/dsigma = 0.081 sigma / (sigma^2 + 0.09)^2
    da = -0.33 * s / ((s2 + 0.33) * (s2 + 0.33))
    db = 0.081 * s / ((s2 + 0.09) * (s2 + 0.09))
    return (a + b * g) * lambert.INV_PI, (da + db * g) * lambert.INV_PI


@inline_kernel
def eval_(q, nch, ix, iy, iz, ox, oy, oz, out, k):
    v, _ = _lobe(q, nch, ix, iy, iz, ox, oy, oz)
    for c in range(nch):
        out[k, c] += q[c] * v


@inline_kernel
def grad_(q, nch, ix, iy, iz, ox, oy, oz, out, k, d):
    """Add f = albedo (A + B g) / pi to ``out[k]``; its derivatives in albedo and sigma into
    ``d``."""
    v, v_s = _lobe(q, nch, ix, iy, iz, ox, oy, oz)
    for c in range(nch):
        out[k, c] += q[c] * v
        d[c, k, c] = v
        d[nch, k, c] = q[c] * v_s


@kernel(linked=OPTIMISED)
def sample_(q, nch, ix, iy, iz, u1, u2):
    return lambert.sample_(q, nch, ix, iy, iz, u1, u2)  # cosine-weighted


@kernel(linked=OPTIMISED)
def pdf_(q, nch, ix, iy, iz, ox, oy, oz):
    return lambert.pdf_(q, nch, ix, iy, iz, ox, oy, oz)


@kernel(linked=OPTIMISED)
def hint_(q, nch, ix, iy, iz):
    return channel_mean(q, 0, nch) if iz > 0.0 else 0.0
