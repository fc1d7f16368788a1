"""Ray-primitive intersection and the bounding-volume hierarchy (numba kernels).

The scene's primitives are spheres, parallelograms ("quads": the rectangles and boxes of
classic scenes, cheaper than two triangles) and triangles. They share one primitive list,
``prim (n, 4)``: kind, row in that kind's array, material (-1: black) and area light (-1: none),
and one BVH over it.

The kernels take plain arrays, never tuples of them: numba passes a tuple by copying it and
counting a reference to each member, which cost more than the intersection tests themselves.
Geometry arrays (see :class:`brdf.render.scene.Compiled`):

- ``sph (ns, 4)``: centre and radius;
- ``quad (nq, 6, 3)``: corner p, edges e1 and e2, unit normal n = e1 x e2 / |e1 x e2|, and the
  dual vectors q1, q2 with (x - p) . q1 = a, (x - p) . q2 = b for x = p + a e1 + b e2;
- ``tri (nt, 3, 3)`` vertices, ``tri_n (nt, 3, 3)`` vertex normals (zero rows: flat shading),
  ``tri_uv (nt, 3, 2)``;
- BVH nodes ``box (nn, 2, 3)`` (lower and upper corners) and ``child (nn, 2)``: an inner node
  holds its two children, a leaf ``(-start - 1, count)`` into ``order``, the primitive order
  (built by :mod:`.bvh`).
"""

import math

import numpy as np

from .._jit import inline_kernel

SPHERE, QUAD, TRIANGLE = 0, 1, 2
#: Depth of the traversal stack (a median-split tree over 2^60 primitives fits).
STACK = 64


# --- primitives ------------------------------------------------------------------------------

@inline_kernel
def hit_sphere(s, ox, oy, oz, dx, dy, dz, tmax):
    """Nearest t in (0, tmax) of the ray on the sphere, or -1. The discriminant is taken from
    the ray's closest approach to the centre, which keeps its digits for distant spheres
    (Haines et al. 2019, Ray Tracing Gems, ch. 7, eq. 10)."""
    cx, cy, cz, r = s[0], s[1], s[2], s[3]
    fx, fy, fz = ox - cx, oy - cy, oz - cz
    b = -(fx * dx + fy * dy + fz * dz)
    lx, ly, lz = fx + b * dx, fy + b * dy, fz + b * dz
    disc = r * r - (lx * lx + ly * ly + lz * lz)
    if disc < 0.0:
        return -1.0
    q = math.sqrt(disc)
    t = b - q
    if t > 0.0 and t < tmax:
        return t
    t = b + q
    if t > 0.0 and t < tmax:
        return t
    return -1.0


@inline_kernel
def hit_quad(g, ox, oy, oz, dx, dy, dz, tmax):
    """``(t, a, b)`` of the ray on the parallelogram p + a e1 + b e2, a and b in [0, 1]; t = -1
    on a miss (plane intersection, then the dual-basis coordinates)."""
    nx, ny, nz = g[3, 0], g[3, 1], g[3, 2]
    den = dx * nx + dy * ny + dz * nz
    if den == 0.0:
        return -1.0, 0.0, 0.0
    px, py, pz = g[0, 0] - ox, g[0, 1] - oy, g[0, 2] - oz
    t = (px * nx + py * ny + pz * nz) / den
    if not (t > 0.0 and t < tmax):
        return -1.0, 0.0, 0.0
    hx, hy, hz = ox + t * dx - g[0, 0], oy + t * dy - g[0, 1], oz + t * dz - g[0, 2]
    a = hx * g[4, 0] + hy * g[4, 1] + hz * g[4, 2]
    b = hx * g[5, 0] + hy * g[5, 1] + hz * g[5, 2]
    if a < 0.0 or a > 1.0 or b < 0.0 or b > 1.0:
        return -1.0, 0.0, 0.0
    return t, a, b


@inline_kernel
def hit_triangle(v, ox, oy, oz, dx, dy, dz, tmax):
    """``(t, b1, b2)`` of the ray on the triangle (Moller & Trumbore 1997, "Fast, Minimum
    Storage Ray-Triangle Intersection", JGT 2(1)); t = -1 on a miss."""
    e1x, e1y, e1z = v[1, 0] - v[0, 0], v[1, 1] - v[0, 1], v[1, 2] - v[0, 2]
    e2x, e2y, e2z = v[2, 0] - v[0, 0], v[2, 1] - v[0, 1], v[2, 2] - v[0, 2]
    px, py, pz = dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    if det == 0.0:
        return -1.0, 0.0, 0.0
    inv = 1.0 / det
    sx, sy, sz = ox - v[0, 0], oy - v[0, 1], oz - v[0, 2]
    b1 = (sx * px + sy * py + sz * pz) * inv
    if b1 < 0.0 or b1 > 1.0:
        return -1.0, 0.0, 0.0
    qx, qy, qz = sy * e1z - sz * e1y, sz * e1x - sx * e1z, sx * e1y - sy * e1x
    b2 = (dx * qx + dy * qy + dz * qz) * inv
    if b2 < 0.0 or b1 + b2 > 1.0:
        return -1.0, 0.0, 0.0
    t = (e2x * qx + e2y * qy + e2z * qz) * inv
    if not (t > 0.0 and t < tmax):
        return -1.0, 0.0, 0.0
    return t, b1, b2


@inline_kernel
def hit_primitive(prim, sph, quad, tri, i, ox, oy, oz, dx, dy, dz, tmax):
    """``(t, a, b)`` of the ray on primitive i (t = -1 on a miss)."""
    j = prim[i, 1]
    if prim[i, 0] == SPHERE:
        return hit_sphere(sph[j], ox, oy, oz, dx, dy, dz, tmax), 0.0, 0.0
    if prim[i, 0] == QUAD:
        return hit_quad(quad[j], ox, oy, oz, dx, dy, dz, tmax)
    return hit_triangle(tri[j], ox, oy, oz, dx, dy, dz, tmax)


# --- hierarchy -------------------------------------------------------------------------------

@inline_kernel
def _box_entry(box, n, ox, oy, oz, rx, ry, rz, tmax):
    """Entry distance of the ray (origin o, reciprocal direction r) into box n, or inf (the
    slab test; Williams et al. 2005, "An Efficient and Robust Ray-Box Intersection")."""
    t0x, t1x = (box[n, 0, 0] - ox) * rx, (box[n, 1, 0] - ox) * rx
    t0y, t1y = (box[n, 0, 1] - oy) * ry, (box[n, 1, 1] - oy) * ry
    t0z, t1z = (box[n, 0, 2] - oz) * rz, (box[n, 1, 2] - oz) * rz
    near = max(max(min(t0x, t1x), min(t0y, t1y)), max(min(t0z, t1z), 0.0))
    far = min(min(max(t0x, t1x), max(t0y, t1y)), min(max(t0z, t1z), tmax))
    # a little slack: a ray grazing a flat box (a quad's own box) must not slip through
    return near if near <= far * (1.0 + 1e-12) else math.inf


@inline_kernel
def closest_hit(prim, sph, quad, tri, box, child, order, stack, ox, oy, oz, dx, dy, dz, tmax):
    """``(t, primitive, a, b)`` of the nearest hit in (0, tmax); primitive -1 on a miss.
    ``stack`` is scratch space of STACK integers."""
    rx = 1.0 / dx if dx != 0.0 else math.inf
    ry = 1.0 / dy if dy != 0.0 else math.inf
    rz = 1.0 / dz if dz != 0.0 else math.inf
    stack[0] = 0
    top = 1
    best, hit, ba, bb = tmax, -1, 0.0, 0.0
    while top > 0:
        top -= 1
        n = stack[top]
        if _box_entry(box, n, ox, oy, oz, rx, ry, rz, best) == math.inf:
            continue
        c0, c1 = child[n, 0], child[n, 1]
        if c0 < 0:
            start = -c0 - 1
            for s in range(start, start + c1):
                i = order[s]
                t, a, b = hit_primitive(prim, sph, quad, tri, i, ox, oy, oz, dx, dy, dz, best)
                if t > 0.0:
                    best, hit, ba, bb = t, i, a, b
        else:
            # visit the nearer child first: its hits shorten the far child's test
            e0 = _box_entry(box, c0, ox, oy, oz, rx, ry, rz, best)
            e1 = _box_entry(box, c1, ox, oy, oz, rx, ry, rz, best)
            if e0 <= e1:
                if e1 < math.inf:
                    stack[top] = c1
                    top += 1
                if e0 < math.inf:
                    stack[top] = c0
                    top += 1
            else:
                if e0 < math.inf:
                    stack[top] = c0
                    top += 1
                if e1 < math.inf:
                    stack[top] = c1
                    top += 1
    return best, hit, ba, bb


@inline_kernel
def occluded(prim, sph, quad, tri, box, child, order, stack, ox, oy, oz, dx, dy, dz, tmax):
    """Whether anything lies on the ray within (0, tmax) (any hit ends the search)."""
    rx = 1.0 / dx if dx != 0.0 else math.inf
    ry = 1.0 / dy if dy != 0.0 else math.inf
    rz = 1.0 / dz if dz != 0.0 else math.inf
    stack[0] = 0
    top = 1
    while top > 0:
        top -= 1
        n = stack[top]
        if _box_entry(box, n, ox, oy, oz, rx, ry, rz, tmax) == math.inf:
            continue
        c0, c1 = child[n, 0], child[n, 1]
        if c0 < 0:
            start = -c0 - 1
            for s in range(start, start + c1):
                t, a, b = hit_primitive(prim, sph, quad, tri, order[s], ox, oy, oz, dx, dy, dz, tmax)
                if t > 0.0:
                    return True
        else:
            stack[top] = c0
            stack[top + 1] = c1
            top += 2
    return False
