"""Rays through a compiled scene from Python: camera rays, first hits with their shading frames,
and shadow-ray visibility, for code that needs the renderer's geometry without its integrator
(the inverse methods of :mod:`brdf.capture`).

Hits are found by the renderer's own traversal (:func:`._intersect.trace_packet`, called from
Python in packets of :data:`PACKET` rays), and the shading frame at a hit is the one the path
tracer shades with (``_integrator``'s surface and frame functions, written again here in numpy
over arrays of hits): a sphere's normal with its tangent along the azimuth, a quad's normal
with its first edge as tangent, a triangle's interpolated vertex normal with its first edge as
tangent, each turned to the side the ray arrives from.
"""

from dataclasses import dataclass

import numpy as np

from . import _intersect as X

__all__ = ["camera_rays", "Hits", "first_hits", "occluded", "to_local", "PACKET"]

#: Rays traced per call of the traversal kernel (its packet loops scale with it).
PACKET = 512


def camera_rays(camera, width, height, offsets=((0.5, 0.5),)):
    """Unit world directions ``(k, height, width, 3)`` from ``camera`` through the points
    ``offsets`` (k pairs in [0, 1) within a pixel, (0.5, 0.5) its centre) of every pixel, and
    the camera's origin (3,), as the renderer's camera casts them (row 0 at the top)."""
    cam = camera.pack(width, height)
    off = np.asarray(offsets, dtype=float).reshape(-1, 2)
    x = np.arange(width)[None, None, :] + off[:, 0, None, None]
    y = np.arange(height)[None, :, None] + off[:, 1, None, None]
    sx = np.broadcast_to(x * cam[12] - 1.0, (len(off), height, width))
    sy = np.broadcast_to(1.0 - y * cam[13], (len(off), height, width))
    d = cam[3:6] + sx[..., None] * cam[6:9] + sy[..., None] * cam[9:12]
    return d / np.linalg.norm(d, axis=-1, keepdims=True), cam[0:3].copy()


def _trace(geo, origins, directions, lengths, any_hit):
    """``(t, slot)`` per ray through :func:`._intersect.trace_packet`, in packets."""
    n = len(directions)
    t_all = np.asarray(lengths, dtype=float).copy()
    slot_all = np.full(n, -1, dtype=np.int64)
    stack = np.zeros(2 * X.STACK, dtype=np.int64)
    dist = np.zeros(X.LANES)
    for a in range(0, n, PACKET):
        b = min(n, a + PACKET)
        m = b - a
        ray = np.empty((X.RAY_ROWS, m))
        ray[X.ORIGIN:X.ORIGIN + 3] = origins[a:b].T
        ray[X.DIRECTION:X.DIRECTION + 3] = directions[a:b].T
        tmax = np.ascontiguousarray(t_all[a:b])
        hit = np.full(m, -1, dtype=np.int64)
        X.trace_packet(geo, stack, dist, ray, np.zeros((3, m)), np.zeros(m, dtype=np.int64),
                       tmax, hit, bool(any_hit), m)
        t_all[a:b], slot_all[a:b] = tmax, hit
    return t_all, slot_all


@dataclass
class Hits:
    """First hits of rays, one entry per ray (arrays over the rays; misses hold -1 in
    ``shape`` and ``primitive`` and zeros elsewhere).

    Attributes
    ----------
    hit : ndarray of bool
    t : ndarray
        Distance along the (unit) ray.
    primitive, shape : ndarray of int
        The compiled primitive and the scene's shape (its index in ``scene.shapes``) hit.
    position, normal, shading, tangent, bitangent : ndarray (n, 3)
        The hit point, the geometric normal, and the shading frame (shading normal, tangent,
        bitangent), all turned to the side the ray came from.
    """

    hit: np.ndarray
    t: np.ndarray
    primitive: np.ndarray
    shape: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    shading: np.ndarray
    tangent: np.ndarray
    bitangent: np.ndarray


def _unit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0.0, n, 1.0)


def _any_tangent(s):
    """A unit vector orthogonal to each row of ``s`` (Duff et al. 2017, JCGT 6(1), listing 3,
    as :func:`brdf.sampling.basis_from_axis`)."""
    sign = np.where(s[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + s[:, 2])
    b = s[:, 0] * s[:, 1] * a
    return np.stack([1.0 + sign * s[:, 0] ** 2 * a, sign * b, -sign * s[:, 0]], axis=1)


def first_hits(compiled, origins, directions):
    """The nearest hit of each ray (``origins``, unit ``directions`` (n, 3)) in a compiled
    scene (:meth:`brdf.render.Scene.compile`), with the renderer's shading frame
    (:class:`Hits`)."""
    geo = compiled.geo
    origins = np.ascontiguousarray(np.broadcast_to(origins, np.shape(directions)), dtype=float)
    directions = np.ascontiguousarray(directions, dtype=float)
    n = len(directions)
    t, slot = _trace(geo, origins, directions, np.full(n, np.inf), False)
    hit = slot >= 0
    prim = np.where(hit, geo.slots[np.maximum(slot, 0)], -1)
    kind = np.where(hit, geo.prim[np.maximum(prim, 0), 0], -1)
    row = geo.prim[np.maximum(prim, 0), 1]
    t = np.where(hit, t, 0.0)
    p = origins + t[:, None] * directions
    nrm = np.zeros((n, 3))
    sh = np.zeros((n, 3))
    tan = np.zeros((n, 3))
    sel = kind == X.SPHERE
    if sel.any():
        c = geo.sph[row[sel]]
        nrm[sel] = (p[sel] - c[:, :3]) / c[:, 3:4]
        sh[sel] = nrm[sel]
        tan[sel] = np.stack([-nrm[sel, 1], nrm[sel, 0], np.zeros(sel.sum())], axis=1)
    sel = kind == X.QUAD
    if sel.any():
        g = geo.quad[row[sel]]
        nrm[sel], sh[sel], tan[sel] = g[:, 3], g[:, 3], g[:, 6]
    sel = kind == X.TRIANGLE
    if sel.any():
        v = geo.tri[row[sel]]
        e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
        ng = _unit(np.cross(e1, e2))
        # barycentrics (a, b) from the dual vectors of the slot's plane (the kernels' planes)
        blk, lane = slot[sel] // X.LANES, slot[sel] % X.LANES
        q1 = geo.planes[blk, X.PQ1:X.PQ1 + 3, lane]
        q2 = geo.planes[blk, X.PQ2:X.PQ2 + 3, lane]
        h = p[sel] - v[:, 0]
        a, b = np.sum(h * q1, axis=1), np.sum(h * q2, axis=1)
        vn = geo.tri_n[row[sel]]
        s = (1.0 - a - b)[:, None] * vn[:, 0] + a[:, None] * vn[:, 1] + b[:, None] * vn[:, 2]
        flat = np.linalg.norm(s, axis=1) == 0.0
        s[flat] = ng[flat]
        nrm[sel], sh[sel], tan[sel] = ng, _unit(s), e1
    # the side the ray arrives from, then the shading normal to the geometric normal's side
    nrm *= np.where(np.sum(nrm * directions, axis=1) > 0.0, -1.0, 1.0)[:, None]
    sh *= np.where(np.sum(sh * nrm, axis=1) < 0.0, -1.0, 1.0)[:, None]
    # Gram-Schmidt of the tangent about the shading normal; any tangent where they are parallel
    tan = tan - np.sum(tan * sh, axis=1, keepdims=True) * sh
    short = np.linalg.norm(tan, axis=1) < 1e-9
    if short.any():
        tan[short] = _any_tangent(sh[short])
    tan = _unit(tan)
    bit = np.cross(sh, tan)
    shape = _shape_of(compiled, prim)
    zero = ~hit
    for a in (p, nrm, sh, tan, bit):
        a[zero] = 0.0
    return Hits(hit, t, prim, shape, p, nrm, sh, tan, bit)


def _shape_of(compiled, prim):
    """The scene shape of each compiled primitive (-1 stays -1)."""
    shapes = compiled.shape_of
    return np.where(prim >= 0, shapes[np.maximum(prim, 0)], -1)


def occluded(compiled, origins, directions, lengths):
    """Whether something blocks each ray within its length (inf: to infinity): shadow rays."""
    directions = np.ascontiguousarray(directions, dtype=float)
    origins = np.ascontiguousarray(np.broadcast_to(origins, directions.shape), dtype=float)
    _, slot = _trace(compiled.geo, origins, directions, lengths, True)
    return slot >= 0


def to_local(hits, v):
    """World vectors ``v`` (n, 3) in each hit's shading frame (tangent, bitangent, normal):
    the library's local frame (docs/conventions.md §1)."""
    return np.stack([np.sum(v * hits.tangent, axis=1), np.sum(v * hits.bitangent, axis=1),
                     np.sum(v * hits.shading, axis=1)], axis=1)
