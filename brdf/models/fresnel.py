"""Fresnel terms for microfacet lobes: none, Schlick, dielectric and conductor.

Each term is a component with declared parameters (``fresnel=schlick(f0=0.04)`` in a spec). In
kernels a term is a block of ``1 + 2 C`` floats: a mode code, then two per-channel parameters.
"""

import math

from .._jit import OPTIMISED, inline_kernel, kernel
from ._registry import FRESNEL
from .base import Component, Layout, Param

NONE, SCHLICK, DIELECTRIC, CONDUCTOR = 0, 1, 2, 3


class Fresnel(Component):
    """A Fresnel term packed as ``[code, a[C], b[C]]``."""

    code = NONE
    packed = ()  # names of the (up to two) per-channel parameters stored in a and b

    def layout(self, nch):
        layout = Layout()
        layout.values.append(float(self.code))
        for i in range(2):
            if i < len(self.packed):
                decl = self.declaration(self.packed[i])
                layout.append(decl, decl.name, self._values[decl.name], nch)
            else:
                layout.pad(nch)
        return layout


@FRESNEL.register
class NoFresnel(Fresnel):
    name = "none"
    summary = "F = 1 (the Fresnel factor is left to ks)"


@FRESNEL.register
class Schlick(Fresnel):
    name = "schlick"
    summary = "Schlick's approximation F0 + (1 - F0)(1 - cos)^5"
    citation = "Schlick 1994, An Inexpensive BRDF Model for Physically-based Rendering, eq. 15"
    code = SCHLICK
    packed = ("f0",)
    PARAMS = (Param("f0", 0.04, (0.0, 1.0), per_channel=True, doc="reflectance at normal incidence"),)


@FRESNEL.register
class Dielectric(Fresnel):
    name = "dielectric"
    summary = "exact unpolarised Fresnel reflectance of a dielectric interface"
    citation = "Walter et al. 2007, Microfacet Models for Refraction, eq. 22"
    code = DIELECTRIC
    packed = ("eta",)
    PARAMS = (Param("eta", 1.5, (1e-3, 10.0), per_channel=True,
                    doc="relative index of refraction (inside / outside)"),)


@FRESNEL.register
class Conductor(Fresnel):
    name = "conductor"
    summary = "exact unpolarised Fresnel reflectance of a conductor with complex index eta + i k"
    citation = "Born & Wolf, Principles of Optics, 14.2; as in PBR 3rd ed. 8.2.1 (FrConductor)"
    code = CONDUCTOR
    packed = ("eta", "k")
    PARAMS = (Param("eta", 0.2, (1e-3, 10.0), per_channel=True, doc="real part of the index"),
              Param("k", 3.0, (0.0, 20.0), per_channel=True, doc="extinction coefficient"))


@kernel(linked=OPTIMISED)
def schlick_d(f0, cos_i):
    """Schlick's F and dF/dF0 = 1 - (1 - cos)^5 (Schlick 1994, "An Inexpensive BRDF Model for
    Physically-based Rendering", eq. 15, differentiated)."""
    m = 1.0 - cos_i
    m2 = m * m
    m5 = m2 * m2 * m
    return f0 + (1.0 - f0) * m5, 1.0 - m5


@kernel
def schlick(f0, cos_i):
    """Schlick 1994, "An Inexpensive BRDF Model for Physically-based Rendering", eq. 15."""
    return schlick_d(f0, cos_i)[0]


@kernel(linked=OPTIMISED)
def dielectric_reflectance_d(cos_i, eta):
    """F and dF/deta of Walter et al. 2007, eq. 22 (total internal reflection gives 1, dF 0).

    With g = sqrt(eta^2 - 1 + c^2), A = (g - c) / (g + c) and B = (c (g + c) - 1) / (c (g - c) + 1),
    F = A^2 (1 + B^2) / 2, dA/dg = 2 c / (g + c)^2, dB/dg = 2 c (1 - c^2) / (c (g - c) + 1)^2 and
    dg/deta = eta / g.
    """
    c = abs(cos_i)
    g2 = eta * eta - 1.0 + c * c
    if g2 <= 0.0:
        return 1.0, 0.0
    g = math.sqrt(g2)
    a = (g - c) / (g + c)
    den = c * (g - c) + 1.0
    b = (c * (g + c) - 1.0) / den
    da = 2.0 * c / ((g + c) * (g + c))
    db = 2.0 * c * (1.0 - c * c) / (den * den)
    return 0.5 * a * a * (1.0 + b * b), (a * da * (1.0 + b * b) + a * a * b * db) * eta / g


@kernel
def dielectric_reflectance(cos_i, eta):
    """Walter et al. 2007, eq. 22 (total internal reflection gives 1)."""
    return dielectric_reflectance_d(cos_i, eta)[0]


@kernel(linked=OPTIMISED)
def conductor_reflectance_d(cos_i, eta, k):
    """Unpolarised reflectance of a conductor (Born & Wolf 14.2; PBR 3rd ed. FrConductor) and its
    partial derivatives in eta and k, by differentiating each intermediate of that formula
    (forward mode, one tangent per parameter: ``_e`` in eta, ``_k`` in k)."""
    c = min(abs(cos_i), 1.0)
    c2 = c * c
    s2 = 1.0 - c2
    t0 = eta * eta - k * k - s2
    t0_e, t0_k = 2.0 * eta, -2.0 * k
    a2b2 = math.sqrt(t0 * t0 + 4.0 * eta * eta * k * k)
    inv = 1.0 / a2b2 if a2b2 > 0.0 else 0.0
    a2b2_e = (t0 * t0_e + 4.0 * eta * k * k) * inv
    a2b2_k = (t0 * t0_k + 4.0 * eta * eta * k) * inv
    a = math.sqrt(max(0.0, 0.5 * (a2b2 + t0)))
    inv = 0.25 / a if a > 0.0 else 0.0
    a_e, a_k = (a2b2_e + t0_e) * inv, (a2b2_k + t0_k) * inv
    t1 = a2b2 + c2
    t2 = 2.0 * a * c
    rs = (t1 - t2) / (t1 + t2)
    # d((t1 - t2) / (t1 + t2)) = 2 (t2 dt1 - t1 dt2) / (t1 + t2)^2, with dt1 = da2b2, dt2 = 2 c da
    w = 2.0 / ((t1 + t2) * (t1 + t2))
    rs_e = w * (t2 * a2b2_e - t1 * 2.0 * c * a_e)
    rs_k = w * (t2 * a2b2_k - t1 * 2.0 * c * a_k)
    t3 = c2 * a2b2 + s2 * s2
    t4 = t2 * s2
    ratio = (t3 - t4) / (t3 + t4)
    # the same rule for (t3 - t4) / (t3 + t4), with dt3 = c^2 da2b2 and dt4 = 2 c s^2 da
    w = 2.0 / ((t3 + t4) * (t3 + t4))
    ratio_e = w * (t4 * c2 * a2b2_e - t3 * 2.0 * c * s2 * a_e)
    ratio_k = w * (t4 * c2 * a2b2_k - t3 * 2.0 * c * s2 * a_k)
    rp = rs * ratio
    return (0.5 * (rp + rs), 0.5 * (rs_e * ratio + rs * ratio_e + rs_e),
            0.5 * (rs_k * ratio + rs * ratio_k + rs_k))


@kernel
def conductor_reflectance(cos_i, eta, k):
    """Unpolarised reflectance of a conductor (Born & Wolf 14.2; PBR 3rd ed. FrConductor)."""
    return conductor_reflectance_d(cos_i, eta, k)[0]


@inline_kernel
def fresnel_d(q, off, nch, ch, cos_d):
    """Reflectance of the Fresnel block at ``q[off:]`` for channel ``ch`` at cosine ``cos_d``,
    and its partial derivatives in the block's two parameters of that channel,
    ``q[off + 1 + ch]`` and ``q[off + 1 + nch + ch]`` (0 for those a term does not use)."""
    mode = q[off]
    a = q[off + 1 + ch]
    if mode == SCHLICK:
        f, f_a = schlick_d(a, cos_d)
        return f, f_a, 0.0
    if mode == DIELECTRIC:
        f, f_a = dielectric_reflectance_d(cos_d, a)
        return f, f_a, 0.0
    if mode == CONDUCTOR:
        return conductor_reflectance_d(cos_d, a, q[off + 1 + nch + ch])
    return 1.0, 0.0, 0.0


@inline_kernel
def fresnel(q, off, nch, ch, cos_d):
    """Reflectance of the Fresnel block at ``q[off:]`` for channel ``ch`` at cosine ``cos_d``."""
    return fresnel_d(q, off, nch, ch, cos_d)[0]
