"""Warps from the unit square to directions, shared by the models and the renderer.

Scalar numba kernels: each takes uniform numbers ``u1, u2`` in ``[0, 1)`` and returns a direction
``(x, y, z)`` in a local frame and, where useful, its solid-angle pdf.
"""

import math

from ._jit import kernel

INV_PI = 1.0 / math.pi


@kernel
def square_to_disk_concentric(u1, u2):
    """Shirley & Chiu 1997, "A Low Distortion Map Between Disk and Square", section 3."""
    a = 2.0 * u1 - 1.0
    b = 2.0 * u2 - 1.0
    if a == 0.0 and b == 0.0:
        return 0.0, 0.0
    if a * a > b * b:
        r = a
        phi = (math.pi / 4.0) * (b / a)
    else:
        r = b
        phi = (math.pi / 2.0) - (math.pi / 4.0) * (a / b)
    return r * math.cos(phi), r * math.sin(phi)


@kernel
def square_to_cosine_hemisphere(u1, u2):
    """Malley's method: project the concentric disk up; pdf = cos(theta) / pi (PBR 4th ed. 13.6.3)."""
    x, y = square_to_disk_concentric(u1, u2)
    z = math.sqrt(max(0.0, 1.0 - x * x - y * y))
    return x, y, z


@kernel
def square_to_cosine_power(u1, u2, n):
    """Direction about +z with density (n + 1) / (2 pi) cos^n(theta): cos(theta) = u1^(1/(n+1))."""
    z = (1.0 - u1) ** (1.0 / (n + 1.0))
    s = math.sqrt(max(0.0, 1.0 - z * z))
    phi = 2.0 * math.pi * u2
    return s * math.cos(phi), s * math.sin(phi), z


@kernel
def cosine_power_pdf(cos_theta, n):
    """Density of :func:`square_to_cosine_power` in solid angle."""
    if cos_theta <= 0.0:
        return 0.0
    return (n + 1.0) / (2.0 * math.pi) * cos_theta ** n


@kernel
def basis_from_axis(ax, ay, az):
    """Tangent and bitangent of a unit axis (Duff et al. 2017, JCGT 6(1), listing 3)."""
    sign = 1.0 if az >= 0.0 else -1.0
    a = -1.0 / (sign + az)
    b = ax * ay * a
    return (1.0 + sign * ax * ax * a, sign * b, -sign * ax), (b, sign + ay * ay * a, -ay)


@kernel
def from_axis_frame(x, y, z, ax, ay, az):
    """Map local ``(x, y, z)`` given about +z into the frame whose pole is the axis ``a``."""
    t, b = basis_from_axis(ax, ay, az)
    return (x * t[0] + y * b[0] + z * ax,
            x * t[1] + y * b[1] + z * ay,
            x * t[2] + y * b[2] + z * az)


@kernel
def reflect_about(ix, iy, iz, hx, hy, hz):
    """Mirror ``i`` about the unit axis ``h``: 2 (i.h) h - i."""
    d = 2.0 * (ix * hx + iy * hy + iz * hz)
    return d * hx - ix, d * hy - iy, d * hz - iz


@kernel
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
