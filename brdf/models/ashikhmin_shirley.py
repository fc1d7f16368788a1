"""The anisotropic Phong BRDF of Ashikhmin & Shirley 2000 ("An Anisotropic Phong BRDF Model",
journal of graphics tools 5(2)): a Fresnel-weighted anisotropic Phong specular term plus a
non-Lambertian diffuse term that gives up the energy the specular term takes (eqs. 4-5).

The specular term is built from the half-vector density of eq. 8,
p_h(h) = sqrt((nu + 1)(nv + 1)) / (2 pi) (n.h)^(nu cos^2 phi_h + nv sin^2 phi_h), which integrates
to 1 exactly; importance sampling draws h from it (eqs. 9-10) and reflects wi about h, or
draws wo from the cosine density for the diffuse term: u1 picks one of the two (then is reused,
rescaled) and the pdf is the mixture of both densities.
"""

import math

from .._jit import OPTIMISED, inline_kernel, kernel
from ..sampling import half_unit, reflect_about, square_to_cosine_hemisphere
from . import _kinds, lambert
from ._registry import register
from .base import Model, Param, Start
from .fresnel import schlick, schlick_d

INV_PI = 1.0 / math.pi
DIFFUSE_NORM = 28.0 / (23.0 * math.pi)  # Ashikhmin & Shirley 2000, eq. 5


@register
class AshikhminShirley(Model):
    """Ashikhmin-Shirley BRDF: diffuse ``rd``, specular ``rs`` at normal incidence, exponents
    ``nu`` along the tangent x and ``nv`` along the bitangent y."""

    name = "ashikhmin-shirley"
    aliases = ("ashikhmin", "anisotropic-phong")
    summary = "anisotropic Phong: Fresnel-weighted specular lobe plus a coupled diffuse term"
    citation = "Ashikhmin & Shirley 2000, An Anisotropic Phong BRDF Model, JGT 5(2), eqs. 4-10"
    kind = _kinds.ASHIKHMIN_SHIRLEY
    mirror_symmetric = True  # eq. 4 squares h_x and h_y; k.h and the cosines are unchanged
    # Measured (tests/models/test_ashikhmin_shirley.py): the albedo is linear in rd and rs and
    # peaks at 0.9996 (rs = 1, nu = nv = 1e4, normal incidence) over all rd, rs in [0, 1].
    energy_conserving = True
    PARAMS = (
        Param("rd", 0.5, (0.0, 1.0), per_channel=True, aliases=("kd", "rho_d"),
              doc="diffuse reflectance of the substrate"),
        Param("rs", 0.05, (0.0, 1.0), per_channel=True, aliases=("ks", "rho_s"),
              doc="specular reflectance at normal incidence (Schlick's F0)"),
        Param("nu", 100.0, (0.0, 1e5), prior="log", aliases=("n",), fit_bounds=(1.0, 1e4),
              doc="Phong exponent along the tangent x (nv too when nv is not given)"),
        Param("nv", None, (0.0, 1e5), prior="log", fallback="nu", fit_bounds=(1.0, 1e4),
              doc="Phong exponent along the bitangent y (default: nu, isotropic)"),
    )
    # rd and rs enter bilinearly (rd (1 - rs) and Schlick's F(rs)): no scale to project out
    START = Start(shape=("nu", "nv"))


# --- kernels (layout: rd[C], rs[C], nu, nv) --------------------------------------------------

@kernel(linked=OPTIMISED)
def diffuse_factor(cos):
    """1 - (1 - cos / 2)^5, the angular factor of the diffuse term (eq. 5)."""
    m = 1.0 - 0.5 * cos
    m2 = m * m
    return 1.0 - m2 * m2 * m


@kernel(linked=OPTIMISED)
def half_exponent_d(nu, nv, hx, hy):
    """nu cos^2 phi_h + nv sin^2 phi_h (eq. 4), any value at h = n, where (n.h)^e = 1, and its
    derivatives cos^2 phi_h in nu and sin^2 phi_h in nv."""
    s2 = hx * hx + hy * hy
    if s2 <= 0.0:
        return nu, 1.0, 0.0
    cx = hx * hx / s2
    cy = hy * hy / s2
    return nu * cx + nv * cy, cx, cy


@kernel(linked=OPTIMISED)
def half_pdf_d(nu, nv, hx, hy, hz):
    """Density of the half vector in solid angle (eq. 8) and its derivatives in nu and nv:
    d ln p_h / d nu = 1 / (2 (nu + 1)) + ln(n.h) de/dnu, likewise nv."""
    if hz <= 0.0:
        return 0.0, 0.0, 0.0
    e, e_u, e_v = half_exponent_d(nu, nv, hx, hy)
    p = math.sqrt((nu + 1.0) * (nv + 1.0)) / (2.0 * math.pi) * hz ** e
    lh = math.log(hz)
    return p, p * (0.5 / (nu + 1.0) + lh * e_u), p * (0.5 / (nv + 1.0) + lh * e_v)


@kernel(linked=OPTIMISED)
def half_pdf(nu, nv, hx, hy, hz):
    """Density of the half vector in solid angle (eq. 8)."""
    return half_pdf_d(nu, nv, hx, hy, hz)[0]


@kernel(linked=OPTIMISED)
def sample_half(nu, nv, u1, u2):
    """A half vector drawn from eq. 8 (eqs. 9-10).

    Eq. 9, tan(phi) = sqrt((nu + 1)/(nv + 1)) tan(pi xi / 2), maps a quarter of a uniform angle to
    phi in the first quadrant; atan2 of the scaled sine and cosine of psi = 2 pi u1 applies it to
    all four quadrants at once and keeps phi continuous in u1.
    """
    psi = 2.0 * math.pi * u1
    phi = math.atan2(math.sqrt(nu + 1.0) * math.sin(psi), math.sqrt(nv + 1.0) * math.cos(psi))
    c, s = math.cos(phi), math.sin(phi)
    cos_t = (1.0 - u2) ** (1.0 / (nu * c * c + nv * s * s + 1.0))  # eq. 10
    sin_t = math.sqrt(max(0.0, 1.0 - cos_t * cos_t))
    return sin_t * c, sin_t * s, cos_t


@kernel(linked=OPTIMISED)
def albedo_parts(q, nch, iz):
    """Channel means of the specular and diffuse albedos at cos(theta_i) = iz.

    The diffuse albedo rd (1 - rs) (1 - (1 - iz/2)^5) is exact (the 28 / 23 pi of eq. 5 is the
    inverse of the integral of the outgoing factor times cos); the specular one is
    approximated by the Fresnel factor F(cos theta_i), the value for h = n.
    """
    spec = 0.0
    diff = 0.0
    fd = diffuse_factor(iz)
    for c in range(nch):
        spec += schlick(q[nch + c], iz)
        diff += q[c] * (1.0 - q[nch + c]) * fd
    return spec / nch, diff / nch


@kernel(linked=OPTIMISED)
def specular_weight(q, nch, iz):
    """Probability of sampling the specular term rather than the diffuse one: its share of the
    albedo estimates, which keeps the weights f cos / pdf flat."""
    spec, diff = albedo_parts(q, nch, iz)
    if diff <= 0.0:
        return 1.0
    if spec <= 0.0:
        return 0.0
    return spec / (spec + diff)


@inline_kernel
def _lobe(q, nch, ix, iy, iz, ox, oy, oz):
    """The channel-free factors of f: the specular term without F, its derivatives in nu and
    nv, the diffuse term without rd (1 - rs), and k.h (all 0 below the horizon)."""
    if iz <= 0.0 or oz <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 1.0
    nu = q[2 * nch]
    nv = q[2 * nch + 1]
    hx, hy, hz, kh = half_unit(ix, iy, iz, ox, oy, oz)
    # eq. 4 without F: p_h(h) / (4 (k.h) max(cos_i, cos_o)), p_h from eq. 8
    p, p_u, p_v = half_pdf_d(nu, nv, hx, hy, hz)
    w = 1.0 / (4.0 * kh * max(iz, oz))
    diff = DIFFUSE_NORM * diffuse_factor(iz) * diffuse_factor(oz)  # eq. 5 without rd (1 - rs)
    return p * w, p_u * w, p_v * w, diff, kh


@inline_kernel
def eval_(q, nch, ix, iy, iz, ox, oy, oz, out, k):
    spec, _, _, diff, kh = _lobe(q, nch, ix, iy, iz, ox, oy, oz)
    for c in range(nch):
        rs = q[nch + c]
        out[k, c] += spec * schlick(rs, kh) + diff * q[c] * (1.0 - rs)


@inline_kernel
def grad_(q, nch, ix, iy, iz, ox, oy, oz, out, k, d):
    """Add f (eqs. 4-5) to ``out[k]`` and its derivatives into ``d``: in rd, d(rd (1 - rs) f_d);
    in rs, the specular term times dF/dF0 minus rd f_d; in nu and nv through eq. 8."""
    spec, spec_u, spec_v, diff, kh = _lobe(q, nch, ix, iy, iz, ox, oy, oz)
    for c in range(nch):
        rd = q[c]
        rs = q[nch + c]
        f, f_rs = schlick_d(rs, kh)
        out[k, c] += spec * f + diff * rd * (1.0 - rs)
        d[c, k, c] = diff * (1.0 - rs)
        d[nch + c, k, c] = spec * f_rs - diff * rd
        d[2 * nch, k, c] = spec_u * f
        d[2 * nch + 1, k, c] = spec_v * f


@kernel(linked=OPTIMISED)
def pdf_(q, nch, ix, iy, iz, ox, oy, oz):
    if iz <= 0.0 or oz <= 0.0:
        return 0.0
    hx, hy, hz, kh = half_unit(ix, iy, iz, ox, oy, oz)
    w = specular_weight(q, nch, iz)
    spec = half_pdf(q[2 * nch], q[2 * nch + 1], hx, hy, hz) / (4.0 * kh)  # eq. 8 / 4 (k.h)
    return w * spec + (1.0 - w) * oz * INV_PI


@kernel(linked=OPTIMISED)
def sample_(q, nch, ix, iy, iz, u1, u2):
    if iz <= 0.0:
        return 0.0, 0.0, 1.0, 0.0
    w = specular_weight(q, nch, iz)
    if u1 < w:
        hx, hy, hz = sample_half(q[2 * nch], q[2 * nch + 1], u1 / w, u2)
        ox, oy, oz = reflect_about(ix, iy, iz, hx, hy, hz)
    else:
        u1 = min((u1 - w) / (1.0 - w), 0.9999999999999999)
        ox, oy, oz, _ = lambert.sample_(q, nch, ix, iy, iz, u1, u2)
    if oz <= 0.0:
        return ox, oy, oz, 0.0
    return ox, oy, oz, pdf_(q, nch, ix, iy, iz, ox, oy, oz)


#: The albedo integrates the specular and the diffuse term apart (see ``albedo_weight_``).
ALBEDO_TERMS = 2


@kernel(linked=OPTIMISED)
def albedo_weight_(q, nch, term, ix, iy, iz, u1, u2, out):
    """f cos(theta_o) / pdf of one term, each over the unit square of its own sampler, into
    ``out[0, :nch]``; returns cos(theta_o) and the smooth piece that holds the sample (0: none,
    the sample is below the horizon).

    Term 0 is the specular lobe (eq. 4) with h drawn from eq. 8: p_h / (4 k.h) cancels and the
    weight is F(k.h) cos_o / max(cos_i, cos_o), whose two pieces meet in a kink at cos_o = cos_i
    (at grazing incidence the piece cos_o < cos_i is a thin ramp along the horizon, as steep as
    a jump). Term 1 is the diffuse term (eq. 5) with wo drawn from the cosine density
    cos_o / pi: the weight is pi f_d = 28/23 rd (1 - rs) times the two angular factors. Apart,
    each integrand is smooth on its pieces; the mixture that ``sample_`` draws from would put a
    sharp lobe's dip (its pdf over the diffuse part) into the cubature's square.
    """
    if iz <= 0.0:
        return 0.0, 0
    if term == 0:
        hx, hy, hz = sample_half(q[2 * nch], q[2 * nch + 1], u1, u2)
        ox, oy, oz = reflect_about(ix, iy, iz, hx, hy, hz)
        if oz <= 0.0:
            return oz, 0
        kh = ix * hx + iy * hy + iz * hz
        s = oz / max(iz, oz)
        for c in range(nch):
            out[0, c] = schlick(q[nch + c], kh) * s
        return oz, 2 if oz < iz else 1
    _, _, oz = square_to_cosine_hemisphere(u1, u2)
    if oz <= 0.0:
        return oz, 0
    d = math.pi * DIFFUSE_NORM * diffuse_factor(iz) * diffuse_factor(oz)
    for c in range(nch):
        out[0, c] = q[c] * (1.0 - q[nch + c]) * d
    return oz, 1


@kernel(linked=OPTIMISED)
def hint_(q, nch, ix, iy, iz):
    if iz <= 0.0:
        return 0.0
    spec, diff = albedo_parts(q, nch, iz)
    return spec + diff
