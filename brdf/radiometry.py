"""Radiometric quantities: solid angle, flux, irradiance, radiance and intensity.

Units are SI throughout (W, W/m^2, W/(m^2 sr), W/sr; lengths in any consistent unit), angles in
radians. Every function broadcasts its array arguments together. References:
Pharr, Jakob & Humphreys, *Physically Based Rendering*, 4th ed. (PBR4), chapter 4;
Cohen & Wallace, *Radiosity and Realistic Image Synthesis* (1993), chapter 2;
Dutré, *Global Illumination Compendium* (2003), section on solid angles and radiometry.
"""

import numpy as np

from .errors import InputError

__all__ = [
    "solid_angle_cone", "solid_angle_patch", "solid_angle_triangle", "solid_angle_rectangle",
    "point_light_irradiance", "lambertian_emitter_flux", "lambertian_intensity",
    "radiance_from_irradiance", "irradiance_from_radiance",
]

# Dot products of unit vectors may overshoot +-1 by a few ulps; cosines within this are clipped.
COS_SLACK = 1e-9


def _number(where, name, value, low=-np.inf, high=np.inf, strict=False):
    """``value`` as a float array, rejecting NaN and values outside ``[low, high]``
    (``(low, high]`` when ``strict``) with a one-line :class:`~brdf.errors.InputError`."""
    try:
        x = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{where}: {name} must be a number or an array of numbers, "
                         f"got {value!r}") from None
    bad = np.isnan(x) | (x <= low if strict else x < low) | (x > high)
    if np.any(bad):
        interval = f"{'(' if strict else '['}{low:g}, {high:g}]"
        raise InputError(f"{where}: {name} must be in {interval}, got {float(x[bad].flat[0])!r}")
    return x


def _cosine(where, value, name="cos_theta"):
    """Validated cosine clipped to ``[-1, 1]``."""
    return np.clip(_number(where, name, value, -1.0 - COS_SLACK, 1.0 + COS_SLACK), -1.0, 1.0)


def _points(where, name, value):
    """Validated array of points or vectors shaped ``(..., 3)``."""
    x = np.asarray(value, dtype=float)
    if x.ndim == 0 or x.shape[-1] != 3:
        raise InputError(f"{where}: {name} must be shaped (..., 3), got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise InputError(f"{where}: {name} holds NaN or infinite values")
    return x


def _dot(u, v):
    return np.sum(u * v, axis=-1)


def solid_angle_cone(half_angle):
    """Solid angle of a circular cone (a spherical cap seen from the sphere's centre).

    Parameters
    ----------
    half_angle : array_like
        Half opening angle in ``[0, pi]`` (radians).

    Returns
    -------
    ndarray
        ``2 pi (1 - cos(alpha))`` in sr; ``4 pi`` for the whole sphere.
    """
    alpha = _number("solid_angle_cone", "half_angle", half_angle, 0.0, np.pi)
    # 2 pi (1 - cos a) (PBR4 sec. 4.2.2, integrating sin(theta) dtheta dphi), written as
    # 4 pi sin^2(a/2) so that narrow cones keep their digits
    return 4.0 * np.pi * np.sin(0.5 * alpha) ** 2


def solid_angle_patch(area, cos_theta, distance):
    """Solid angle of a small planar patch (small-patch approximation).

    Parameters
    ----------
    area : array_like
        Patch area (>= 0).
    cos_theta : array_like
        Cosine between the patch normal and the direction to the viewpoint; the sign (which
        side faces the viewpoint) does not matter.
    distance : array_like
        Distance from the viewpoint to the patch (> 0).

    Returns
    -------
    ndarray
        ``A |cos(theta)| / r^2`` in sr; accurate while the patch is small against ``r``
        (compare :func:`solid_angle_rectangle`).
    """
    where = "solid_angle_patch"
    area = _number(where, "area", area, 0.0)
    cos_theta = _cosine(where, cos_theta)
    r = _number(where, "distance", distance, 0.0, strict=True)
    return area * np.abs(cos_theta) / r**2  # d omega = dA cos(theta) / r^2 (PBR4 sec. 4.2.3)


def solid_angle_triangle(point, a, b, c):
    """Exact solid angle of a planar triangle seen from a point.

    Parameters
    ----------
    point, a, b, c : array_like, shape (..., 3)
        Viewpoint and triangle vertices, broadcast together.

    Returns
    -------
    ndarray
        Solid angle in ``[0, 2 pi]`` sr, whichever side of the triangle faces the point
        (0 for a point in the triangle's plane outside it).
    """
    where = "solid_angle_triangle"
    p = _points(where, "point", point)
    r1, r2, r3 = (_points(where, name, v) - p for name, v in (("a", a), ("b", b), ("c", c)))
    l1, l2, l3 = (np.linalg.norm(r, axis=-1) for r in (r1, r2, r3))
    triple = _dot(r1, np.cross(r2, r3))
    # Van Oosterom & Strackee 1983, IEEE Trans. Biomed. Eng. 30(2), p. 125:
    # tan(Omega/2) = [r1 r2 r3] / (l1 l2 l3 + (r1.r2) l3 + (r1.r3) l2 + (r2.r3) l1);
    # arctan2 keeps the quadrant when the denominator is negative (Omega > pi)
    den = l1 * l2 * l3 + _dot(r1, r2) * l3 + _dot(r1, r3) * l2 + _dot(r2, r3) * l1
    return 2.0 * np.arctan2(np.abs(triple), den)


def solid_angle_rectangle(point, corner, edge_u, edge_v):
    """Exact solid angle of a planar parallelogram (e.g. a rectangular area light).

    Parameters
    ----------
    point : array_like, shape (..., 3)
        Viewpoint.
    corner : array_like, shape (..., 3)
        One vertex; the others are ``corner + edge_u``, ``corner + edge_u + edge_v`` and
        ``corner + edge_v``.
    edge_u, edge_v : array_like, shape (..., 3)
        The two edges from ``corner``.

    Returns
    -------
    ndarray
        Solid angle in sr: the sum over the two triangles of :func:`solid_angle_triangle`, which
        share an orientation because the parallelogram is planar and convex.
    """
    where = "solid_angle_rectangle"
    c0 = _points(where, "corner", corner)
    u, v = _points(where, "edge_u", edge_u), _points(where, "edge_v", edge_v)
    c2 = c0 + u + v
    return solid_angle_triangle(point, c0, c0 + u, c2) + solid_angle_triangle(point, c0, c2,
                                                                                c0 + v)


def point_light_irradiance(intensity, distance, cos_theta, attenuation=(1.0, 0.0, 0.0)):
    """Irradiance on a surface from an isotropic point light.

    Parameters
    ----------
    intensity : array_like
        Radiant intensity ``I`` of the light (W/sr, >= 0).
    distance : array_like
        Distance ``r`` from the light (>= 0).
    cos_theta : array_like
        Cosine between the surface normal and the direction to the light; lights behind the
        surface (negative cosine) give zero.
    attenuation : (float, float, float)
        ``(a, b, c)``: the quadratic, linear and constant coefficients of the OpenGL-style
        distance falloff ``a r^2 + b r + c`` (all >= 0, not all zero). The default
        ``(1, 0, 0)`` is the physical inverse-square law.

    Returns
    -------
    ndarray
        ``I max(cos(theta), 0) / (a r^2 + b r + c)`` in W/m^2.
    """
    where = "point_light_irradiance"
    intensity = _number(where, "intensity", intensity, 0.0)
    r = _number(where, "distance", distance, 0.0)
    cos_theta = _cosine(where, cos_theta)
    a, b, c = _attenuation(where, attenuation)
    falloff = a * r**2 + b * r + c
    if np.any(falloff <= 0.0):
        raise InputError(f"{where}: a r^2 + b r + c must be > 0; the light sits on the surface "
                         "point (distance 0) with no constant attenuation term")
    # E = I cos(theta) / r^2 (PBR4 sec. 4.1.1, intensity and irradiance; sec. 12.1 point lights);
    # r^2 generalised to k_q r^2 + k_l r + k_c (OpenGL 2.1 specification, sec. 2.14.1)
    return intensity * np.maximum(cos_theta, 0.0) / falloff


def _attenuation(where, attenuation):
    """Validated ``(a, b, c)`` attenuation coefficients."""
    coefficients = _number(where, "attenuation", attenuation, 0.0)
    if coefficients.shape != (3,) or not np.all(np.isfinite(coefficients)):
        raise InputError(f"{where}: attenuation must be three finite numbers (a, b, c), "
                         f"got {attenuation!r}")
    return coefficients


def lambertian_emitter_flux(radiance, area):
    """Total flux leaving a Lambertian (uniform-radiance) emitter on one side.

    Parameters
    ----------
    radiance : array_like
        Emitted radiance ``L`` (>= 0).
    area : array_like
        Emitting area ``A`` (>= 0).

    Returns
    -------
    ndarray
        ``pi A L`` in W.
    """
    where = "lambertian_emitter_flux"
    radiance = _number(where, "radiance", radiance, 0.0)
    area = _number(where, "area", area, 0.0)
    # Phi = A int L cos(theta) d omega = pi A L (Cohen & Wallace 1993, ch. 2; PBR4 sec. 4.2.1)
    return np.pi * area * radiance


def lambertian_intensity(radiance, area, cos_theta):
    """Radiant intensity of a small flat Lambertian emitter in one direction.

    Parameters
    ----------
    radiance : array_like
        Emitted radiance ``L`` (>= 0).
    area : array_like
        Emitting area ``A`` (>= 0).
    cos_theta : array_like
        Cosine between the emitter normal and the direction; behind the emitter gives zero.

    Returns
    -------
    ndarray
        ``L A max(cos(theta), 0)`` in W/sr (Lambert's cosine law).
    """
    where = "lambertian_intensity"
    radiance = _number(where, "radiance", radiance, 0.0)
    area = _number(where, "area", area, 0.0)
    cos_theta = _cosine(where, cos_theta)
    # I = d Phi / d omega = L A cos(theta) (PBR4 sec. 4.1.1, radiance definition integrated over A)
    return radiance * area * np.maximum(cos_theta, 0.0)


def radiance_from_irradiance(irradiance, albedo):
    """Radiance reflected by a Lambertian surface.

    Parameters
    ----------
    irradiance : array_like
        Incident irradiance ``E`` (>= 0).
    albedo : array_like
        Diffuse reflectance ``rho`` in ``[0, 1]``.

    Returns
    -------
    ndarray
        ``rho E / pi`` in W/(m^2 sr), the same in every outgoing direction.
    """
    where = "radiance_from_irradiance"
    irradiance = _number(where, "irradiance", irradiance, 0.0)
    albedo = _number(where, "albedo", albedo, 0.0, 1.0)
    # L_o = int (rho / pi) L_i cos(theta) d omega = rho E / pi (Cohen & Wallace 1993, ch. 2)
    return albedo * irradiance / np.pi


def irradiance_from_radiance(radiance, half_angle=np.pi / 2):
    """Irradiance from uniform radiance arriving within a cone about the normal.

    Parameters
    ----------
    radiance : array_like
        Incident radiance ``L`` (>= 0), the same from every direction of the cone.
    half_angle : array_like
        Half opening angle of the cone in ``[0, pi/2]``; the default ``pi/2`` is a uniform sky
        (the whole hemisphere). A disc light of radius ``R`` centred on the normal at distance
        ``d`` is the cone with ``sin(alpha) = R / sqrt(R^2 + d^2)``.

    Returns
    -------
    ndarray
        ``pi L sin^2(alpha)`` in W/m^2; ``pi L`` for a uniform sky.
    """
    where = "irradiance_from_radiance"
    radiance = _number(where, "radiance", radiance, 0.0)
    alpha = _number(where, "half_angle", half_angle, 0.0, np.pi / 2)
    # E = int_0^{2 pi} int_0^alpha L cos(theta) sin(theta) d theta d phi = pi L sin^2(alpha)
    # (PBR4 sec. 4.2.2; the cone's projected solid angle, Nusselt analog, Cohen & Wallace ch. 4)
    return np.pi * radiance * np.sin(alpha) ** 2
