"""Directions, frames and angle parametrisations.

Conventions (DESIGN.md section 1): local shading frame with z the normal, x the tangent and y the
bitangent; unit directions in arrays shaped ``(..., 3)`` pointing away from the surface; polar
angle ``theta`` from +z, azimuth ``phi`` from +x towards +y; radians throughout.
"""

import numpy as np

from .errors import InputError

__all__ = [
    "spherical_to_cartesian", "cartesian_to_spherical", "normalize", "frame_from_normal",
    "to_local", "to_world", "reflect", "half_vector", "half_diff_from_directions",
    "directions_from_half_diff", "rotate",
]


def normalize(v):
    """Return ``v / |v|`` along the last axis (zero vectors stay zero)."""
    v = np.asarray(v, dtype=float)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)


def spherical_to_cartesian(theta, phi):
    """Unit vectors ``(..., 3)`` from polar angle ``theta`` and azimuth ``phi`` (radians)."""
    theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def cartesian_to_spherical(v):
    """``(theta, phi)`` of directions ``(..., 3)``; ``phi`` in ``[0, 2 pi)``."""
    v = np.asarray(v, dtype=float)
    theta = np.arccos(np.clip(v[..., 2] / np.linalg.norm(v, axis=-1), -1.0, 1.0))
    phi = np.mod(np.arctan2(v[..., 1], v[..., 0]), 2.0 * np.pi)
    return theta, phi


def frame_from_normal(n, tangent=None):
    """Orthonormal frame ``(t, b, n)`` as three ``(..., 3)`` arrays.

    With ``tangent`` the tangent is its Gram-Schmidt projection into the plane normal to ``n``;
    without it a continuous-enough tangent is built by Duff et al. 2017, "Building an Orthonormal
    Basis, Revisited" (JCGT 6(1)), listing 3.
    """
    n = normalize(n)
    if tangent is not None:
        t = np.asarray(tangent, dtype=float)
        t = normalize(t - np.sum(t * n, axis=-1, keepdims=True) * n)
        if np.any(np.linalg.norm(t, axis=-1) == 0):
            raise InputError("frame_from_normal: tangent is parallel to the normal")
        return t, np.cross(n, t), n
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    sign = np.where(z >= 0, 1.0, -1.0)  # Duff et al. 2017, listing 3
    a = -1.0 / (sign + z)
    b = x * y * a
    t = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=-1)
    bt = np.stack([b, sign + y * y * a, -y], axis=-1)
    return t, bt, n


def to_local(v, frame):
    """Coordinates of world vectors ``v`` in the frame ``(t, b, n)``."""
    t, b, n = frame
    v = np.asarray(v, dtype=float)
    return np.stack([np.sum(v * t, -1), np.sum(v * b, -1), np.sum(v * n, -1)], axis=-1)


def to_world(v, frame):
    """World vectors from local coordinates ``v`` in the frame ``(t, b, n)``."""
    t, b, n = frame
    v = np.asarray(v, dtype=float)
    return v[..., 0:1] * t + v[..., 1:2] * b + v[..., 2:3] * n


def reflect(v, n=(0.0, 0.0, 1.0)):
    """Mirror ``v`` about the axis ``n`` (the normal, or a half vector): ``2 (v.n) n - v``."""
    v = np.asarray(v, dtype=float)
    n = np.asarray(n, dtype=float)
    return 2.0 * np.sum(v * n, axis=-1, keepdims=True) * n - v


def half_vector(wi, wo):
    """Normalised half vector ``(wi + wo) / |wi + wo|``."""
    return normalize(np.asarray(wi, float) + np.asarray(wo, float))


def rotate(v, axis, angle):
    """Rotate vectors ``v`` about a unit ``axis`` by ``angle`` (Rodrigues' formula)."""
    v = np.asarray(v, dtype=float)
    k = np.asarray(axis, dtype=float)
    c, s = np.cos(angle)[..., None], np.sin(angle)[..., None]
    return v * c + np.cross(k, v) * s + k * np.sum(k * v, -1, keepdims=True) * (1.0 - c)


def half_diff_from_directions(wi, wo):
    """Rusinkiewicz coordinates ``(theta_h, phi_h, theta_d, phi_d)`` of direction pairs.

    Rusinkiewicz 1998, "A New Change of Variables for Efficient BRDF Representation", section 3:
    the difference vector is ``wi`` rotated into the frame where the half vector is the pole,
    i.e. by ``-phi_h`` about the normal, then by ``-theta_h`` about the bitangent.
    """
    h = half_vector(wi, wo)
    theta_h, phi_h = cartesian_to_spherical(h)
    z = np.array([0.0, 0.0, 1.0])
    y = np.array([0.0, 1.0, 0.0])
    d = rotate(rotate(np.asarray(wi, float), z, -phi_h), y, -theta_h)
    theta_d, phi_d = cartesian_to_spherical(d)
    return theta_h, phi_h, theta_d, phi_d


def directions_from_half_diff(theta_h, phi_h, theta_d, phi_d):
    """Inverse of :func:`half_diff_from_directions`: ``(wi, wo)`` from Rusinkiewicz angles."""
    theta_h, phi_h, theta_d, phi_d = np.broadcast_arrays(
        *(np.asarray(a, float) for a in (theta_h, phi_h, theta_d, phi_d)))
    d = spherical_to_cartesian(theta_d, phi_d)
    h = spherical_to_cartesian(theta_h, phi_h)
    z = np.array([0.0, 0.0, 1.0])
    y = np.array([0.0, 1.0, 0.0])
    wi = rotate(rotate(d, y, theta_h), z, phi_h)
    return wi, reflect(wi, h)
