"""Warps from the unit square to directions, shared by the models and the renderer, and the
polynomial sine, cosine and arctangent that they and the renderer's lookups use.

Scalar numba kernels: each warp takes uniform numbers ``u1, u2`` in ``[0, 1)`` and returns a
direction ``(x, y, z)`` in a local frame and, where useful, its solid-angle pdf.
"""

import math

from ._jit import OPTIMISED, inline_kernel, kernel

INV_PI = 1.0 / math.pi


# sin and cos as polynomials: the samplers need both of one angle, and libm's pair of calls cost
# 20-25 ns where the polynomials take 5 (branch-free, so they also run in SIMD lanes).
# Minimax coefficients of Cephes (Moshier 1989, "Methods and Programs for Mathematical
# Functions", sin.c) for |x| <= pi/4: sin x = x + x^3 P(x^2), cos x = 1 - x^2/2 + x^4 Q(x^2).
_SIN = (1.58962301576546568060e-10, -2.50507477628578072866e-8, 2.75573136213857245213e-6,
        -1.98412698295895385996e-4, 8.33333333332211858878e-3, -1.66666666666666307295e-1)
_COS = (-1.13585365213876817300e-11, 2.08757008419747316778e-9, -2.75573141792967388112e-7,
        2.48015872888517045348e-5, -1.38888888888730564116e-3, 4.16666666666665929218e-2)


@kernel(linked=OPTIMISED)
def sincos_octant(x):
    """``(sin x, cos x)`` for |x| <= pi/4, within 1 ulp of libm's."""
    z = x * x
    ps = (((((_SIN[0] * z + _SIN[1]) * z + _SIN[2]) * z + _SIN[3]) * z + _SIN[4]) * z
          + _SIN[5])
    pc = (((((_COS[0] * z + _COS[1]) * z + _COS[2]) * z + _COS[3]) * z + _COS[4]) * z
          + _COS[5])
    return x + x * z * ps, 1.0 - 0.5 * z + z * z * pc


# The arctangent as a polynomial: libm's atan2 costs 26-28 ns a call (a MERL-grid lookup makes
# three), where the polynomial takes 1 ns in SIMD lanes.
# atan r = r + r^3 P(r^2) for |r| <= tan(pi/8) (Abramowitz & Stegun 1964, 4.4.42), P the
# Chebyshev interpolant of degree 10 of the series' remainder (atan s - s) / s^3 in t = s^2 on
# [0, tan^2(pi/8)] (numpy.polynomial.chebyshev.Chebyshev.interpolate), in powers of t.
_ATAN = (-0.3333333333333327, 0.19999999999954654, -0.14285714278306827, 0.11111110596745237,
         -0.0909088993853778, 0.0769188120783656, -0.06660656571035933, 0.05827357429554711,
         -0.049356523858863424, 0.03517335366632264, -0.014482933736871916)
_TAN_PI_8 = math.sqrt(2.0) - 1.0


@inline_kernel
def arctan2(y, x):
    """``atan2(y, x)`` for finite y and x, within 3 ulp of libm's (signed zeros as libm). The
    ratio of the smaller to the larger magnitude r lies in [0, 1]; above tan(pi/8), atan r =
    pi/4 + atan((r - 1) / (r + 1)) (A&S 4.4.34) brings it within the polynomial's range with the
    same one division. Selects, not branches: the octant of a direction is a coin toss."""
    ax, ay = abs(x), abs(y)
    steep = ay > ax
    n = ax if steep else ay
    d = ay if steep else ax
    wide = n > _TAN_PI_8 * d
    num = n - d if wide else n
    den = n + d if wide else d
    r = num / den if den > 0.0 else 0.0
    t = r * r
    # Estrin's scheme: a chain of 4 multiply-adds rather than Horner's 10 (a lookup calls this
    # on one lane at a time, and waits on it)
    t2 = t * t
    t4 = t2 * t2
    p = ((_ATAN[0] + _ATAN[1] * t) + t2 * (_ATAN[2] + _ATAN[3] * t)
         + t4 * ((_ATAN[4] + _ATAN[5] * t) + t2 * (_ATAN[6] + _ATAN[7] * t))
         + t4 * t4 * ((_ATAN[8] + _ATAN[9] * t) + t2 * _ATAN[10]))
    a = r + r * t * p + (0.25 * math.pi if wide else 0.0)
    a = 0.5 * math.pi - a if steep else a
    a = math.pi - a if math.copysign(1.0, x) < 0.0 else a
    return math.copysign(a, y)


@inline_kernel
def arccos(z):
    """``acos(z)`` for z in [-1, 1] (clamped), as arctan2(sqrt((1 - z)(1 + z)), z): the
    factored form keeps sin's accuracy near z = 1."""
    z = min(max(z, -1.0), 1.0)
    return arctan2(math.sqrt((1.0 - z) * (1.0 + z)), z)


@kernel(linked=OPTIMISED)
def sincos_turn(u):
    """``(sin 2 pi u, cos 2 pi u)``, u an angle in turns (the azimuth of a uniform number, or
    any other, negative too): u less its nearest quarter turn k / 4 (exact: the two are within
    a factor of 2, Sterbenz's lemma) through :func:`sincos_octant`, then rotated by k quarter
    turns."""
    k = math.floor(4.0 * u + 0.5)
    s, c = sincos_octant((2.0 * math.pi) * (u - 0.25 * k))
    quarter = int(k) & 3
    odd = (quarter & 1) != 0
    flip = 1.0 if quarter < 2 else -1.0  # quarter k: sin(x + k pi/2), cos(x + k pi/2)
    return flip * (c if odd else s), flip * (-s if odd else c)


@kernel(linked=OPTIMISED)
def square_to_disk_concentric(u1, u2):
    """Shirley & Chiu 1997, "A Low Distortion Map Between Disk and Square", section 3."""
    a = 2.0 * u1 - 1.0
    b = 2.0 * u2 - 1.0
    # selects, not branches: which wedge a sample lies in is a coin toss, and a loop of warps
    # runs in SIMD lanes (the centre, a = b = 0, maps to r = 0 through a ratio of 0)
    wide = a * a > b * b
    r = a if wide else b
    # phi = pi/4 b/a where |a| > |b|, else pi/2 - pi/4 a/b: the second swaps sin and cos
    ratio = (b if wide else a) / r if r != 0.0 else 0.0
    s, c = sincos_octant((math.pi / 4.0) * ratio)
    return r * (c if wide else s), r * (s if wide else c)


@kernel(linked=OPTIMISED)
def square_to_cosine_hemisphere(u1, u2):
    """Malley's method: project the concentric disk up; pdf = cos(theta) / pi (PBR 4th ed. 13.6.3)."""
    x, y = square_to_disk_concentric(u1, u2)
    z = math.sqrt(max(0.0, 1.0 - x * x - y * y))
    return x, y, z


@kernel(linked=OPTIMISED)
def square_to_cosine_power(u1, u2, n):
    """Direction about +z with density (n + 1) / (2 pi) cos^n(theta): cos(theta) = u1^(1/(n+1))."""
    z = (1.0 - u1) ** (1.0 / (n + 1.0))
    s = math.sqrt(max(0.0, 1.0 - z * z))
    sin_phi, cos_phi = sincos_turn(u2)
    return s * cos_phi, s * sin_phi, z


@kernel(linked=OPTIMISED)
def cosine_power_pdf(cos_theta, n):
    """Density of :func:`square_to_cosine_power` in solid angle."""
    if cos_theta <= 0.0:
        return 0.0
    return (n + 1.0) / (2.0 * math.pi) * cos_theta ** n


@kernel(linked=OPTIMISED)
def basis_from_axis(ax, ay, az):
    """Tangent and bitangent of a unit axis (Duff et al. 2017, JCGT 6(1), listing 3)."""
    sign = 1.0 if az >= 0.0 else -1.0
    a = -1.0 / (sign + az)
    b = ax * ay * a
    return (1.0 + sign * ax * ax * a, sign * b, -sign * ax), (b, sign + ay * ay * a, -ay)


@kernel(linked=OPTIMISED)
def from_axis_frame(x, y, z, ax, ay, az):
    """Map local ``(x, y, z)`` given about +z into the frame whose pole is the axis ``a``."""
    t, b = basis_from_axis(ax, ay, az)
    return (x * t[0] + y * b[0] + z * ax,
            x * t[1] + y * b[1] + z * ay,
            x * t[2] + y * b[2] + z * az)


@kernel(linked=OPTIMISED)
def reflect_about(ix, iy, iz, hx, hy, hz):
    """Mirror ``i`` about the unit axis ``h``: 2 (i.h) h - i."""
    d = 2.0 * (ix * hx + iy * hy + iz * hz)
    return d * hx - ix, d * hy - iy, d * hz - iz


@kernel(linked=OPTIMISED)
def half_unit(ix, iy, iz, ox, oy, oz):
    """Normalised half vector and the cosine ``i.h``; a zero vector when ``i = -o``."""
    hx = ix + ox
    hy = iy + oy
    hz = iz + oz
    n2 = hx * hx + hy * hy + hz * hz
    if n2 <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    inv = 1.0 / math.sqrt(n2)
    hx *= inv
    hy *= inv
    hz *= inv
    return hx, hy, hz, ix * hx + iy * hy + iz * hz
