"""One generalised cosine lobe of Lafortune, Foo, Torrance & Greenberg 1997.

f = max(0, Cx wi_x wo_x + Cy wi_y wo_y + Cz wi_z wo_z)^n  ("Non-Linear Approximation of
Reflectance Functions", SIGGRAPH 1997, eqs. 3-4, with the matrix diagonal in the local frame).

Cx = Cy = -1, Cz = 1 is a Phong lobe about the mirror direction, Cx = Cy = Cz > 0 a retro-reflective
lobe, |Cx| = |Cy| < Cz an off-specular one. The paper fits the coefficients per colour channel;
a fit with several lobes is a sum (``lafortune(...) + lafortune(...)``), its diffuse part a
``lambert`` lobe. The magnitude of C carries the lobe's scale, so the family conserves energy only
for some coefficients (the energy checks evaluate it).

Sampling draws wo from a cos^m lobe about s / |s|, s = (Cx wi_x, Cy wi_y, Cz wi_z), with the
channel means of C and the smallest channel exponent m: f = |s|^n cos^n(angle to s), so when the
channels share an axis the weight f cos / pdf ~ cos^(n - m) stays bounded in every channel (a
mean exponent would give the broader channels heavy tails the pdf cannot cover).
"""

import math

import numpy as np

from .._jit import OPTIMISED, inline_kernel, kernel
from ..errors import ParameterError
from ..sampling import cosine_power_pdf, from_axis_frame, square_to_cosine_power
from . import _kinds
from ._registry import register
from .base import Model, Param, Start
from .packed import channel_mean

#: Cap of the albedo hint: keeps an unnormalised lobe (|s| > 1, large n) from turning the
#: lobe-selection weights of a sum into inf / inf.
HINT_MAX = 1e6
#: Largest log of the peak value max(|C|)^n that double precision holds with room to spare.
MAX_LOG_PEAK = 690.0


@register
class Lafortune(Model):
    """A generalised cosine lobe with per-channel coefficients ``cx, cy, cz`` and exponent ``n``."""

    name = "lafortune"
    aliases = ("cosine-lobe",)
    summary = "generalised cosine lobe, f = max(0, Cx ix ox + Cy iy oy + Cz iz oz)^n"
    citation = ("Lafortune, Foo, Torrance & Greenberg 1997, Non-Linear Approximation of "
                "Reflectance Functions, eqs. 3-4")
    kind = _kinds.LAFORTUNE
    mirror_symmetric = True  # wi_x wo_x and wi_y wo_y keep their signs under M
    energy_conserving = False
    # n gets a log prior: it sets the lobe width (about 1/sqrt(n)), so equal prior mass per
    # decade treats n = 2 and n = 2000 alike; a log scale needs a positive floor, and n = 0.01
    # (cos^0.01 is within 2% of the constant n = 0 lobe up to 80 degrees off the axis) is one.
    PARAMS = (
        Param("cx", -1.0, per_channel=True, fit_bounds=(-5.0, 5.0),
              doc="coefficient of wi_x wo_x (negative for forward scattering)"),
        Param("cy", -1.0, per_channel=True, fit_bounds=(-5.0, 5.0),
              doc="coefficient of wi_y wo_y (differs from cx for an anisotropic lobe)"),
        Param("cz", 1.0, per_channel=True, fit_bounds=(-5.0, 5.0),
              doc="coefficient of wi_z wo_z"),
        Param("n", 20.0, (0.0, 1e5), per_channel=True, prior="log", aliases=("exponent",),
              fit_bounds=(1e-2, 1e4), doc="exponent (larger is a narrower lobe)"),
    )
    # f = (C . w)^n: multiplying C by k^(1/n) multiplies f by k (eq. 4); the lobes of section 4:
    # forward (Cx = Cy < 0 < Cz), retro-reflective (Cx = Cy > 0) and diffuse-like (Cx = Cy = 0)
    START = Start(scale=("cx", "cy", "cz"), shape=("n",), power="n",
                  directions=((-1.0, -1.0, 1.0), (1.0, 1.0, 1.0), (0.0, 0.0, 1.0)))

    @property
    def is_anisotropic(self):
        return bool((self["cx"] != self["cy"]).any())

    def _check(self):
        log_peak = _log_peak(self["cx"], self["cy"], self["cz"], self["n"])
        if np.any(log_peak > MAX_LOG_PEAK):
            raise ParameterError(f"{self.name}: max(|cx|, |cy|, |cz|)^n = e^{np.max(log_peak):.0f} "
                                 f"overflows double precision; need it below e^{MAX_LOG_PEAK:.0f}")


    @staticmethod
    def admissible(q, nch):
        """Whether the packed block ``q`` (cx, cy, cz, n per channel) is a lobe ``_check``
        accepts: the fitter treats other points of its box as infinitely bad."""
        q = np.asarray(q)
        return bool(np.all(_log_peak(q[:nch], q[nch:2 * nch], q[2 * nch:3 * nch],
                                     q[3 * nch:4 * nch]) <= MAX_LOG_PEAK))


def _log_peak(cx, cy, cz, n):
    """log of the peak value max(|Cx|, |Cy|, |Cz|)^n (wi = wo along that axis): past double
    precision the lobe would evaluate to inf, which no fit or render can use."""
    peak = np.max(np.broadcast_arrays(*(np.abs(np.asarray(c, float)) for c in (cx, cy, cz))),
                  axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.asarray(n, float) * np.log(peak)


# --- kernels (layout: cx[C], cy[C], cz[C], n[C]) ---------------------------------------------

@kernel(linked=OPTIMISED)
def _axis(q, nch, ix, iy, iz):
    """Sampling lobe: unit axis s / |s| of the channel-mean C (+z if s = 0), smallest exponent."""
    sx = channel_mean(q, 0, nch) * ix
    sy = channel_mean(q, nch, nch) * iy
    sz = channel_mean(q, 2 * nch, nch) * iz
    norm = math.sqrt(sx * sx + sy * sy + sz * sz)
    n = q[3 * nch]
    for c in range(1, nch):
        n = min(n, q[3 * nch + c])
    if norm <= 0.0:
        return 0.0, 0.0, 1.0, n
    return sx / norm, sy / norm, sz / norm, n


@inline_kernel
def _channel(q, nch, c, px, py, pz):
    """The lobe's dot product Cx px + Cy py + Cz pz of channel c (Lafortune et al. 1997, eq. 4)
    and its power f = max(0, dot)^n."""
    dot = q[c] * px + q[nch + c] * py + q[2 * nch + c] * pz
    return dot, dot ** q[3 * nch + c] if dot > 0.0 else 0.0


@inline_kernel
def eval_(q, nch, ix, iy, iz, ox, oy, oz, out, k):
    if iz <= 0.0 or oz <= 0.0:
        return
    px, py, pz = ix * ox, iy * oy, iz * oz
    for c in range(nch):
        out[k, c] += _channel(q, nch, c, px, py, pz)[1]


@inline_kernel
def grad_(q, nch, ix, iy, iz, ox, oy, oz, out, k, d):
    """Add f = max(0, dot)^n (eq. 4) to ``out[k]`` and its derivatives into ``d``:
    df/dC_x = n dot^(n-1) wi_x wo_x (likewise y, z) and df/dn = dot^n ln(dot), 0 where dot <= 0."""
    above = iz > 0.0 and oz > 0.0
    px, py, pz = ix * ox, iy * oy, iz * oz
    for c in range(nch):
        dot, f = _channel(q, nch, c, px, py, pz)
        live = above and f > 0.0
        f = f if live else 0.0
        slope = q[3 * nch + c] * f / dot if live else 0.0  # n dot^(n-1)
        out[k, c] += f
        d[c, k, c] = slope * px
        d[nch + c, k, c] = slope * py
        d[2 * nch + c, k, c] = slope * pz
        d[3 * nch + c, k, c] = f * math.log(dot) if live else 0.0


@kernel(linked=OPTIMISED)
def pdf_(q, nch, ix, iy, iz, ox, oy, oz):
    if iz <= 0.0 or oz <= 0.0:
        return 0.0
    ax, ay, az, n = _axis(q, nch, ix, iy, iz)
    return cosine_power_pdf(ax * ox + ay * oy + az * oz, n)


@kernel(linked=OPTIMISED)
def sample_(q, nch, ix, iy, iz, u1, u2):
    ax, ay, az, n = _axis(q, nch, ix, iy, iz)
    lx, ly, lz = square_to_cosine_power(u1, u2, n)
    ox, oy, oz = from_axis_frame(lx, ly, lz, ax, ay, az)
    if iz <= 0.0 or oz <= 0.0:
        return ox, oy, oz, 0.0
    return ox, oy, oz, cosine_power_pdf(lz, n)


@kernel(linked=OPTIMISED)
def hint_(q, nch, ix, iy, iz):
    """Channel mean of |s|^n 2 pi / (n + 2) max(0, s_z / |s|), each channel's lobe albedo if it
    lay wholly above the horizon (the integral of cos^n about s times cos(theta_o))."""
    if iz <= 0.0:
        return 0.0
    total = 0.0
    for c in range(nch):
        sx = q[c] * ix
        sy = q[nch + c] * iy
        sz = q[2 * nch + c] * iz
        norm = math.sqrt(sx * sx + sy * sy + sz * sz)
        if norm > 0.0 and sz > 0.0:
            n = q[3 * nch + c]
            total += min(norm ** n * 2.0 * math.pi / (n + 2.0) * sz / norm, HINT_MAX)
    return total / nch
