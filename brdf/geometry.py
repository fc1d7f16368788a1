"""Directions, frames and angle parametrisations.

Conventions (docs/conventions.md §1): local shading frame with z the normal, x the tangent and
y the bitangent; unit directions in arrays shaped ``(..., 3)`` pointing away from the surface; polar
angle ``theta`` from +z, azimuth ``phi`` from +x towards +y; radians throughout, degrees only
through :func:`directions_from_degrees` and :func:`degrees_from_directions` at the I/O edge.
"""

import math

import numpy as np

from .errors import InputError

__all__ = [
    "spherical_to_cartesian", "cartesian_to_spherical", "directions_from_degrees",
    "degrees_from_directions", "normalize", "frame_from_normal", "to_local", "to_world", "reflect",
    "half_vector", "half_diff_from_directions", "directions_from_half_diff", "rotate",
    "direction_array", "real_array", "uniform_array", "flat_pairs", "broadcast_shape", "UNIT_TOL",
    "UNIT_SQ",
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


#: Largest accepted deviation of a direction's length from 1: vectors normalised in single
#: precision (float32 data) stay within 3e-7; anything further was not normalised, and kernels
#: that take it for a unit vector would return wrong values without a sign.
UNIT_TOL = 1e-6
#: The accepted range of a direction's squared length (see :data:`UNIT_TOL`).
UNIT_SQ = ((1.0 - UNIT_TOL) ** 2, (1.0 + UNIT_TOL) ** 2)
#: From this many directions on, a compiled loop screens their lengths (see brdf._directions).
_COMPILED_ROWS = 1024


def real_array(x, name):
    """``x`` as a float64 array; InputError naming ``name`` if it is not an array of real
    numbers (text, complex, ragged lists, None)."""
    if type(x) is np.ndarray and x.dtype == np.float64:
        return x
    try:
        arr = np.asarray(x)
    except ValueError:  # ragged nested lists
        raise InputError(f"{name} must be an array of numbers, got a ragged sequence") from None
    if arr.dtype.kind not in "iuf":
        raise InputError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    return arr.astype(np.float64, copy=False)


def direction_array(x, name, screen=True):
    """``x`` as a float64 array of unit directions ``(..., 3)``; InputError naming ``name``
    and the first offending row if it holds NaN or infinite values or a vector whose length is
    further than :data:`UNIT_TOL` from 1 (a zero vector, an unnormalised one).

    With ``screen`` False, the lengths are left unchecked: for a caller whose kernel screens
    the rows as it reads them (squared lengths in :data:`UNIT_SQ`) and calls this function
    again to refuse them."""
    arr = real_array(x, name)
    if arr.ndim == 0 or arr.shape[-1] != 3:
        raise InputError(f"{name} must be shaped (..., 3), got shape {arr.shape}")
    if not screen:
        return arr
    if arr.size >= 3 * _COMPILED_ROWS and arr.flags.c_contiguous:
        from ._directions import first_outside
        k = first_outside(*UNIT_SQ, arr.reshape(-1, 3))
        if k >= 0:
            _refuse_direction(arr, np.unravel_index(k, arr.shape[:-1]), name)
    elif arr.size:
        sq = np.einsum("...i,...i->...", arr, arr)
        # NaN fails both comparisons, inf the second: one screen for all three
        bad = ~((sq >= UNIT_SQ[0]) & (sq <= UNIT_SQ[1]))
        if bad.any():
            _refuse_direction(arr, tuple(np.argwhere(bad)[0]), name)
    return arr


def _refuse_direction(arr, index, name):
    k = tuple(int(i) for i in index)
    where = f"{name}[{', '.join(map(str, k))}]" if k else name
    v = arr[k]
    if not np.all(np.isfinite(v)):
        raise InputError(f"{where} = {v.tolist()} holds NaN or infinite values; expected a "
                         "unit vector")
    raise InputError(f"{where} is not a unit vector: {v.tolist()} has length "
                     f"{math.hypot(*v.tolist()):.9g}, expected within {UNIT_TOL:g} of 1")


def uniform_array(u, name="u"):
    """``u`` as a float64 array of uniform numbers ``(..., 2)`` in ``[0, 1)`` (a sampler's
    input); InputError naming ``name`` and the first offending entry otherwise."""
    u = real_array(u, name)
    if u.shape[-1:] != (2,):
        raise InputError(f"{name} must be shaped (..., 2), got shape {u.shape}")
    # NaN fails both comparisons
    if u.size and not (u.min() >= 0.0 and u.max() < 1.0):
        k = tuple(int(i) for i in np.argwhere(~((u >= 0.0) & (u < 1.0)))[0])
        raise InputError(f"{name}[{', '.join(map(str, k))}] = {float(u[k])!r}; {name} must "
                         "hold numbers in [0, 1)")
    return u


def flat_pairs(wi, wo, screen=True):
    """Broadcast ``wi`` and ``wo`` together and flatten: ``(wi (n, 3), wo (n, 3), shape)``
    (``screen`` as in :func:`direction_array`)."""
    wi = direction_array(wi, "wi", screen)
    wo = direction_array(wo, "wo", screen)
    shape = broadcast_shape(wi, wo, "wi", "wo")
    return _flat_rows(wi, shape), _flat_rows(wo, shape), shape


def _flat_rows(v, shape):
    """``v`` broadcast to ``shape + (3,)`` as C-contiguous rows (n, 3)."""
    if v.shape[:-1] != shape:
        v = np.broadcast_to(v, shape + (3,))
    return np.ascontiguousarray(v.reshape(-1, 3))


def broadcast_shape(a, b, name_a, name_b):
    """The shape of ``a`` and ``b`` broadcast together, less the last axis (the vectors');
    InputError naming both arguments' shapes if they do not broadcast."""
    try:
        return np.broadcast_shapes(a.shape[:-1], b.shape[:-1])
    except ValueError:
        raise InputError(f"{name_a} shaped {a.shape} and {name_b} shaped {b.shape} do not "
                         f"broadcast together; expected the same leading shape, or one of them "
                         f"a single vector") from None
