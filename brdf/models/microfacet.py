"""Microfacet lobes in the Cook-Torrance form with GGX or Beckmann normals.

f = ks F(wi.h) D(h) G2(wi, wo) / (4 cos(theta_i) cos(theta_o))  (Walter et al. 2007, eq. 20)

D is anisotropic with roughness ``alpha`` along the tangent x and ``alpha_y`` along y (isotropic
when ``alpha_y`` is not given). G2 is Smith's masking-shadowing, separable G1(wi) G1(wo) by
default (the form in Walter et al. 2007 and Mitsuba 3) or height-correlated
1 / (1 + Lambda(wi) + Lambda(wo)) (Heitz 2014, "Understanding the Masking-Shadowing Function in
Microfacet-Based BRDFs", eq. 99). Sampling draws visible normals (Dupuy & Benyoub 2023's spherical
caps for GGX; Heitz & d'Eon 2014 for Beckmann), so pdf(wo) = G1(wi) D(h) / (4 cos(theta_i)).
"""

import math

from .._jit import OPTIMISED, inline_kernel, kernel
from ..sampling import reflect_about, sincos_turn
from . import _kinds
from ._registry import FRESNEL, register
from .base import Choice, Model, Nested, Param, Start
from .fresnel import NONE, fresnel, fresnel_d

#: The distributions, the first argument (``dist``) of the kernels below. GGX is None, which
#: numba types apart and prunes tests against (it prunes no other constant's), so a kernel
#: compiled for GGX drops every ``dist is GGX`` test with its Beckmann branch: a model without
#: Beckmann lobes never compiles Beckmann's sampler (its slope search and erfinv).
GGX, BECKMANN = None, 1
SQRT_PI = math.sqrt(math.pi)
ERF_EDGE = 1.0 - 2.0 ** -53
ERF_EDGE_U = 2.0 ** -54  # the u with 2u - 1 = -ERF_EDGE
#: A bracket of the visible slope for every u in [2^-54, 1 - 2^-53] and mu >= 0: C(-7) <=
#: (erfc(7) + e^-49) C(mu) < 2^-54 C(mu) and C(mu) - C(7) <= erfc(7) C(mu) < 2^-53 C(mu), as
#: C(mu) >= max(1/2, sqrt(pi) mu / 2) and (mu - t) <= mu (see beckmann_visible_slope_search).
SLOPE_LO, SLOPE_HI = -7.0, 7.0
#: Bracket width at which the visible-slope inversion stops if Halley's steps have not.
SLOPE_TOL = 2.0 ** -40
#: Iteration cap of the inversion: every three evaluations at least halve the bracket, and
#: 2^44 SLOPE_TOL > SLOPE_HI - SLOPE_LO, so 3 * 44 + 1 evaluations always reach SLOPE_TOL.
MAX_STEPS = 3 * 44 + 1


class Microfacet(Model):
    """Shared parameters of the GGX and Beckmann lobes (kernel layout in declaration order)."""

    distribution = GGX
    mirror_symmetric = True  # D and Lambda take x, y squared; F depends on wi.h
    PARAMS = (
        Param("ks", 1.0, (0.0, math.inf), per_channel=True, aliases=("rho_s",),
              doc="specular scale", fit_bounds=(0.0, 2.0)),
        Param("alpha", 0.1, (1e-4, 4.0), prior="log", aliases=("alpha_x",),
              doc="roughness (along the tangent x when alpha_y is given)", fit_bounds=(1e-3, 1.5)),
        Param("alpha_y", None, (1e-4, 4.0), prior="log", fallback="alpha",
              doc="roughness along the bitangent y (default: alpha, isotropic)",
              fit_bounds=(1e-3, 1.5)),
        Choice("masking", "separable", ("separable", "height-correlated"),
               doc="Smith masking-shadowing: G1(wi) G1(wo), or height-correlated"),
        Nested("fresnel", "none", FRESNEL, doc="Fresnel term at cos(theta_d)"),
    )
    START = Start(scale=("ks",), shape=("alpha", "alpha_y"))  # f = ks F D G2 / (4 cos cos)


@register
class GGXModel(Microfacet):
    name = "ggx"
    aliases = ("trowbridge-reitz", "cook-torrance-ggx")
    summary = "Cook-Torrance microfacet lobe with GGX normals"
    citation = ("Walter et al. 2007, Microfacet Models for Refraction through Rough Surfaces, "
                "eqs. 20, 33, 34; anisotropy: Heitz 2014 eq. 85-86; sampling: Heitz 2018 eq. 17, "
                "Dupuy & Benyoub 2023")
    kind = _kinds.GGX
    distribution = GGX


@register
class BeckmannModel(Microfacet):
    name = "beckmann"
    aliases = ("cook-torrance",)
    summary = "Cook-Torrance microfacet lobe with Beckmann normals"
    citation = ("Cook & Torrance 1982; Walter et al. 2007 eqs. 20, 25, 27; sampling: "
                "Heitz & d'Eon 2014, Importance Sampling Microfacet-Based BSDFs using the "
                "Distribution of Visible Normals")
    kind = _kinds.BECKMANN
    distribution = BECKMANN


# --- distributions ---------------------------------------------------------------------------

@kernel(linked=OPTIMISED)
def ndf_d(dist, ax, ay, hx, hy, hz):
    """Normal distribution D(h) in 1/sr (integral of D cos = 1) as a fraction, with its
    logarithmic partial derivatives in alpha_x and alpha_y as numerators over a common
    denominator: ``(D numerator, D denominator, n_x, n_y, den)`` with d ln D / d alpha =
    n / den, so that a caller multiplying D into other fractions divides once for all of them
    (divisions bound the evaluation); h need not be normalised."""
    hh = hx * hx + hy * hy + hz * hz
    sx = hx / ax
    sy = hy / ay
    if dist is GGX:
        t = sx * sx + sy * sy + hz * hz
        # Heitz 2014, eq. 85: D = |h|^4 / (pi ax ay t^2)
        # eq. 85 differentiated: d ln D / d alpha_x = (4 s_x^2 / t - 1) / alpha_x
        return (hh * hh, math.pi * ax * ay * t * t, (4.0 * sx * sx - t) / ax,
                (4.0 * sy * sy - t) / ay, t)
    hz2 = hz * hz
    # eq. 84: D = exp(-(s_x^2 + s_y^2) / h_z^2) |h|^4 / (pi ax ay h_z^4)
    # eq. 84 differentiated: d ln D / d alpha_x = (2 s_x^2 / h_z^2 - 1) / alpha_x
    return (math.exp(-(sx * sx + sy * sy) / hz2) * hh * hh, math.pi * ax * ay * hz2 * hz2,
            (2.0 * sx * sx - hz2) / ax, (2.0 * sy * sy - hz2) / ay, hz2)


@kernel(linked=OPTIMISED)
def ndf(dist, ax, ay, hx, hy, hz):
    """Normal distribution D(h) in 1/sr (integral of D cos = 1); h need not be normalised."""
    num, den, _, _, _ = ndf_d(dist, ax, ay, hx, hy, hz)
    return num / den


@kernel(linked=OPTIMISED)
def smith_lambda_d(dist, ax, ay, x, y, z):
    """Smith's Lambda of a direction with z > 0 (Heitz 2014, eqs. 72, 83 Beckmann, 86 GGX) and
    its partial derivatives in alpha_x and alpha_y."""
    a2t2 = (ax * ax * x * x + ay * ay * y * y) / (z * z)  # alpha(phi)^2 tan^2(theta)
    z2 = z * z
    if dist is GGX:
        root = math.sqrt(1.0 + a2t2)
        # eq. 86 differentiated through a2t2: dLambda/da2t2 = 1 / (4 root)
        w = 0.5 / (root * z2)
        return 0.5 * (root - 1.0), w * ax * x * x, w * ay * y * y
    if a2t2 <= 0.0:
        return 0.0, 0.0, 0.0
    a = 1.0 / math.sqrt(a2t2)
    e = math.exp(-a * a)
    # eq. 83 differentiated: dLambda/da = -exp(-a^2) / (2 sqrt(pi) a^2), da/da2t2 = -a^3 / 2
    w = e * a / (2.0 * SQRT_PI * z2)
    return 0.5 * (math.erf(a) - 1.0) + e / (2.0 * a * SQRT_PI), w * ax * x * x, w * ay * y * y


@kernel(linked=OPTIMISED)
def smith_lambda(dist, ax, ay, x, y, z):
    """Smith's Lambda of a direction with z > 0 (Heitz 2014, eqs. 72, 83 Beckmann, 86 GGX)."""
    return smith_lambda_d(dist, ax, ay, x, y, z)[0]


@kernel(linked=OPTIMISED)
def ggx_root(ax, ay, x, y, z):
    """sqrt(z^2 + alpha_x^2 x^2 + alpha_y^2 y^2), so that GGX's 1 + Lambda = (z + root) / (2 z)."""
    return math.sqrt(z * z + ax * ax * x * x + ay * ay * y * y)  # Heitz 2014, eq. 86


@kernel(linked=OPTIMISED)
def g1(dist, ax, ay, x, y, z):
    """Smith masking G1 = 1 / (1 + Lambda) of a direction with z > 0 (Heitz 2014, eq. 43)."""
    if dist is GGX:
        return 2.0 * z / (z + ggx_root(ax, ay, x, y, z))
    return 1.0 / (1.0 + smith_lambda(dist, ax, ay, x, y, z))


@kernel(linked=OPTIMISED)
def visibility_d(dist, separable, ax, ay, ix, iy, iz, ox, oy, oz):
    """G2 / (4 cos_i cos_o) for directions above the horizon as its reciprocal, so that a
    caller multiplying it into other fractions divides once for all of them, with its
    logarithmic partial derivatives in alpha_x and alpha_y as numerators over a common
    denominator (as :func:`ndf_d`): ``(1 / v, m_x, m_y, den)``.

    For GGX, G1 = 2 z / (z + root) cancels the cosines: separable G2 / (4 cos_i cos_o) =
    1 / ((z_i + root_i)(z_o + root_o)), height-correlated = 1 / (2 (root_i z_o + root_o z_i)).
    """
    if dist is GGX:
        ri = ggx_root(ax, ay, ix, iy, iz)
        ro = ggx_root(ax, ay, ox, oy, oz)
        # d root / d alpha_x = alpha_x x^2 / root (the root of Heitz 2014, eq. 86)
        if separable:
            # Walter et al. 2007, eq. 34 (G1 of each side) differentiated:
            # d ln v = -d root_i / (z_i + root_i) - d root_o / (z_o + root_o)
            p = ri * (iz + ri)
            r = ro * (oz + ro)
            return ((iz + ri) * (oz + ro), -ax * (ix * ix * r + ox * ox * p),
                    -ay * (iy * iy * r + oy * oy * p), p * r)
        s = ri * oz + ro * iz
        # Heitz 2014, eq. 99 with GGX's Lambda (eq. 86): v = 1 / (2 s); d ln v = -d s / s
        return (2.0 * s, -ax * (ix * ix * oz * ro + ox * ox * iz * ri),
                -ay * (iy * iy * oz * ro + oy * oy * iz * ri), ri * ro * s)
    li, li_x, li_y = smith_lambda_d(dist, ax, ay, ix, iy, iz)
    lo, lo_x, lo_y = smith_lambda_d(dist, ax, ay, ox, oy, oz)
    if separable:
        m = (1.0 + li) * (1.0 + lo)  # Heitz 2014, eq. 98: v = 1 / (m 4 cos_i cos_o)
        # d ln v = -d Lambda_i / (1 + Lambda_i) - d Lambda_o / (1 + Lambda_o)
        return (m * (4.0 * iz * oz), -(li_x * (1.0 + lo) + lo_x * (1.0 + li)),
                -(li_y * (1.0 + lo) + lo_y * (1.0 + li)), m)
    s = 1.0 + li + lo  # eq. 99: v = 1 / (s 4 cos_i cos_o)
    return s * (4.0 * iz * oz), -(li_x + lo_x), -(li_y + lo_y), s


@kernel(linked=OPTIMISED)
def visibility(dist, separable, ax, ay, ix, iy, iz, ox, oy, oz):
    """G2 / (4 cos_i cos_o) for directions above the horizon (see :func:`visibility_d`)."""
    return 1.0 / visibility_d(dist, separable, ax, ay, ix, iy, iz, ox, oy, oz)[0]


@kernel(linked=OPTIMISED)
def _giles_erfinv(w, y):
    """erfinv(y) to single precision from w = -ln((1 - y)(1 + y)): Giles 2010, "Approximating
    the erfinv function", GPU Computing Gems, single-precision branch (fitted over the range of
    float inputs, w <= 16)."""
    if w < 5.0:
        w -= 2.5
        p = 2.81022636e-08
        p = 3.43273939e-07 + p * w
        p = -3.5233877e-06 + p * w
        p = -4.39150654e-06 + p * w
        p = 0.00021858087 + p * w
        p = -0.00125372503 + p * w
        p = -0.00417768164 + p * w
        p = 0.246640727 + p * w
        p = 1.50140941 + p * w
    else:
        w = math.sqrt(w) - 3.0
        p = -0.000200214257
        p = 0.000100950558 + p * w
        p = 0.00134934322 + p * w
        p = -0.00367342844 + p * w
        p = 0.00573950773 + p * w
        p = -0.0076224613 + p * w
        p = 0.00943887047 + p * w
        p = 1.00167406 + p * w
        p = 2.83297682 + p * w
    return p * y


@kernel(linked=OPTIMISED)
def erfinv(y):
    """Inverse error function: Giles 2010's single-precision estimate refined by one Halley step
    on erf(x) = y (erf'' = -2x erf' makes it x - e / (1 + x e), e = (erf(x) - y) / erf'(x));
    its cubic convergence turns Giles' 1e-7 into rounding error (measured: relative error below
    2e-13 for |y| <= 1 - 1e-6; closer to +-1, erf(x) - y loses digits, as it did with the two
    Newton steps this replaces). ``y`` is clamped inside (-1, 1) so that u = 0, a legal uniform
    number, maps to a finite slope."""
    y = min(max(y, -ERF_EDGE), ERF_EDGE)
    x = _giles_erfinv(-math.log((1.0 - y) * (1.0 + y)), y)
    e = (math.erf(x) - y) / (2.0 / SQRT_PI * math.exp(-x * x))
    return x - e / (1.0 + x * e)


@kernel(linked=OPTIMISED)
def beckmann_visible_slope_search(mu, u, halley):
    """Slope x of a unit-roughness Beckmann visible normal seen at cot(theta) = mu >= 0, the
    number of CDF evaluations spent and the width of the final bracket.

    Solves C(x) = u C(mu) on x < mu, where C(x) = mu sqrt(pi)/2 erfc(-x) + exp(-x^2)/2 is the
    CDF of the visible-slope density (mu - x) exp(-x^2) of Heitz & d'Eon 2014, section 5.2
    (erfc(-x) rather than 1 + erf(x) keeps the left tail's precision). C rises strictly, so the
    root stays inside a bracket [lo, hi], first [SLOPE_LO, min(mu, SLOPE_HI)], that every
    evaluation narrows (Jakob 2014, "An Improved Visible Normal Sampling Routine for the
    Beckmann Distribution", brackets it likewise in the erf domain). Halley's method runs on
    ln C(x) for u <= 1/2 and on ln S(x), S = C(mu) - C(x), above: in logs the Gaussian tails
    are near-quadratic, so steps stay long far from the root. A step whose curvature
    correction more than doubles it falls back to Newton's (near mu, ln S ~ 2 ln(mu - x) drives
    Halley's denominator to 0); a step that leaves the bracket, and any step after two
    evaluations that did not halve it, is a bisection, so each three evaluations halve the
    bracket and MAX_STEPS of them bring it below SLOPE_TOL: the search returns converged by
    construction. A Halley step below 1e-4 of the scale of x ends it sooner (its error is of
    the order of the step's cube); so does the bracket reaching SLOPE_TOL, as it does where
    S has no digits left (u within ~1e-13 of 1).

    The start blends the exact solutions at the two ends of mu, erfinv(2u - 1) (mu -> inf,
    density exp(-x^2)) and -sqrt(-ln u) (mu = 0, C = exp(-x^2)/2), with weights mu^2 and 1;
    for u > 1/2, x_mu solving S = exp(-mu^2) (mu - x)^2 / 2 is a lower bound of the root where
    x_mu >= -mu (there exp(-t^2) >= exp(-mu^2) under the integral of S) and so narrows the
    bracket, and it takes over from the blend where that lies right of mu. ``halley`` False
    bisects from the first step: the worst case that MAX_STEPS is sized for, for the tests.
    """
    u = max(u, ERF_EDGE_U)  # like erfinv's clamp: u = 0, a legal uniform number, stays finite
    k = 0.5 * SQRT_PI * mu
    em = math.exp(-mu * mu)
    total = k * math.erfc(-mu) + 0.5 * em
    right = u > 0.5
    log_target = math.log((1.0 - u) * total if right else u * total)
    lo, hi = SLOPE_LO, min(mu, SLOPE_HI)
    # Giles' fit covers w <= 16; clamped, it only coarsens the start in the far tails
    gauss = _giles_erfinv(min(-math.log(4.0 * u * (1.0 - u)), 16.0), 2.0 * u - 1.0)
    w = mu * mu / (1.0 + mu * mu)
    x = w * gauss - (1.0 - w) * math.sqrt(-math.log(u))
    if right:
        near_mu = mu - math.sqrt(2.0 * (1.0 - u) * total / em)
        x = near_mu if x >= mu else max(x, near_mu)
        if near_mu >= -mu:
            lo = max(lo, near_mu)
    if not halley or not lo <= x < hi:
        x = 0.5 * (lo + hi)
    before = last = hi - lo  # the bracket's width two evaluations back and one back
    for i in range(MAX_STEPS):
        e = math.exp(-x * x)
        if right:  # g = ln((1 - u) C(mu)) - ln S rises with x as S falls
            c = k * (math.erfc(x) - math.erfc(mu)) + 0.5 * (em - e)
            sign = -1.0
        else:
            c = k * math.erfc(-x) + 0.5 * e
            sign = 1.0
        g = sign * (math.log(c) - log_target)
        if g <= 0.0:
            lo = x
        else:  # also NaN: S <= 0 from cancellation next to mu, where x is right of the root
            hi = x
        width = hi - lo
        if width <= SLOPE_TOL:
            return 0.5 * (lo + hi), i + 1, width
        g1 = (mu - x) * e / c  # C' = (mu - x) exp(-x^2), over c
        g2 = -e * (1.0 + 2.0 * x * (mu - x)) / c - sign * g1 * g1  # C'' / c - sign (C' / c)^2
        step = g / g1
        d = 1.0 - 0.5 * step * g2 / g1  # Halley: Newton's step over d, if d keeps it sane
        if d >= 0.5:
            step /= d
        # the scale of x is 1, or its distance to mu where S vanishes like (mu - x)^2
        if halley and abs(step) <= 1e-4 * min(1.0 + abs(x), mu - x):
            # a rounding-level step may point out of the bracket
            return min(max(x - step, lo), hi), i + 1, width
        x -= step
        stalled = i >= 2 and width > 0.5 * before
        before, last = last, width
        if not halley or stalled or not lo < x < hi:
            x = 0.5 * (lo + hi)
    return 0.5 * (lo + hi), MAX_STEPS, hi - lo  # not reached: width <= SLOPE_TOL by then


@kernel(linked=OPTIMISED)
def beckmann_visible_slope_x(mu, u):
    """Slope x of a unit-roughness Beckmann visible normal seen at cot(theta) = mu >= 0, to
    within SLOPE_TOL (see :func:`beckmann_visible_slope_search`)."""
    return beckmann_visible_slope_search(mu, u, True)[0]


@kernel(linked=OPTIMISED)
def sample_visible_normal(dist, ax, ay, ix, iy, iz, u1, u2):
    """A microfacet normal drawn from D_wi(h) = G1(wi) max(0, wi.h) D(h) / cos(theta_i)."""
    vx = ax * ix  # stretch to unit roughness
    vy = ay * iy
    inv = 1.0 / math.sqrt(vx * vx + vy * vy + iz * iz)
    vx *= inv
    vy *= inv
    vz = iz * inv
    if dist is GGX:  # Dupuy & Benyoub 2023, "Sampling Visible GGX Normals with Spherical Caps"
        # (listing 3): V plus a point uniform on the unit sphere's cap z > -V.z, unstretched;
        # three square roots and no tangent frame, where Heitz 2018's listing 1 takes six
        z = (1.0 - u1) * (1.0 + vz) - vz
        st = math.sqrt(max(0.0, 1.0 - z * z))
        sin_phi, cos_phi = sincos_turn(u2)
        mx, my, mz = ax * (st * cos_phi + vx), ay * (st * sin_phi + vy), max(0.0, z + vz)
    else:  # Heitz & d'Eon 2014, section 5.2: standard visible slopes, rotate, unstretch
        sin_t = math.sqrt(vx * vx + vy * vy)
        if sin_t < 1e-9:
            sx = erfinv(2.0 * u1 - 1.0)
            cphi, sphi = 1.0, 0.0
        else:
            sx = beckmann_visible_slope_x(vz / sin_t, u1)
            cphi, sphi = vx / sin_t, vy / sin_t
        sy = erfinv(2.0 * u2 - 1.0)
        mx = -(cphi * sx - sphi * sy) * ax
        my = -(sphi * sx + cphi * sy) * ay
        mz = 1.0
    inv = 1.0 / math.sqrt(mx * mx + my * my + mz * mz)
    return mx * inv, my * inv, mz * inv


# --- lobe kernels (layout: ks[C], alpha, alpha_y, masking, fresnel[1 + 2C]) -------------------

@inline_kernel
def _lobe(dist, q, nch, ix, iy, iz, ox, oy, oz):
    """:func:`_lobe_at` with the lobe's roughness and masking read from its packed row."""
    return _lobe_at(dist, q[nch], q[nch + 1], q[nch + 2] == 0.0, ix, iy, iz, ox, oy, oz)


@inline_kernel
def _lobe_at(dist, ax, ay, separable, ix, iy, iz, ox, oy, oz):
    """The channel-free factor D G2 / (4 cos_i cos_o) of f (0 unless both directions are above
    the horizon), its partial derivatives in alpha_x and alpha_y, and the unnormalised half
    vector; ``eval_`` and ``grad_`` both build f from it.

    The derivatives are f times the sum of the logarithmic derivatives of D and of G2 / (4
    cos_i cos_o), each a fraction (:func:`ndf_d`, :func:`visibility_d`): over their common
    denominator, one division serves both (the divisions bounded the gradient pass). D and
    G2 / (4 cos_i cos_o), fractions too, make f with one division (two took half again as
    long in an evaluation of ``lambert + ggx``)."""
    hx = ix + ox
    hy = iy + oy
    hz = iz + oz
    d, d_den, n_x, n_y, den = ndf_d(dist, ax, ay, hx, hy, hz)
    v_den, m_x, m_y, den_v = visibility_d(dist, separable, ax, ay, ix, iy, iz, ox, oy, oz)
    f = d / (d_den * v_den)
    u = f / (den * den_v)
    above = iz > 0.0 and oz > 0.0  # selects, not branches: keep the loops vectorised
    return (f if above else 0.0, ((n_x * den_v + m_x * den) * u) if above else 0.0,
            ((n_y * den_v + m_y * den) * u) if above else 0.0, hx, hy, hz)


@kernel(linked=OPTIMISED)
def _cos_d(ix, iy, iz, hx, hy, hz):
    """wi.h with h the unit half vector of the unnormalised (hx, hy, hz)."""
    return (ix * hx + iy * hy + iz * hz) / math.sqrt(hx * hx + hy * hy + hz * hz)


@inline_kernel
def rows_split_(q, nch):
    """Whether the lobe has no Fresnel term: the test ``eval_`` and ``grad_`` make at every pair
    (see ``brdf.models._kernels.rows_dispatcher``)."""
    return q[nch + 3] == NONE


@inline_kernel
def _eval_at(dist, q, nch, plain, ix, iy, iz, ox, oy, oz, out, k):
    """``eval_``, with F = 1 when ``plain`` (the lobe has no Fresnel term)."""
    v, _, _, hx, hy, hz = _lobe(dist, q, nch, ix, iy, iz, ox, oy, oz)
    if plain:
        for c in range(nch):
            out[k, c] += q[c] * v  # Walter et al. 2007, eq. 20 with F = 1
    else:
        cos_d = _cos_d(ix, iy, iz, hx, hy, hz)
        for c in range(nch):
            out[k, c] += q[c] * fresnel(q, nch + 3, nch, c, cos_d) * v  # eq. 20


@inline_kernel
def eval_(dist, q, nch, ix, iy, iz, ox, oy, oz, out, k):
    _eval_at(dist, q, nch, rows_split_(q, nch), ix, iy, iz, ox, oy, oz, out, k)


@inline_kernel
def eval_rows_(dist, q, nch, wi, wo, out):
    """``eval_`` at every row of ``wi`` and ``wo`` for a lobe without a Fresnel term (the test
    made once, the loop over the rows then holds no branch or call and vectorises); returns
    False, leaving the rows to ``eval_``, for a lobe with one."""
    if not rows_split_(q, nch):
        return False
    for k in range(wi.shape[0]):
        _eval_at(dist, q, nch, True, wi[k, 0], wi[k, 1], wi[k, 2], wo[k, 0], wo[k, 1], wo[k, 2],
                 out, k)
    return True


@inline_kernel
def _grad_at(dist, q, nch, plain, ix, iy, iz, ox, oy, oz, out, k, d):
    """``grad_``, with F = 1 when ``plain`` (the lobe has no Fresnel term)."""
    v, v_x, v_y, hx, hy, hz = _lobe(dist, q, nch, ix, iy, iz, ox, oy, oz)
    if plain:
        for c in range(nch):
            ks = q[c]
            out[k, c] += ks * v
            d[c, k, c] = v
            d[nch, k, c] = ks * v_x
            d[nch + 1, k, c] = ks * v_y
    else:
        cos_d = _cos_d(ix, iy, iz, hx, hy, hz)
        for c in range(nch):
            ks = q[c]
            f, f_a, f_b = fresnel_d(q, nch + 3, nch, c, cos_d)
            out[k, c] += ks * f * v
            d[c, k, c] = f * v
            d[nch, k, c] = ks * f * v_x
            d[nch + 1, k, c] = ks * f * v_y
            d[nch + 4 + c, k, c] = ks * f_a * v
            d[2 * nch + 4 + c, k, c] = ks * f_b * v


@inline_kernel
def grad_(dist, q, nch, ix, iy, iz, ox, oy, oz, out, k, d):
    """Add f to ``out[k, :nch]`` and set ``d[j, k, c]`` to df_c / dq[j] for the parameters f
    depends on: Walter et al. 2007, eq. 20, differentiated in ks, alpha_x, alpha_y (through
    :func:`ndf_d`, :func:`visibility_d`) and the Fresnel parameters (:func:`fresnel_d`)."""
    _grad_at(dist, q, nch, rows_split_(q, nch), ix, iy, iz, ox, oy, oz, out, k, d)


@inline_kernel
def grad_rows_(dist, q, nch, wi, wo, out, d):
    """``grad_`` at every row of ``wi`` and ``wo`` for a lobe without a Fresnel term, else False
    (see :func:`eval_rows_`)."""
    if not rows_split_(q, nch):
        return False
    for k in range(wi.shape[0]):
        _grad_at(dist, q, nch, True, wi[k, 0], wi[k, 1], wi[k, 2], wo[k, 0], wo[k, 1], wo[k, 2],
                 out, k, d)
    return True


@inline_kernel
def _visible_density(dist, ax, ay, ix, iy, iz, ox, oy, oz):
    """The density of wo drawn from the visible normals, above the horizon on both sides."""
    # D_wi(h) / (4 wo.h) with D_wi = G1 (wi.h) D / cos_i and wi.h = wo.h: Heitz 2018, eq. 17
    return g1(dist, ax, ay, ix, iy, iz) * ndf(dist, ax, ay, ix + ox, iy + oy, iz + oz) / (4.0 * iz)


@kernel(linked=OPTIMISED)
def pdf_(dist, q, nch, ix, iy, iz, ox, oy, oz):
    if iz <= 0.0 or oz <= 0.0:
        return 0.0
    return _visible_density(dist, q[nch], q[nch + 1], ix, iy, iz, ox, oy, oz)


@inline_kernel
def plain_in_lanes(dist, q, nch, ix, iy, iz, ox, oy, oz):
    """f over the lobe's colour for a lobe without a Fresnel term (:func:`rows_split_`): the
    factor D G2 / (4 cos_i cos_o) of ``eval_``, 0 below the horizon, inlined into its caller,
    whose loop over items then runs in SIMD lanes."""
    return _lobe(dist, q, nch, ix, iy, iz, ox, oy, oz)[0]


@inline_kernel
def pdf_in_lanes(dist, q, nch, ix, iy, iz, ox, oy, oz):
    """:func:`pdf_` with a select where it branches, inlined into its caller (see
    :func:`plain_in_lanes`)."""
    return density_in_lanes(dist, q[nch], q[nch + 1], ix, iy, iz, ox, oy, oz)


@inline_kernel
def factor_in_lanes(dist, ax, ay, separable, ix, iy, iz, ox, oy, oz):
    """:func:`plain_in_lanes` of a lobe of roughness (ax, ay) and masking ``separable`` (else
    height-correlated), given apart from a packed row: for callers whose items each have a
    lobe of their own (the renderer's blocks of paths)."""
    return _lobe_at(dist, ax, ay, separable, ix, iy, iz, ox, oy, oz)[0]


@inline_kernel
def density_in_lanes(dist, ax, ay, ix, iy, iz, ox, oy, oz):
    """:func:`pdf_in_lanes` of a lobe of roughness (ax, ay) given apart (see
    :func:`factor_in_lanes`)."""
    v = _visible_density(dist, ax, ay, ix, iy, iz, ox, oy, oz)
    return v if iz > 0.0 and oz > 0.0 else 0.0


@inline_kernel
def draw_in_lanes(dist, ax, ay, ix, iy, iz, u1, u2):
    """wo drawn given wi from the visible normals of a lobe of roughness (ax, ay) given apart
    (see :func:`factor_in_lanes`), and its density: :func:`sample_in_lanes` without its
    horizon test (the caller selects), with selects where :func:`pdf_` branches."""
    hx, hy, hz = sample_visible_normal(dist, ax, ay, ix, iy, iz, u1, u2)
    ox, oy, oz = reflect_about(ix, iy, iz, hx, hy, hz)
    return ox, oy, oz, density_in_lanes(dist, ax, ay, ix, iy, iz, ox, oy, oz)


@inline_kernel
def sample_in_lanes(dist, q, nch, ix, iy, iz, u1, u2):
    """:func:`sample_`'s draw with selects where it branches, inlined into its caller: a loop
    over items that calls it runs in SIMD lanes for GGX (Beckmann's slope search branches).
    Below the horizon (iz <= 0) its numbers are computed and dropped; the density is 0 where
    oz <= 0 (:func:`draw_in_lanes`).
    (sample_ keeps its branches: as a call of this, its rounding moved under fast-math.)"""
    ox, oy, oz, pdf = draw_in_lanes(dist, q[nch], q[nch + 1], ix, iy, iz, u1, u2)
    below = iz <= 0.0
    return 0.0 if below else ox, 0.0 if below else oy, 1.0 if below else oz, pdf


@kernel(linked=OPTIMISED)
def sample_(dist, q, nch, ix, iy, iz, u1, u2):
    if iz <= 0.0:
        return 0.0, 0.0, 1.0, 0.0
    hx, hy, hz = sample_visible_normal(dist, q[nch], q[nch + 1], ix, iy, iz, u1, u2)
    ox, oy, oz = reflect_about(ix, iy, iz, hx, hy, hz)
    if oz <= 0.0:
        return ox, oy, oz, 0.0
    return ox, oy, oz, pdf_(dist, q, nch, ix, iy, iz, ox, oy, oz)


@kernel(linked=OPTIMISED)
def albedo_weight_(dist, q, nch, ix, iy, iz, u1, u2, out):
    """f cos(theta_o) / pdf at the sample drawn from (u1, u2), into ``out[0, :nch]``; returns
    cos(theta_o) and 1 if the sample is above the horizon, else 0 (no weight).

    With f from Walter et al. 2007, eq. 20 and pdf = G1(wi) D / (4 cos_i) (Heitz 2018, eq. 17),
    D and the cosines cancel: the weight is ks F G2 / G1(wi), which is ks F G1(wo) for separable
    masking (Heitz 2014, eq. 98) and ks F (1 + Lambda_i) / (1 + Lambda_i + Lambda_o) for the
    height-correlated form (eq. 99), as the abstract of Heitz & d'Eon 2014 notes of their
    sampler. Neither D nor the pdf is evaluated, which is most of the cost of f cos / pdf.
    """
    if iz <= 0.0:
        return 0.0, 0
    ax = q[nch]
    ay = q[nch + 1]
    hx, hy, hz = sample_visible_normal(dist, ax, ay, ix, iy, iz, u1, u2)
    ox, oy, oz = reflect_about(ix, iy, iz, hx, hy, hz)
    if oz <= 0.0:
        return oz, 0
    if q[nch + 2] == 0.0:
        m = g1(dist, ax, ay, ox, oy, oz)
    else:
        li = smith_lambda(dist, ax, ay, ix, iy, iz)
        m = (1.0 + li) / (1.0 + li + smith_lambda(dist, ax, ay, ox, oy, oz))
    if q[nch + 3] == NONE:
        for c in range(nch):
            out[0, c] = q[c] * m
    else:
        cos_d = ix * hx + iy * hy + iz * hz  # wi.h, h the unit half vector of wi and wo
        for c in range(nch):
            out[0, c] = q[c] * fresnel(q, nch + 3, nch, c, cos_d) * m
    return oz, 1


@kernel(linked=OPTIMISED)
def hint_(q, nch, ix, iy, iz):
    if iz <= 0.0:
        return 0.0
    s = 0.0
    for c in range(nch):
        s += q[c] * fresnel(q, nch + 3, nch, c, iz)
    return s / nch
