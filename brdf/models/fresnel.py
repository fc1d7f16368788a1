"""Fresnel terms for microfacet lobes: none, Schlick, dielectric and conductor.

Each term is a component with declared parameters (``fresnel=schlick(f0=0.04)`` in a spec). In
kernels a term is a block of ``1 + 2 C`` floats: a mode code, then two per-channel parameters.
"""

import math

from .._jit import inline_kernel
from ._registry import FRESNEL
from .base import Component, Param

NONE, SCHLICK, DIELECTRIC, CONDUCTOR = 0, 1, 2, 3


class Fresnel(Component):
    """A Fresnel term packed as ``[code, a[C], b[C]]``."""

    code = NONE
    packed = ()  # names of the (up to two) per-channel parameters stored in a and b

    def pack(self, nch):
        out = [float(self.code)]
        for i in range(2):
            if i < len(self.packed):
                out.extend(self._pack_value(self.declaration(self.packed[i]), nch))
            else:
                out.extend([0.0] * nch)
        return out


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


@inline_kernel
def schlick(f0, cos_i):
    """Schlick 1994, "An Inexpensive BRDF Model for Physically-based Rendering", eq. 15."""
    m = 1.0 - cos_i
    m2 = m * m
    return f0 + (1.0 - f0) * m2 * m2 * m


@inline_kernel
def dielectric_reflectance(cos_i, eta):
    """Walter et al. 2007, eq. 22 (total internal reflection gives 1)."""
    c = abs(cos_i)
    g2 = eta * eta - 1.0 + c * c
    if g2 <= 0.0:
        return 1.0
    g = math.sqrt(g2)
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return 0.5 * a * a * (1.0 + b * b)


@inline_kernel
def conductor_reflectance(cos_i, eta, k):
    """Unpolarised reflectance of a conductor (Born & Wolf 14.2; PBR 3rd ed. FrConductor)."""
    c = min(abs(cos_i), 1.0)
    c2 = c * c
    s2 = 1.0 - c2
    t0 = eta * eta - k * k - s2
    a2b2 = math.sqrt(t0 * t0 + 4.0 * eta * eta * k * k)
    a = math.sqrt(max(0.0, 0.5 * (a2b2 + t0)))
    t1 = a2b2 + c2
    t2 = 2.0 * a * c
    rs = (t1 - t2) / (t1 + t2)
    t3 = c2 * a2b2 + s2 * s2
    t4 = t2 * s2
    rp = rs * (t3 - t4) / (t3 + t4)
    return 0.5 * (rp + rs)


@inline_kernel
def fresnel(q, off, nch, ch, cos_d):
    """Reflectance of the Fresnel block at ``q[off:]`` for channel ``ch`` at cosine ``cos_d``."""
    mode = q[off]
    a = q[off + 1 + ch]
    if mode == SCHLICK:
        return schlick(a, cos_d)
    if mode == DIELECTRIC:
        return dielectric_reflectance(cos_d, a)
    if mode == CONDUCTOR:
        return conductor_reflectance(cos_d, a, q[off + 1 + nch + ch])
    return 1.0

