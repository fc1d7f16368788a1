"""Ray-primitive intersection and the bounding-volume hierarchy (numba kernels).

The scene's primitives are spheres, parallelograms ("quads": the rectangles and boxes of
classic scenes, cheaper than two triangles) and triangles. They share one primitive list,
``prim (n, 4)``: kind, row in that kind's array, material (-1: black) and area light (-1: none),
and one BVH over it.

The kernels take the geometry as one :data:`Geometry` tuple of arrays, fields by name. Kernels
compiled without reference counting (:func:`brdf._jit.kernel`) pass a tuple as its members'
fields, as they pass the arrays themselves: no copy, no count (the plain-array arguments of
earlier versions avoided a reference count per member that those kernels no longer take).
Its arrays (built by :meth:`brdf.render.scene.Scene.compile`):

- ``sph (ns, 4)``: centre and radius;
- ``quad (nq, 7, 3)``: corner p, edges e1 and e2, unit normal n = e1 x e2 / |e1 x e2|, the
  dual vectors q1, q2 with (x - p) . q1 = a, (x - p) . q2 = b for x = p + a e1 + b e2, and the
  unit tangent e1 / |e1| (the shading frame's);
- ``tri (nt, 3, 3)`` vertices, ``tri_n (nt, 3, 3)`` vertex normals (zero rows: flat shading),
  ``tri_uv (nt, 3, 2)``;
- BVH nodes ``box (nn, 2, 3)`` (lower and upper corners) and ``child (nn, 2)``: an inner node
  holds its two children, a leaf ``(-first - 1, count)``: its primitives fill ``count`` blocks
  of LANES slots from block ``first`` on, and ``slots (nb * LANES,)`` holds the primitive in
  each slot, -1 in the padding that ends a leaf's last block (built by :mod:`.bvh`);
- the same tree collapsed to WIDTH-wide nodes for single rays (:func:`.bvh.collapse`):
  ``wbox (nw, 6, WIDTH)`` float32, each child's lower and upper corner a row per coordinate,
  rounded outward; ``wchild (nw, 2, WIDTH)``, a child's wide node or leaf (coded as in
  ``child``); ``entry (nn, 2)``, each binary node's wide node and the mask of its slots there;
- ``planes (nb, PLANE_ROWS, LANES)``: the intersection data of the primitive in each slot of
  each block, one row per field (normal, corner, q1, q2, a triangle flag, a sphere flag) so
  that a block's primitives are tested side by side in SIMD lanes (:func:`leaf_distances`);
  a sphere's column holds only its flag, a padding slot's only zeros (a miss).

Rays are traced in packets (:func:`trace_packet`): a packet's rays side by side in SIMD lanes
while many of them enter the same nodes, and each ray alone, with a block's primitives in the
lanes, where they part ways.
"""

import math
from collections import namedtuple

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from .._jit import FASTMATH, OPTIMISED, inline_kernel, kernel

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
#: unrolled instead of vectorised. (:func:`_least` is written out for 16.)
LANES = 16
#: Rows of a packet's ``ray`` array (:func:`trace_packet`), a ray per column: its origin and
#: unit direction.
ORIGIN, DIRECTION, RAY_ROWS = 0, 3, 6
#: Levels of the binary tree at most (:func:`.bvh.build_bvh` keeps every tree shallower).
DEPTH = 62
#: Children of a wide node (:func:`.bvh.collapse`), the single rays' tree: a power of two.
#: On the 40,400-triangle mesh of ``bench_render.py``, one thread, its camera, bounce and
#: shadow rays (ALONE 32) took 109, 182 and 250 ns at 4; 122, 202 and 276 at 8; 114, 187 and
#: 260 at 16 (whose node test runs in AVX-512 lanes: 16 boxes in 15.6 ns, as 4 in scalar code).
#: With every width's node test in SIMD lanes (:func:`_wide_entries`), 4 still beat 8: 115-129,
#: 218-253 and 225-272 ns against 122-165, 237-313 and 252-321 (four alternating pairs).
WIDTH = 4
#: Half the traversal's stack (callers pass 2 STACK integers): the packet's stack holds at most
#: DEPTH + 2 nodes, a ray's on top of it WIDTH - 1 per wide level and one more.
STACK = 128
#: The scene's geometry as every kernel takes it (the arrays described above).
Geometry = namedtuple("Geometry",
                      "prim sph quad tri tri_n tri_uv box child slots planes wbox wchild entry")


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
def _plane(planes, b, s):
    """The planar primitive in slot s of block b: normal, corner, dual vectors (3-tuples) and
    triangle flag."""
    return ((planes[b, PN, s], planes[b, PN + 1, s], planes[b, PN + 2, s]),
            (planes[b, PP, s], planes[b, PP + 1, s], planes[b, PP + 2, s]),
            (planes[b, PQ1, s], planes[b, PQ1 + 1, s], planes[b, PQ1 + 2, s]),
            (planes[b, PQ2, s], planes[b, PQ2 + 1, s], planes[b, PQ2 + 2, s]),
            planes[b, PTRI, s])


@inline_kernel
def plane_distance(plane, ox, oy, oz, dx, dy, dz, tmax):
    """Distance in (0, tmax) of the ray to a planar primitive (:func:`_plane`), inf on a miss.

    One formula for parallelograms and triangles, x = p + a e1 + b e2 with a, b >= 0 and
    max(a, b) <= 1 or a + b <= 1 (the plane, then the dual-basis coordinates; for a triangle
    they are Moller and Trumbore's barycentrics b1, b2). A ray parallel to the plane divides
    by zero, and the inf or NaN it gives fails the tests, as the 0 / 0 of a padding slot's
    zero normal does."""
    (nx, ny, nz), (cx, cy, cz), (ax, ay, az), (bx, by, bz), tri = plane
    px, py, pz = cx - ox, cy - oy, cz - oz
    t = (px * nx + py * ny + pz * nz) / (dx * nx + dy * ny + dz * nz)
    hx, hy, hz = t * dx - px, t * dy - py, t * dz - pz
    a = hx * ax + hy * ay + hz * az
    b = hx * bx + hy * by + hz * bz
    inside = ((t > 0.0) & (t < tmax) & (a >= 0.0) & (b >= 0.0)
              & (max(a, b) + tri * min(a, b) <= 1.0))
    return t if inside else math.inf


@kernel(linked=OPTIMISED)
def leaf_distances(planes, blk, ox, oy, oz, dx, dy, dz, tmax, dist):
    """Distances in (0, tmax) of the ray to the planar primitives in the LANES slots of block
    ``blk`` into ``dist`` (:func:`plane_distance`): inf on a miss (and in padding), -1 for a
    sphere (tested apart). Free of branches, so LLVM runs it across the slots in SIMD lanes,
    where a test of one primitive at a time mispredicted its branches on random rays."""
    for j in range(LANES):
        t = plane_distance(_plane(planes, blk, j), ox, oy, oz, dx, dy, dz, tmax)
        dist[j] = -1.0 if planes[blk, PSPH, j] != 0.0 else t


@kernel(linked=OPTIMISED)
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
def _corners(box, n):
    """The lower and upper corners of box n (3-tuples)."""
    return ((box[n, 0, 0], box[n, 0, 1], box[n, 0, 2]),
            (box[n, 1, 0], box[n, 1, 1], box[n, 1, 2]))


@inline_kernel
def _slab(corners, ox, oy, oz, rx, ry, rz, tmax):
    """Entry distance of the ray (origin o, reciprocal direction r) into a box (its
    :func:`_corners`) within (0, tmax), and whether it enters (the slab test; Williams et al.
    2005, "An Efficient and Robust Ray-Box Intersection")."""
    (lox, loy, loz), (hix, hiy, hiz) = corners
    t0x, t1x = (lox - ox) * rx, (hix - ox) * rx
    t0y, t1y = (loy - oy) * ry, (hiy - oy) * ry
    t0z, t1z = (loz - oz) * rz, (hiz - oz) * rz
    near = max(max(min(t0x, t1x), min(t0y, t1y)), max(min(t0z, t1z), 0.0))
    far = min(min(max(t0x, t1x), max(t0y, t1y)), min(max(t0z, t1z), tmax))
    # a little slack: a ray grazing a flat box (a quad's own box) must not slip through
    return near, near <= far * (1.0 + 1e-12)


@inline_kernel
def _least(d):
    """The least of the leaf pass's LANES (16) distances ``d``, -1 if the block holds a sphere,
    halved pairwise, so that the minima of a halving run side by side: the scan of the slots
    in order, a chain of 15 comparisons each waiting on the last, was a tenth of the mesh's
    traversal."""
    m0, m1, m2, m3 = min(d[0], d[8]), min(d[1], d[9]), min(d[2], d[10]), min(d[3], d[11])
    m4, m5, m6, m7 = min(d[4], d[12]), min(d[5], d[13]), min(d[6], d[14]), min(d[7], d[15])
    m0, m1, m2, m3 = min(m0, m4), min(m1, m5), min(m2, m6), min(m3, m7)
    return min(min(m0, m2), min(m1, m3))


@inline_kernel
def _slot_hit(geo, dist, slot, j, ox, oy, oz, dx, dy, dz, tmax):
    """Distance to the primitive in ``slot``, lane j of the leaf pass (which held it to the
    pass's tmax), the sphere's own test in (0, tmax) for a sphere; inf on a miss."""
    t = dist[j]
    if t < 0.0:
        t = hit_sphere(geo.sph[geo.prim[geo.slots[slot], 1]], ox, oy, oz, dx, dy, dz, tmax)
        return t if t > 0.0 else math.inf
    return t


@kernel(linked=OPTIMISED)
def _trace_lane(geo, stack, top, dist, start, ox, oy, oz, dx, dy, dz, rx, ry, rz, tmax,
                any_hit):
    """One ray (origin o, direction d, reciprocal direction r) through the subtree of binary
    node ``start``, in the wide tree (:func:`.bvh.collapse`): ``(t, slot)`` of its nearest hit
    in (0, tmax), or with ``any_hit`` of the first one found; slot -1 on a miss. ``stack``
    holds the caller's entries below ``top``; ``dist`` (LANES numbers) is work space.

    A wide node's WIDTH child boxes are tested in one loop (float32 corners, widened exactly,
    against the ray in float64, so the test is as exact as the binary tree's and conservative),
    and its children are pushed farthest first, so the nearest is visited next (its hits
    shorten the other tests). A leaf is pushed as ``-(node * WIDTH + slot) - 1``."""
    wbox, wchild, planes = geo.wbox, geo.wchild, geo.planes
    w, mask = geo.entry[start, 0], geo.entry[start, 1]
    stack[top] = w
    bottom = top
    top += 1
    best, found = tmax, -1
    while top > bottom:
        top -= 1
        code = stack[top]
        if code < 0:
            ref = -code - 1
            n, s = ref // WIDTH, ref % WIDTH
            first = -wchild[n, 0, s] - 1
            for blk in range(first, first + wchild[n, 1, s]):
                leaf_distances(planes, blk, ox, oy, oz, dx, dy, dz, best, dist)
                least = _least(dist)
                if least == math.inf:
                    continue  # the usual case: the ray misses the block's primitives
                if least > 0.0:
                    # planar primitives only: the nearest, the lowest slot of equal ones (as
                    # a scan in slot order finds it); with any_hit the first slot hit
                    for j in range(LANES):
                        if dist[j] == least or (any_hit and dist[j] < best):
                            best, found = dist[j], blk * LANES + j
                            break
                    if any_hit:
                        return best, found
                    continue
                for j in range(LANES):
                    t = _slot_hit(geo, dist, blk * LANES + j, j, ox, oy, oz, dx, dy, dz, best)
                    if t < best:
                        best, found = t, blk * LANES + j
                        if any_hit:
                            return best, found
            continue
        entered = _wide_entries(wbox, code, ox, oy, oz, rx, ry, rz, best, dist) & mask
        mask = -1
        if entered == 0:
            continue
        if entered & (entered - 1) == 0:
            # one child (the usual case): no order to find
            s = _lowest_bit(entered)
            c = wchild[code, 0, s]
            stack[top] = c if c >= 0 else -(code * WIDTH + s) - 1
            top += 1
            continue
        # the entered children, farthest first (insertion sort on their entry distances;
        # equal distances keep the slots' order, the lower slot visited first)
        low = top
        while entered:
            s = _lowest_bit(entered)
            entered &= entered - 1
            e = dist[s]
            i = top
            while i > low and dist[stack[i - 1]] <= e:
                stack[i] = stack[i - 1]
                i -= 1
            stack[i] = s
            top += 1
        for i in range(low, top):
            s = stack[i]
            c = wchild[code, 0, s]
            stack[i] = c if c >= 0 else -(code * WIDTH + s) - 1
    return best, found


@intrinsic
def _wide_entries(typingctx, wbox, n, ox, oy, oz, rx, ry, rz, tmax, dist):
    """Entry distance of the ray into each of wide node n's WIDTH child boxes within (0, tmax)
    into ``dist[:WIDTH]``, inf where it misses, and the mask of the children entered (bit s:
    ``dist[s] < inf``): :func:`_slab` on all WIDTH children at once, in one SIMD register per
    coordinate (``wbox`` float32 C (nw, 6, WIDTH), ``dist`` float64).

    Written as LLVM vector code: the scalar loop was unrolled into one child after another,
    whose stores into ``dist`` LLVM could not move past the next child's loads (the arrays
    might overlap), so it never ran in SIMD lanes, and it was three fifths of a single ray's
    traversal. The operations are _slab's, in its order and with numba's min and max (``b <
    a ? b : a``), so the distances are the same to the bit."""
    if not (isinstance(wbox, types.Array) and wbox.dtype == types.float32 and wbox.ndim == 3
            and wbox.layout == "C" and isinstance(dist, types.Array)
            and dist.dtype == types.float64 and dist.layout == "C"):
        return None

    def codegen(context, builder, signature, args):
        f64 = ir.DoubleType()
        vec = ir.VectorType(f64, WIDTH)
        index = ir.IntType(32)
        zeros = ir.Constant(ir.VectorType(index, WIDTH), [0] * WIDTH)

        def splat(x, ty):
            x = context.cast(builder, x, ty, types.float64)
            one = builder.insert_element(ir.Constant(vec, ir.Undefined), x, index(0))
            return builder.shuffle_vector(one, ir.Constant(vec, ir.Undefined), zeros)

        def lesser(a, b):  # numba's min(a, b)
            return builder.select(builder.fcmp_ordered("<", b, a), b, a)

        def greater(a, b):  # numba's max(a, b)
            return builder.select(builder.fcmp_ordered(">", b, a), b, a)

        boxes = context.make_array(signature.args[0])(context, builder, args[0])
        node = context.cast(builder, args[1], signature.args[1], types.intp)
        rows = []
        for r in range(6):
            at = cgutils.get_item_pointer(context, builder, signature.args[0], boxes,
                                          [node, context.get_constant(types.intp, r),
                                           context.get_constant(types.intp, 0)])
            row = builder.load(builder.bitcast(at, ir.VectorType(ir.FloatType(),
                                                                 WIDTH).as_pointer()), align=4)
            rows.append(builder.fpext(row, vec))
        o = [splat(args[k], signature.args[k]) for k in (2, 3, 4)]
        r = [splat(args[k], signature.args[k]) for k in (5, 6, 7)]
        flags = sorted(FASTMATH)
        t0 = [builder.fmul(builder.fsub(rows[a], o[a], flags=flags), r[a], flags=flags)
              for a in range(3)]
        t1 = [builder.fmul(builder.fsub(rows[3 + a], o[a], flags=flags), r[a], flags=flags)
              for a in range(3)]
        zero = ir.Constant(vec, [0.0] * WIDTH)
        near = greater(greater(lesser(t0[0], t1[0]), lesser(t0[1], t1[1])),
                       greater(lesser(t0[2], t1[2]), zero))
        far = lesser(lesser(greater(t0[0], t1[0]), greater(t0[1], t1[1])),
                     lesser(greater(t0[2], t1[2]), splat(args[8], signature.args[8])))
        slack = builder.fmul(far, ir.Constant(vec, [1.0 + 1e-12] * WIDTH), flags=flags)
        enters = builder.fcmp_ordered("<=", near, slack)
        inf = ir.Constant(vec, [math.inf] * WIDTH)
        entry = builder.select(enters, near, inf)
        out = context.make_array(signature.args[9])(context, builder, args[9])
        builder.store(entry, builder.bitcast(out.data, vec.as_pointer()), align=8)
        bits = builder.bitcast(builder.fcmp_ordered("!=", entry, inf), ir.IntType(WIDTH))
        return builder.zext(bits, ir.IntType(64))

    return types.int64(wbox, n, ox, oy, oz, rx, ry, rz, tmax, dist), codegen


@intrinsic
def _lowest_bit(typingctx, x):
    """The index of the lowest set bit of the int64 ``x`` (not 0): one instruction."""
    if x != types.int64:
        return None

    def codegen(context, builder, signature, args):
        return builder.cttz(args[0], ir.Constant(ir.IntType(1), 1))

    return types.int64(x), codegen


@inline_kernel
def ray_at(ray, j):
    """Origin and direction of the ray in column j of a packet's ``ray`` array."""
    return (ray[ORIGIN, j], ray[ORIGIN + 1, j], ray[ORIGIN + 2, j], ray[DIRECTION, j],
            ray[DIRECTION + 1, j], ray[DIRECTION + 2, j])


# --- packets ---------------------------------------------------------------------------------
#
# The integrator traces its PACKET paths' rays together, one packet traversal of the tree for
# all of them (Wald et al. 2001, "Interactive Rendering with Coherent Ray Tracing", packets;
# the lanes' tests of a box or a primitive form one loop, which LLVM runs in SIMD lanes). A
# packet visits every node that any of its rays enters, so it pays off while many of its rays
# go the same way: in a small scene (the Cornell box's 18 quads, where every ray enters both
# leaves) a random ray costs about 20 ns in a packet of 256, against 90 ns (any hit) to 190 ns
# (closest hit) traced alone. Deep in a large tree the rays of
# a bounce part ways, and a node that few of them enter is left to each of them alone
# (:func:`_trace_lane`), as Benthin et al. 2012 ("Combining Single and Packet-Ray Tracing for
# Arbitrary Ray Distributions on the Intel MIC Architecture") switch from packets to single
# rays when a packet's utilisation drops.

#: Rays traced together (the integrator's paths in flight per thread). Larger packets spread
#: each pass's fixed costs (a node's test, a shading batch) over more paths: Cornell box, one
#: thread, 64 -> 128 -> 256: 1.36 -> 1.62 -> 1.70 M paths/s; once the work arrays' rows were
#: padded (the integrator's ROW), 512 gained another 4-7 % over 256 and 1,024 no more.
PACKET = 512
#: A node that at most this many of a packet's rays enter is traversed by each ray alone. The
#: packet's test of a node costs all PACKET lanes, so the threshold grows with the packet: the
#: Cornell box with a 44,400-triangle sphere in it, one thread, went from 0.58 M paths/s
#: (packets of 256, threshold 8) to 0.66 M (512, 32; 24 and 48 did as well); the bare box is
#: unaffected (every ray enters its two leaves). The single rays' 4-wide tree made them
#: cheaper, so more are left alone: on the 40,400-triangle mesh of ``bench_render.py``, one
#: thread, 32 -> 64 took a path from 718 to 689 ns, and its camera, bounce and shadow rays from
#: 109, 182 and 250 to 102, 172 and 232 ns (96: 104, 176, 234; 128: 106, 178, 232; 8 and 16
#: were slower).
ALONE = 64


@kernel(linked=OPTIMISED)
def _packet_enters(box, nd, ray, inv, tmax, enters, n):
    """How many of the first n lanes' rays enter box ``nd`` within (0, tmax[j]), each lane's
    verdict (0 or 1) in ``enters`` (:func:`_slab`). Idle lanes (tmax < 0) never enter."""
    corners = _corners(box, nd)
    count = 0
    for j in range(n):
        ox, oy, oz = ray_at(ray, j)[:3]
        enters[j] = _slab(corners, ox, oy, oz, inv[0, j], inv[1, j], inv[2, j], tmax[j])[1]
        count += enters[j]
    return count


@kernel(linked=OPTIMISED)
def _packet_slot(geo, slot, ray, tmax, hit, n):
    """Test the primitive in ``slot`` against the first n lanes (:func:`hit_sphere`,
    :func:`plane_distance`): where it lies within (0, tmax[j]), tmax[j] becomes its distance
    and hit[j] the slot."""
    planes = geo.planes
    b, s = slot // LANES, slot % LANES
    if planes[b, PSPH, s] != 0.0:
        c = geo.sph[geo.prim[geo.slots[slot], 1]]
        for j in range(n):
            ox, oy, oz, dx, dy, dz = ray_at(ray, j)
            old = tmax[j]
            t = hit_sphere(c, ox, oy, oz, dx, dy, dz, old)
            nearer = t > 0.0
            hit[j] = slot if nearer else hit[j]  # in this order: see below
            tmax[j] = t if nearer else old
        return
    plane = _plane(planes, b, s)
    for j in range(n):
        ox, oy, oz, dx, dy, dz = ray_at(ray, j)
        old = tmax[j]
        t = plane_distance(plane, ox, oy, oz, dx, dy, dz, old)
        nearer = t < old
        # hit first, reading hit[j] only where it is kept, then tmax from the value read
        # before: LLVM turned the other order into a masked store of tmax (a store of
        # select(c, t, tmax[j]) right after loading tmax[j] writes only where c; a store to
        # another array in between stops it), which AMD's Zen 3 cores run in microcode: a
        # quarter of the Cornell box's packet tests on znver3
        hit[j] = slot if nearer else hit[j]
        tmax[j] = t if nearer else old


@kernel
def trace_packet(geo, stack, dist, ray, inv, enters, tmax, hit, any_hit, n):
    """Trace the rays of the packet's first n lanes (``ray``: rows ORIGIN and DIRECTION hold
    their origins and unit directions, a lane each) through the tree.

    Closest hits: ``tmax[j]`` becomes the distance of lane j's nearest hit in (0, tmax[j]) and
    ``hit[j]`` its slot (the primitive is ``slots[hit[j]]``), -1 on a miss. With ``any_hit``
    the search of a lane ends at its first hit (``hit[j] >= 0``: occluded) and the whole
    traversal once every lane has one; ``tmax`` is then spent. Lanes with tmax[j] < 0 are
    idle. ``stack`` (2 STACK integers), ``dist`` (LANES numbers), ``inv`` (3 rows) and
    ``enters`` (PACKET integers) are work space."""
    box, child, slots = geo.box, geo.child, geo.slots
    busy = 0
    for j in range(n):
        _, _, _, dx, dy, dz = ray_at(ray, j)
        inv[0, j], inv[1, j], inv[2, j] = 1.0 / dx, 1.0 / dy, 1.0 / dz
        hit[j] = -1
        busy += tmax[j] > 0.0
    stack[0] = 0
    top = 1
    while top > 0 and busy > 0:
        top -= 1
        nd = stack[top]
        count = _packet_enters(box, nd, ray, inv, tmax, enters, n)
        if count == 0:
            continue
        if count <= ALONE:
            # the lanes that enter, listed in place without branches (which lanes enter is a
            # coin toss to the branch predictor), in lane order
            m = 0
            for j in range(n):
                e = enters[j]
                enters[m] = j
                m += e
            for i in range(m):
                j = enters[i]
                ox, oy, oz, dx, dy, dz = ray_at(ray, j)
                t, slot = _trace_lane(geo, stack, top, dist, nd, ox, oy, oz, dx, dy, dz,
                                      inv[0, j], inv[1, j], inv[2, j], tmax[j], any_hit)
                if slot >= 0:
                    tmax[j], hit[j] = (-1.0, slot) if any_hit else (t, slot)
                    busy -= any_hit
            continue
        c0, c1 = child[nd, 0], child[nd, 1]
        if c0 >= 0:
            stack[top], stack[top + 1] = _near_last(box, c0, c1, ray, n)
            top += 2
            continue
        for blk in range(-c0 - 1, -c0 - 1 + c1):
            for s in range(LANES):
                slot = blk * LANES + s
                if slots[slot] < 0:
                    break
                _packet_slot(geo, slot, ray, tmax, hit, n)
        if any_hit:
            for j in range(n):
                # lanes hit in this leaf are done; the store into ``enters`` (work space)
                # between reading and writing tmax keeps LLVM from making the write a masked
                # store (see _packet_slot)
                t = tmax[j]
                done = (hit[j] >= 0) & (t > 0.0)
                enters[j] = done
                tmax[j] = -1.0 if done else t
                busy -= done


@kernel(linked=OPTIMISED)
def _near_last(box, c0, c1, ray, n):
    """The children in stack order, the one the packet reaches first on top: along the axis
    that separates their centres most, the packet's mean direction decides (its rays' hits in
    the near child then cut the far child's tests short)."""
    gap, axis = -1.0, 0
    for a in range(3):
        g = abs(box[c1, 0, a] + box[c1, 1, a] - box[c0, 0, a] - box[c0, 1, a])
        if g > gap:
            gap, axis = g, a
    heading = 0.0
    for j in range(n):
        heading += ray[DIRECTION + axis, j]
    c0_low = box[c0, 0, axis] + box[c0, 1, axis] <= box[c1, 0, axis] + box[c1, 1, axis]
    return (c1, c0) if c0_low == (heading >= 0.0) else (c0, c1)


