"""Directions, frames and angle parametrisations.

Conventions (DESIGN.md section 1): local shading frame with z the normal, x the tangent and y the
bitangent; unit directions in arrays shaped ``(..., 3)`` pointing away from the surface; polar
angle ``theta`` from +z, azimuth ``phi`` from +x towards +y; radians throughout, degrees only
through :func:`directions_from_degrees` and :func:`degrees_from_directions` at the I/O edge.
"""

import numpy as np

from .errors import InputError

__all__ = [
    "spherical_to_cartesian", "cartesian_to_spherical", "directions_from_degrees",
    "degrees_from_directions", "normalize", "frame_from_normal", "to_local", "to_world", "reflect",
    "half_vector", "half_diff_from_directions", "directions_from_half_diff", "rotate",
    "direction_array", "flat_pairs",
]

TWO_PI = 2.0 * np.pi

# Below this sine of the polar angle the azimuth is rounding noise; the pole convention phi = 0
# then makes Rusinkiewicz angles of wi = wo and of normal-incidence pairs deterministic.
POLE_SINE = 1e-14

# A tangent closer to the normal than this (sine of the angle) does not define a direction.
PARALLEL_SINE = 1e-6

Y_AXIS = np.array([0.0, 1.0, 0.0])
Z_AXIS = np.array([0.0, 0.0, 1.0])
Y_AXIS.setflags(write=False)
Z_AXIS.setflags(write=False)


def normalize(v):
    """Return ``v / |v|`` along the last axis; zero vectors stay zero."""
    v = np.asarray(v, dtype=float)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)


def spherical_to_cartesian(theta, phi):
    """Unit vectors from spherical angles.

    Parameters
    ----------
    theta, phi : array_like
        Polar angle from +z and azimuth from +x towards +y, in radians; broadcast together.

    Returns
    -------
    ndarray, shape (..., 3)
    """
    theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def cartesian_to_spherical(v):
    """Spherical angles of vectors of any length.

    Parameters
    ----------
    v : array_like, shape (..., 3)

    Returns
    -------
    theta : ndarray
        Polar angle in ``[0, pi]``, accurate down to tiny angles (``arctan2`` of the in-plane
        length and z, where ``arccos(z)`` would lose half the digits near the pole).
    phi : ndarray
        Azimuth in ``[0, 2 pi)``; 0 on the z axis. The zero vector maps to ``(0, 0)``.
    """
    v = np.asarray(v, dtype=float)
    rho = np.hypot(v[..., 0], v[..., 1])
    theta = np.arctan2(rho, v[..., 2])
    phi = np.mod(np.arctan2(v[..., 1], v[..., 0]), TWO_PI)
    # mod(-tiny, 2 pi) rounds up to 2 pi itself, outside the half-open range
    phi = np.where(phi >= TWO_PI, 0.0, phi)
    return theta, phi


def directions_from_degrees(theta, phi):
    """Unit vectors ``(..., 3)`` from polar angle and azimuth in degrees (CSV and CLI edge)."""
    return spherical_to_cartesian(np.radians(theta), np.radians(phi))


def degrees_from_directions(v):
    """``(theta, phi)`` in degrees of vectors ``(..., 3)``; ``phi`` in ``[0, 360)``."""
    theta, phi = cartesian_to_spherical(v)
    phi = np.degrees(phi)
    return np.degrees(theta), np.where(phi >= 360.0, 0.0, phi)


def frame_from_normal(n, tangent=None):
    """Right-handed orthonormal frame ``(t, b, n)`` with ``t x b = n``.

    Parameters
    ----------
    n : array_like, shape (..., 3)
        Normals (normalised here); zero or NaN normals raise :class:`~brdf.errors.InputError`.
    tangent : array_like, shape (..., 3), optional
        Preferred tangent (the anisotropy axis); its component normal to ``n`` is used
        (Gram-Schmidt). Without it the tangent of Duff et al. 2017, "Building an Orthonormal
        Basis, Revisited" (JCGT 6(1)), listing 3: exact to rounding, smooth on each hemisphere
        (it switches branch at ``z = 0``).

    Returns
    -------
    t, b, n : ndarray, shape (..., 3)
    """
    n = np.asarray(n, dtype=float)
    length = np.linalg.norm(n, axis=-1)
    if not np.all(np.isfinite(length) & (length > 0)):
        raise InputError("frame_from_normal: the normal must be a non-zero finite vector")
    n = n / length[..., None]
    if tangent is not None:
        return _frame_with_tangent(n, tangent)
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    sign = np.where(z >= 0, 1.0, -1.0)  # Duff et al. 2017, listing 3
    a = -1.0 / (sign + z)
    b = x * y * a
    t = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=-1)
    bt = np.stack([b, sign + y * y * a, -y], axis=-1)
    return t, bt, n


def _frame_with_tangent(n, tangent):
    """Frame whose tangent is the projection of ``tangent`` onto the plane normal to ``n``."""
    t = normalize(tangent)
    # Gram-Schmidt twice: one pass leaves t.n ~ eps / sin(angle(t, n)); the second brings it
    # to eps ("twice is enough", Giraud et al. 2005, Numer. Math. 101(1))
    for _ in range(2):
        t = t - np.sum(t * n, axis=-1, keepdims=True) * n
    length = np.linalg.norm(t, axis=-1, keepdims=True)
    if not np.all(length > PARALLEL_SINE):
        raise InputError("frame_from_normal: tangent is zero or parallel to the normal")
    t = t / length
    n = np.broadcast_to(n, t.shape).copy()
    return t, np.cross(n, t), n


def to_local(v, frame):
    """Coordinates of world vectors ``v`` ``(..., 3)`` in the orthonormal frame ``(t, b, n)``."""
    t, b, n = frame
    v = np.asarray(v, dtype=float)
    return np.stack([np.sum(v * t, -1), np.sum(v * b, -1), np.sum(v * n, -1)], axis=-1)


def to_world(v, frame):
    """World vectors from local coordinates ``v`` ``(..., 3)``; inverse of :func:`to_local`."""
    t, b, n = frame
    v = np.asarray(v, dtype=float)
    return v[..., 0:1] * t + v[..., 1:2] * b + v[..., 2:3] * n


def reflect(v, n=Z_AXIS):
    """Mirror ``v`` about the unit axis ``n``: ``2 (v.n) n - v``.

    With the normal (the default, local +z) this is the specular direction; with the half vector
    of ``(wi, wo)`` it maps ``wi`` to ``wo``.
    """
    v = np.asarray(v, dtype=float)
    n = np.asarray(n, dtype=float)
    return 2.0 * np.sum(v * n, axis=-1, keepdims=True) * n - v


def half_vector(wi, wo):
    """Normalised half vector ``(wi + wo) / |wi + wo|`` (zero where ``wi = -wo``)."""
    return normalize(normalize(wi) + normalize(wo))


def rotate(v, axis, angle):
    """Rotate vectors ``v`` about a unit ``axis`` by ``angle`` (Rodrigues' formula)."""
    v = np.asarray(v, dtype=float)
    k = np.asarray(axis, dtype=float)
    c, s = np.cos(angle)[..., None], np.sin(angle)[..., None]
    return v * c + np.cross(k, v) * s + k * np.sum(k * v, -1, keepdims=True) * (1.0 - c)


def _angles_with_pole(v):
    """:func:`cartesian_to_spherical` of unit ``v`` with ``phi = 0`` within rounding of the pole."""
    theta, phi = cartesian_to_spherical(v)
    return theta, np.where(np.sin(theta) < POLE_SINE, 0.0, phi)


def half_diff_from_directions(wi, wo):
    """Rusinkiewicz half/difference angles of direction pairs.

    Rusinkiewicz 1998, "A New Change of Variables for Efficient BRDF Representation", section 3:
    ``(theta_h, phi_h)`` are the spherical angles of the half vector; the difference vector is
    ``wi`` expressed in the frame whose pole is the half vector, i.e. rotated by ``-phi_h`` about
    the normal, then by ``-theta_h`` about the bitangent.

    Parameters
    ----------
    wi, wo : array_like, shape (..., 3)
        Directions (normalised here), broadcast together.

    Returns
    -------
    theta_h, phi_h, theta_d, phi_d : ndarray
        ``theta_h`` in ``[0, pi/2]`` when both directions are in the upper hemisphere,
        ``theta_d`` in ``[0, pi/2]``, azimuths in ``[0, 2 pi)``. Swapping ``wi`` and ``wo`` adds
        ``pi`` to ``phi_d`` (mod ``2 pi``) and keeps the rest. Where an azimuth is undefined
        (``theta_h = 0``, or ``theta_d = 0`` i.e. ``wi = wo``) it is 0. A pair ``wi = -wo`` has no
        half vector; the normal stands in, which is exact for grazing pairs.
    """
    wi = normalize(wi)
    theta_h, phi_h = _angles_with_pole(half_vector(wi, wo))
    d = rotate(rotate(wi, Z_AXIS, -phi_h), Y_AXIS, -theta_h)
    theta_d, phi_d = _angles_with_pole(d)
    return theta_h, phi_h, theta_d, phi_d


def directions_from_half_diff(theta_h, phi_h, theta_d, phi_d):
    """Inverse of :func:`half_diff_from_directions`.

    Parameters
    ----------
    theta_h, phi_h, theta_d, phi_d : array_like
        Rusinkiewicz angles in radians, broadcast together.

    Returns
    -------
    wi, wo : ndarray, shape (..., 3)
        ``wi`` is the difference vector rotated back (by ``theta_h`` about the bitangent, then by
        ``phi_h`` about the normal); ``wo`` is ``wi`` mirrored about the half vector.
    """
    theta_h, phi_h, theta_d, phi_d = np.broadcast_arrays(
        *(np.asarray(a, float) for a in (theta_h, phi_h, theta_d, phi_d)))
    d = spherical_to_cartesian(theta_d, phi_d)
    h = spherical_to_cartesian(theta_h, phi_h)
    wi = rotate(rotate(d, Y_AXIS, theta_h), Z_AXIS, phi_h)
    return wi, reflect(wi, h)


def direction_array(x, name):
    """``x`` as a float64 array of directions ``(..., 3)``; InputError naming ``name`` if not."""
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim == 0 or arr.shape[-1] != 3:
        raise InputError(f"{name} must be shaped (..., 3), got shape {arr.shape}")
    # the sum is a cheap screen (NaN and inf propagate); only a non-finite sum needs the full test
    if not np.isfinite(arr.sum()) and not np.all(np.isfinite(arr)):
        raise InputError(f"{name} holds NaN or infinite values")
    return arr


def flat_pairs(wi, wo):
    """Broadcast ``wi`` and ``wo`` together and flatten: ``(wi (n, 3), wo (n, 3), shape)``."""
    wi = direction_array(wi, "wi")
    wo = direction_array(wo, "wo")
    shape = np.broadcast_shapes(wi.shape, wo.shape)[:-1]
    wi = np.ascontiguousarray(np.broadcast_to(wi, shape + (3,)).reshape(-1, 3))
    wo = np.ascontiguousarray(np.broadcast_to(wo, shape + (3,)).reshape(-1, 3))
    return wi, wo, shape
