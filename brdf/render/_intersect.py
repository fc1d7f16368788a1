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
  holds its two children, a leaf ``(-first - 1, count)``: its primitives fill ``count`` blocks
  of LANES slots from block ``first`` on, and ``slots (nb * LANES,)`` holds the primitive in
  each slot, -1 in the padding that ends a leaf's last block (built by :mod:`.bvh`);
- ``planes (nb, PLANE_ROWS, LANES)``: the intersection data of the primitive in each slot of
  each block, one row per field (normal, corner, q1, q2, a triangle flag, a sphere flag) so
  that a block's primitives are tested side by side in SIMD lanes (:func:`leaf_distances`);
  a sphere's column holds only its flag, a padding slot's only zeros (a miss).
"""

import math

import numpy as np

from .._jit import inline_kernel, kernel

SPHERE, QUAD, TRIANGLE = 0, 1, 2
#: rows of ``planes``: normal, corner, dual vectors q1 and q2, triangle flag, sphere flag
PN, PP, PQ1, PQ2, PTRI, PSPH = 0, 3, 6, 9, 12, 13
PLANE_ROWS = 14
#: Primitives per BVH leaf at most (the builder's bound; leaves of coincident centroids hold
#: more, in more blocks).
LEAF_SIZE = 16
#: Slots per leaf block, the leaf pass's fixed width. LLVM vectorises a loop of this constant
#: length (four AVX2 or two AVX-512 registers of doubles) with no remainder and no trip-count
#: test; a leaf of 9 primitives looped over its own count ran scalar, and a length of 8 is
#: unrolled instead of vectorised.
LANES = 16
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


@kernel
def leaf_distances(planes, blk, ox, oy, oz, dx, dy, dz, tmax, dist):
    """Distances in (0, tmax) of the ray to the planar primitives in the LANES slots of block
    ``blk`` into ``dist``: inf on a miss (and in padding), -1 for a sphere (tested apart).

    One formula for parallelograms and triangles, x = p + a e1 + b e2 with a, b >= 0 and
    max(a, b) <= 1 or a + b <= 1 (the plane, then the dual-basis coordinates; for a triangle
    they are Moller and Trumbore's barycentrics b1, b2). Free of branches, so LLVM runs it
    across the slots in SIMD lanes, where a test of one primitive at a time mispredicted its
    branches on random rays. A ray parallel to the plane divides by zero, and the inf or NaN
    it gives fails the tests, as the 0 / 0 of a padding slot's zero normal does."""
    for j in range(LANES):
        nx, ny, nz = planes[blk, PN, j], planes[blk, PN + 1, j], planes[blk, PN + 2, j]
        px = planes[blk, PP, j] - ox
        py = planes[blk, PP + 1, j] - oy
        pz = planes[blk, PP + 2, j] - oz
        t = (px * nx + py * ny + pz * nz) / (dx * nx + dy * ny + dz * nz)
        hx, hy, hz = t * dx - px, t * dy - py, t * dz - pz
        a = hx * planes[blk, PQ1, j] + hy * planes[blk, PQ1 + 1, j] + hz * planes[blk, PQ1 + 2, j]
        b = hx * planes[blk, PQ2, j] + hy * planes[blk, PQ2 + 1, j] + hz * planes[blk, PQ2 + 2, j]
        edge = max(a, b) + planes[blk, PTRI, j] * min(a, b)
        inside = (t > 0.0) & (t < tmax) & (a >= 0.0) & (b >= 0.0) & (edge <= 1.0)
        d = t if inside else math.inf
        dist[j] = -1.0 if planes[blk, PSPH, j] != 0.0 else d


@kernel
def plane_coordinates(planes, slot, ox, oy, oz, dx, dy, dz, t):
    """(a, b) of the hit at distance t on the planar primitive in ``slot``."""
    b, j = slot // LANES, slot % LANES
    hx = ox + t * dx - planes[b, PP, j]
    hy = oy + t * dy - planes[b, PP + 1, j]
    hz = oz + t * dz - planes[b, PP + 2, j]
    return (hx * planes[b, PQ1, j] + hy * planes[b, PQ1 + 1, j] + hz * planes[b, PQ1 + 2, j],
            hx * planes[b, PQ2, j] + hy * planes[b, PQ2 + 1, j] + hz * planes[b, PQ2 + 2, j])


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
def _slot_hit(prim, sph, slots, dist, slot, j, ox, oy, oz, dx, dy, dz, tmax):
    """Distance to the primitive in ``slot``, lane j of the leaf pass (which held it to the
    pass's tmax), the sphere's own test in (0, tmax) for a sphere; inf on a miss."""
    t = dist[j]
    if t < 0.0:
        t = hit_sphere(sph[prim[slots[slot], 1]], ox, oy, oz, dx, dy, dz, tmax)
        return t if t > 0.0 else math.inf
    return t


@inline_kernel
def closest_hit(prim, sph, planes, box, child, slots, stack, dist, ox, oy, oz, dx, dy, dz,
                tmax):
    """``(t, primitive, a, b)`` of the nearest hit in (0, tmax); primitive -1 on a miss.
    ``stack`` (STACK integers) and ``dist`` (LANES numbers) are scratch space."""
    rx = 1.0 / dx if dx != 0.0 else math.inf
    ry = 1.0 / dy if dy != 0.0 else math.inf
    rz = 1.0 / dz if dz != 0.0 else math.inf
    stack[0] = 0
    top = 1
    best, slot = tmax, -1
    while top > 0:
        top -= 1
        n = stack[top]
        if _box_entry(box, n, ox, oy, oz, rx, ry, rz, best) == math.inf:
            continue
        c0, c1 = child[n, 0], child[n, 1]
        if c0 < 0:
            for blk in range(-c0 - 1, -c0 - 1 + c1):
                leaf_distances(planes, blk, ox, oy, oz, dx, dy, dz, best, dist)
                for j in range(LANES):
                    s = blk * LANES + j
                    t = _slot_hit(prim, sph, slots, dist, s, j, ox, oy, oz, dx, dy, dz, best)
                    if t < best:
                        best, slot = t, s
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
    if slot < 0:
        return best, -1, 0.0, 0.0
    i = slots[slot]
    if prim[i, 0] == SPHERE:
        return best, i, 0.0, 0.0
    a, b = plane_coordinates(planes, slot, ox, oy, oz, dx, dy, dz, best)
    return best, i, a, b


@inline_kernel
def occluded(prim, sph, planes, box, child, slots, stack, dist, ox, oy, oz, dx, dy, dz, tmax):
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
            for blk in range(-c0 - 1, -c0 - 1 + c1):
                leaf_distances(planes, blk, ox, oy, oz, dx, dy, dz, tmax, dist)
                for j in range(LANES):
                    if _slot_hit(prim, sph, slots, dist, blk * LANES + j, j, ox, oy, oz, dx, dy,
                                 dz, tmax) < math.inf:
                        return True
        else:
            stack[top] = c0
            stack[top + 1] = c1
            top += 2
    return False
