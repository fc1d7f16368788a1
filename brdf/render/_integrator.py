"""The path tracer's kernel: unidirectional path tracing with next-event estimation, multiple
importance sampling and Russian roulette, parallel over image tiles.

A thread traces the paths of its tile in a packet of PACKET paths in flight, bounce by bounce
(a wavefront within the tile; Laine et al. 2013, "Megakernels Considered Harmful"): the
packet's rays are traced through the tree together (:func:`._intersect.trace_packet`), each
path's vertex is set up on its own, then the paths on each material are shaded together
(:mod:`._materials`, one lobe at a time over them), and the shadow rays go through the tree
together again. A finished path's lane takes the tile's next (pixel, sample) pair at once.

With derivative images asked for (:data:`Gradient`), each path also carries the derivatives of
its throughput and radiance in a material's parameters (forward mode): :func:`_shade_target`
evaluates f and its gradient on that material, :func:`_carry` and :func:`_emitted` apply the
product rule, and :func:`_settle_derivatives` adds them to the pixel's sums. Without them
``grad`` is None, whose type makes numba leave those passes out of the compiled kernels.

Scenes of a few spheres and quads with Lambertian and GGX lobes are traced another way, by
:func:`trace_blocks` (see its section below): each block of BLOCK paths whole, vertex by
vertex, every pass a loop over the block's lanes without branches, which LLVM runs in SIMD
lanes. Its estimator is the packet's, to rounding.

Each (pixel, sample) pair owns a random stream derived from (seed, pixel, sample index) alone,
and a tile's paths run in an order fixed by the tile alone, so an image is the same to the last
bit whatever the number of threads.

Changing this code
------------------
Free to change: the layouts of the work arrays (``FLOAT_LAYOUT``, ``INT_LAYOUT``,
``SHADOW_LAYOUT``: a block is added, widened or moved in its one line), PACKET, ROW, the tile
size and the split into passes, how kernels are grouped and what they are called with, and
anything else that moves no arithmetic: such a change must leave every image bit-identical.
What must stay bit-identical across thread counts (and is tested so): an image for a given
seed. It holds as long as a path's numbers depend only on its own (pixel, sample) stream, a
tile's paths run in an order fixed by the tile, and a pixel's sums are added by one thread
in that order; never draw numbers from a stream shared by lanes or threads, nor add into a
pixel from another tile. A change of the estimator (the order of operations in a formula,
what a stream's numbers are spent on) moves the bits; its commit says why.

How to check: ``tests/render/test_render_digest.py`` renders a small scene with one thread and
two and compares the bytes with each other, with a digest stored for this numba, llvmlite and
machine, and with a committed reference image (to rounding, on a compiler without a stored
digest); ``tests/render/test_blocks.py`` renders the scenes the blocks cover both ways and
compares them to rounding. The kernels are compiled with fast-math contraction and
reassociation, and a cold compile may round some lobes' formulas differently from kernels loaded
from the cache (seen with GGX and measured tables): compare renders of a change with all kernels
cached on both sides. ``benchmarks/bench_render.py`` times ten scenes against Mitsuba 3
(``--all``).
"""

import math
from collections import namedtuple

import numpy as np

from .._jit import (AS_LOWERED, OPTIMISED, SIMD_INT64_PRODUCTS, allocating_kernel, fetch_add,
                    in_threads, inline_kernel, kernel, nogil_kernel, ticks)
from .. import sampling
from ._intersect import (DIRECTION, LANES, ORIGIN, PACKET, QUAD, RAY_ROWS, SPHERE, STACK,
                         hit_sphere, plane_coordinates, plane_distance, trace_packet)
from ._lights import (AREA, ENV, area_pdf, emits_towards, env_constant, env_lookup, env_samples,
                      pick_light, rescaled_pick, sample_light)
from ..models import _kinds, fresnel, lambert, microfacet
from ..models._kernels import (BELOW_ONE, DRAW, DRAWN, GIVEN, PAIR, PDF, QUERY_ROWS,
                               mixture_gradient, stack_array, with_last_axis)
from ..models.microfacet import GGX
from ._materials import (B0, B1, K0, K1, MODEL, O0, O1, P0, P1, SHARE, TYPE, bsdf_shade,
                         material_params)
from .stats import (CLOCK_ROWS, CLOCK_SHADED, CLOCK_SHADOWS, CLOCK_STEPS, CLOCK_TOTAL, NUMBERS,
                    PATHS, RAYS, SHADING, SHADOW_RAYS, VERTICES)

MIS, BSDF, LIGHT = 0, 1, 2
#: ``opts`` layout: width, height, max depth, Russian-roulette depth, strategy, jitter, tile,
#: threads (passed in: numba.get_num_threads inside a kernel keeps numba from caching it),
#: whether to estimate the extra layers (first-hit albedo and normal, the squared radiance),
#: the material whose parameters the derivative images follow (-1: none; see :data:`Gradient`)
#: and the material whose parameters f is evaluated with on its surfaces
W, H, DEPTH, RR, STRATEGY, JITTER, TILE, THREADS, LAYERS, TARGET, EVALUATE = range(11)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


# --- random numbers ---------------------------------------------------------------------------

@kernel(linked=OPTIMISED)
def _mix(z):
    """SplitMix64's output function (Steele et al. 2014, "Fast Splittable Pseudorandom Number
    Generators", OOPSLA; constants of Vigna's reference code)."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@kernel(linked=OPTIMISED)
def _stream(seed, pixel, s):
    """Starting state of the stream of sample s of a pixel: hashes of the three, chained."""
    return _mix(_mix(_mix(np.uint64(seed) + _GOLDEN) ^ np.uint64(pixel)) ^ np.uint64(s))


@inline_kernel
def _uniform(state, j):
    """Next number in [0, 1) (53 random bits) of the stream held in ``state[j]``."""
    state[j] += _GOLDEN
    return _number(state[j])


# --- geometry at a hit --------------------------------------------------------------------------

@inline_kernel
def _surface(geo, i, a, b, px, py, pz, uv):
    """Geometric normal n, shading normal s, tangent t and texture coordinates (u, v) at point
    p of primitive i hit with parameters (a, b). A quad's t is a unit vector orthogonal to n.
    A sphere's (u, v) are (0, 0) unless ``uv`` (a textured material): their arctangent and
    arccosine were a tenth of a white furnace's render (perf: libm's atan2 and acos)."""
    j = geo.prim[i, 1]
    kind = geo.prim[i, 0]
    if kind == SPHERE:
        c = geo.sph[j]
        nx, ny, nz = (px - c[0]) / c[3], (py - c[1]) / c[3], (pz - c[2]) / c[3]
        u = v = 0.0
        if uv:
            u = sampling.arctan2(ny, nx) / (2.0 * math.pi)
            u = u + 1.0 if u < 0.0 else u  # u % 1 without fmod's call
            v = 1.0 - sampling.arccos(nz) / math.pi
        return nx, ny, nz, nx, ny, nz, -ny, nx, 0.0, u, v
    if kind == QUAD:
        g = geo.quad[j]
        return (g[3, 0], g[3, 1], g[3, 2], g[3, 0], g[3, 1], g[3, 2], g[6, 0], g[6, 1], g[6, 2],
                a, b)
    v3 = geo.tri[j]
    e1x, e1y, e1z = v3[1, 0] - v3[0, 0], v3[1, 1] - v3[0, 1], v3[1, 2] - v3[0, 2]
    e2x, e2y, e2z = v3[2, 0] - v3[0, 0], v3[2, 1] - v3[0, 1], v3[2, 2] - v3[0, 2]
    nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
    inv = 1.0 / math.sqrt(nx * nx + ny * ny + nz * nz)
    nx, ny, nz = nx * inv, ny * inv, nz * inv
    w0 = 1.0 - a - b
    vn = geo.tri_n[j]
    sx = w0 * vn[0, 0] + a * vn[1, 0] + b * vn[2, 0]
    sy = w0 * vn[0, 1] + a * vn[1, 1] + b * vn[2, 1]
    sz = w0 * vn[0, 2] + a * vn[1, 2] + b * vn[2, 2]
    sn = math.sqrt(sx * sx + sy * sy + sz * sz)
    if sn > 0.0:
        sx, sy, sz = sx / sn, sy / sn, sz / sn
    else:
        sx, sy, sz = nx, ny, nz
    uv = geo.tri_uv[j]
    u = w0 * uv[0, 0] + a * uv[1, 0] + b * uv[2, 0]
    v = w0 * uv[0, 1] + a * uv[1, 1] + b * uv[2, 1]
    return nx, ny, nz, sx, sy, sz, e1x, e1y, e1z, u, v


@kernel(linked=OPTIMISED)
def _frame(sx, sy, sz, tx, ty, tz, framed):
    """Orthonormal tangent and bitangent about the shading normal s: the tangent t itself where
    ``framed`` (a quad's, of unit length and orthogonal to s already), else following t
    (Gram-Schmidt), any tangent where t is parallel to s."""
    d = tx * sx + ty * sy + tz * sz
    gx, gy, gz = tx - d * sx, ty - d * sy, tz - d * sz
    n = math.sqrt(gx * gx + gy * gy + gz * gz)
    t, b = sampling.basis_from_axis(sx, sy, sz)
    # written as selects, but LLVM moves the rare fallback's work (a division) behind a
    # branch, and the caller's loop stays scalar (see _frames)
    along = (n < 1e-9) & (not framed)
    ax = tx if framed else (t[0] if along else gx / n)
    ay = ty if framed else (t[1] if along else gy / n)
    az = tz if framed else (t[2] if along else gz / n)
    return (ax, ay, az, b[0] if along else sy * az - sz * ay,
            b[1] if along else sz * ax - sx * az, b[2] if along else sx * ay - sy * ax)


@kernel(linked=OPTIMISED)
def _offset(px, py, pz, nx, ny, nz, side):
    """Ray origin pushed off the surface along the normal, to the side ``side`` (+1 or -1), by
    a margin relative to the point's magnitude (avoids self-intersection)."""
    eps = 1e-7 * (1.0 + max(abs(px), max(abs(py), abs(pz))))
    return px + side * eps * nx, py + side * eps * ny, pz + side * eps * nz


@inline_kernel
def _short_of(dist):
    """The length of a shadow ray towards a light at distance ``dist``, stopped just short of
    it so that the light's own surface does not block it (inf: a light at infinity)."""
    return dist * (1.0 - 1e-7) if dist < math.inf else math.inf


@kernel(linked=OPTIMISED)
def _power(a, b):
    """Veach's power heuristic with beta = 2 (Veach 1997, thesis, eq. 9.13) for density a."""
    if a == math.inf:
        return 1.0
    a2, b2 = a * a, b * b
    return a2 / (a2 + b2) if a2 + b2 > 0.0 else 0.0


# --- the packet of paths ----------------------------------------------------------------------
#
# A path's state lives in lane j of the work arrays: ``fl`` (the float rows of FLOAT_LAYOUT),
# ``il`` (the integer rows of INT_LAYOUT), ``state`` (its random stream), ``sh`` (its shadow
# ray, SHADOW_LAYOUT), ``q`` and ``f`` (the BSDF's query sets and values,
# :func:`._materials.bsdf_shade`: PAIR towards the light, DRAW the sampled direction) and
# ``lp`` (the packed parameters of its material, where its batch needs a row per path; see
# :func:`_shade`). A layout lists its blocks of rows in order, with their
# widths; the names are the blocks' first rows, so a block is added, widened or moved in one
# line (``fl`` and ``sh`` start with the ray, whose rows :func:`trace_packet` reads).

#: The vertex's uniform numbers, in rows U + k of ``fl``: the light, a point on it, the BSDF
#: sample's pair, Russian roulette
UNIFORMS = 5
PICK, ON_LIGHT, BSDF_U1, BSDF_U2, ROULETTE = range(UNIFORMS)


def _offsets(layout):
    """First rows of the consecutive blocks of ``layout`` ``((name, rows, what), ...)``, and
    the number of rows they fill. Computed once, at import: numba reads module globals as
    constants when it compiles a kernel."""
    first, k = [], 0
    for _, rows, _ in layout:
        first.append(k)
        k += rows
    return tuple(first), k


#: rows of ``fl``, block by block (the names below are the blocks' first rows)
FLOAT_LAYOUT = (
    ("RAY", RAY_ROWS, "the ray the path traces next"),
    ("T", 1, "the ray's length (inf; -1: an idle lane), then its hit distance"),
    ("THR", 3, "the path's throughput"),
    ("RAD", 3, "the radiance it has gathered"),
    ("PREV", 1, "the density of its last bounce"),
    ("N", 3, "the vertex's geometric normal, on the side the ray arrives from"),
    ("S", 3, "its shading normal"),
    ("A", 3, "its shading tangent"),
    ("B", 3, "its shading bitangent"),
    ("Q", 3, "the next ray's origin, off the surface"),
    ("LI", 3, "the light sample's incident radiance (or irradiance of a delta light)"),
    ("LPDF", 1, "its solid-angle density"),
    ("LPICK", 1, "the probability of picking its light"),
    ("EMIT", 3, "what emission seen at the vertex added per unit throughput"),
    ("U", UNIFORMS, "the vertex's uniform numbers (see _draw and below)"),
)
(RAY, T, THR, RAD, PREV, N, S, A, B, Q, LI, LPDF, LPICK, EMIT, U), FLOAT_ROWS = _offsets(
    FLOAT_LAYOUT)
O, D = RAY + ORIGIN, RAY + DIRECTION
#: rows of ``il``, block by block
INT_LAYOUT = (
    ("ALIVE", 1, "the path is in flight"),
    ("PIXEL_X", 1, "its pixel's column"),
    ("PIXEL_Y", 1, "its pixel's row"),
    ("DEPTH_", 1, "its depth (segments traced)"),
    ("SPECULAR", 1, "whether its last bounce was specular"),
    ("HIT", 1, "the slot its ray hit (-1: none)"),
    ("MAT", 1, "its shading batch (its material's SHARE)"),
    ("MATERIAL", 1, "its material"),
    ("NEE", 1, "the lane of sh that holds its shadow ray (-1: none)"),
    ("BLOCKER", 1, "what the shadow ray in each lane of sh hit"),
    ("END", 1, "whether the path ends at this vertex"),
    ("ENTERS", 1, "work space: whether a ray enters a node (tracing), the lanes whose rays "
                  "escaped (_vertices), the lanes left to shade (_shade)"),
    ("CHOSEN", 1, "work space: the lanes whose rays hit (_draw), the lobe each path sampled "
                  "(_shade)"),
    ("FRAMED", 1, "the vertex's tangent (row A) is its frame's already (a quad's)"),
    ("COUNT", 1, "the lengths of the lists of lanes"),
    ("LIST", 5, "the lists of lanes of a shading batch (see bsdf_shade)"),
)
(ALIVE, PIXEL_X, PIXEL_Y, DEPTH_, SPECULAR, HIT, MAT, MATERIAL, NEE, BLOCKER, END, ENTERS,
 CHOSEN, FRAMED, COUNT, LIST), INT_ROWS = _offsets(INT_LAYOUT)
#: rows of ``sh``, block by block
SHADOW_LAYOUT = (
    ("RAY", RAY_ROWS, "the shadow ray, from Q towards the light"),
    ("LENGTH", 1, "its length short of the light (inf: none), -1 in an idle lane"),
)
(_, LENGTH), SHADOW_ROWS = _offsets(SHADOW_LAYOUT)

#: Length of the rows of the work arrays: PACKET lanes, then 8 unused. Rows of a power of two
#: of numbers (256: 2 KiB) lie a multiple of 2 KiB apart, so a lane's numbers in every row of
#: every array fell into the same few sets of the 12-way L1 data cache, and the 50-odd rows a
#: pass reads evicted each other; the pad staggers the rows over all sets (Cornell box, packets
#: of 256: 8-10 % faster).
ROW = PACKET + 8
#: A packet's work space (:func:`_packet_space`): the path state ``fl`` (FLOAT_LAYOUT), ``il``
#: (INT_LAYOUT) and ``sh`` (SHADOW_LAYOUT), a row of ROW numbers per field; the lanes' random
#: ``state``; tracing's reciprocal directions ``inv``, ``stack`` and ``dist``; the BSDF query
#: sets ``q`` and values ``f`` (:func:`brdf.models._kernels.mixture_batch`); the lanes' packed
#: material parameters ``lp`` (PACKET rows, and a last one for a batch of one material;
#: :func:`_shade`); shading's ``sel`` and ``work``; a light sample's radiance ``li``;
#: for derivative images (K of them, 0 without), ``dl (2, 3, K, ROW)`` the derivatives of the
#: throughput (0) and the gathered radiance (1) per channel, ``df (2, PACKET, 3, K)`` those of
#: ``f`` (set PAIR: f; set DRAW: the weight f cos / pdf), and the work space of one evaluation
#: of f with its derivatives: ``fv (1, 3)``, ``dv (P, 1, 3)`` and the parameter row ``theta``.
Packet = namedtuple("Packet", "fl il state sh inv stack dist q f lp sel work li dl df fv dv "
                              "theta")
#: The running sums of a pass (:func:`render_pass`): radiance, its square, first-hit layers.
Sums = namedtuple("Sums", "acc acc2 aov")
#: Derivative images (:func:`render_pass`), of the pixels' radiance in K directions of the
#: packed parameters of material opts[TARGET]: direction k moves the slots ``slots[k]`` (-1
#: pads a row) together, and ``acc (h, w, 3, K)`` sums the derivatives of the paths' radiance.
#:
#: The estimator is detached sampling (Zeltner et al. 2021, "Monte Carlo Estimators for
#: Differential Light Transport", detached sampling): paths are drawn, weighed by MIS and ended exactly
#: as on material opts[TARGET] (the proposal), while f on its surfaces is that of material
#: opts[EVALUATE]; a path's radiance is then a smooth function of the evaluated parameters, its
#: derivative the sum over the path's factors f_theta of the others times df_theta (forward
#: mode, carried along the path), and both are unbiased for the image and its derivatives at
#: theta. Russian roulette would end paths on the evaluated throughput: the caller turns it off.
Gradient = namedtuple("Gradient", "slots acc")


@inline_kernel
def _number(state):
    """The number in [0, 1) that :func:`_uniform` draws from a stream whose state, advanced,
    is ``state``: a pure function, for loops that keep the states in registers."""
    return float(_mix(state) >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@inline_kernel
def _camera_ray(cam, x, y, jx, jy):
    """The unit direction of the camera ray through (x + jx, y + jy) in pixel units (the
    origin is the camera's, ``cam[:3]``)."""
    # the pixel's extent is packed: a division and two integer conversions less a path
    sx = (x + jx) * cam[12] - 1.0
    sy = 1.0 - (y + jy) * cam[13]
    dx = cam[3] + sx * cam[6] + sy * cam[9]
    dy = cam[4] + sx * cam[7] + sy * cam[10]
    dz = cam[5] + sx * cam[8] + sy * cam[11]
    n = math.sqrt(dx * dx + dy * dy + dz * dz)
    return dx / n, dy / n, dz / n


@kernel(linked=AS_LOWERED)
def _draw(fl, il, state):
    """The five numbers for its next vertex (rows U to U + 4) of every path whose ray hit,
    drawn from its stream (a path whose ray escaped, or that ends at the vertex, leaves some
    unused: the next path in its lane starts a stream of its own). Where most lanes hit, or
    where SIMD lanes multiply 64-bit integers (:data:`brdf._jit.SIMD_INT64_PRODUCTS`), for
    every lane in one pass that runs in SIMD lanes; else, where a quarter or more miss, for
    the lanes that hit, listed without branches, lane by lane. Without AVX-512 a lane's
    numbers cost about as much either way, and the lanes that missed are the saving (the
    white furnace, three in five: 11.0 against 6.7 ns a sample, one thread, AVX2); with it
    every lane's in SIMD lanes cost less than the hits' one by one (the furnace's numbers
    stage 3.2-4.2 against 6.3-6.7 CPU ns a sample, Zen 4)."""
    hits = il[CHOSEN]  # shading's work row, free until the paths shade
    n = 0
    for j in range(PACKET):
        hits[n] = j
        n += (il[ALIVE, j] != 0) & (il[HIT, j] >= 0)
    if SIMD_INT64_PRODUCTS or 4 * n >= 3 * PACKET:
        for k in range(UNIFORMS):
            for j in range(PACKET):
                fl[U + k, j] = _uniform(state, j)
        return
    for t in range(n):
        j = hits[t]
        for k in range(UNIFORMS):
            fl[U + k, j] = _uniform(state, j)


#: Pairs per block of :func:`_launch`.
LAUNCH_BLOCK = 64
_LOW32 = np.uint64(0xFFFFFFFF)


@inline_kernel
def _step_pairs(tile, s0, x, y, smp, n, w, cx, cy, cs):
    """The pixels and samples of the tile's next n pairs (pixel-major within a sample), from
    the pair at column x, row y of the tile and sample s0 + smp, into ``w[0, i, cx]``,
    ``w[0, i, cy]`` and ``w[0, i, cs]``; returns the pair after them. Stepped along, since
    integer division costs tens of cycles."""
    x0, y0, x1, y1 = tile
    tw, npix = x1 - x0, (x1 - x0) * (y1 - y0)
    for i in range(n):
        w[0, i, cx], w[0, i, cy], w[0, i, cs] = x0 + x, y0 + y, s0 + smp
        x += 1
        if x == tw:
            x = 0
            y += 1
            if y * tw == npix:
                y = 0
                smp += 1
    return x, y, smp


@inline_kernel
def _pair_at(tile, start):
    """Column, row within the tile and sample (from the pass's first) of the tile's pair
    ``start``: where :func:`_step_pairs` begins."""
    x0, y0, x1, y1 = tile
    tw, npix = x1 - x0, (x1 - x0) * (y1 - y0)
    k = start % npix
    return k % tw, k // tw, start // npix


@inline_kernel
def _path_start(cam, seed, width, jitter, px, py, sample):
    """A path's start: its stream's state after the jitter's two numbers (none without
    ``jitter``: the pixel's centre) and its camera ray's direction."""
    st = _stream(seed, py * width + px, sample)
    a1 = st + _GOLDEN
    a2 = a1 + _GOLDEN
    jx = _number(a1) if jitter else 0.5
    jy = _number(a2) if jitter else 0.5
    dx, dy, dz = _camera_ray(cam, px, py, jx, jy)
    return (a2 if jitter else st), dx, dy, dz


@inline_kernel
def _halves(st):
    """A stream's state in two exact halves, for work space that holds float64."""
    return float(st >> np.uint64(32)), float(st & _LOW32)


@inline_kernel
def _joined(hi, lo):
    """The stream's state from its :func:`_halves`."""
    return (np.uint64(hi) << np.uint64(32)) | np.uint64(lo)


@inline_kernel
def _launch(cam, opts, seed, tile, s0, start, lanes, n, p):
    """Start the paths of the tile's pairs ``start`` to ``start + n`` (pixel-major within a
    sample, so a packet's camera rays are neighbours) in the lanes ``lanes[:n]``: each
    pair's stream, jitter and camera ray, in blocks of LAUNCH_BLOCK in a loop without
    branches or stores to the packet's arrays, which LLVM runs in SIMD lanes (the square
    root and division of a ray's direction, and with 64-bit SIMD products its hashes, were
    a chain that a lane's start waited on, lane after lane); then into the lanes."""
    fl, il, state = p.fl, p.il, p.state
    jitter = opts[JITTER] != 0
    width = opts[W]
    x, y, s = _pair_at(tile, start)
    b = stack_array(1, LAUNCH_BLOCK, 8)
    for t0 in range(0, n, LAUNCH_BLOCK):
        m = min(LAUNCH_BLOCK, n - t0)
        x, y, s = _step_pairs(tile, s0, x, y, s, m, b, 0, 1, 2)
        for i in range(m):
            st, b[0, i, 3], b[0, i, 4], b[0, i, 5] = _path_start(
                cam, seed, width, jitter, int(b[0, i, 0]), int(b[0, i, 1]), int(b[0, i, 2]))
            b[0, i, 6], b[0, i, 7] = _halves(st)
        for i in range(m):
            j = lanes[t0 + i]
            state[j] = _joined(b[0, i, 6], b[0, i, 7])
            fl[O, j], fl[O + 1, j], fl[O + 2, j] = cam[0], cam[1], cam[2]
            fl[D, j], fl[D + 1, j], fl[D + 2, j] = b[0, i, 3], b[0, i, 4], b[0, i, 5]
            for c in range(3):
                fl[THR + c, j], fl[RAD + c, j] = 1.0, 0.0
            fl[PREV, j] = 0.0
            il[ALIVE, j], il[PIXEL_X, j], il[PIXEL_Y, j], il[DEPTH_, j] = (
                1, int(b[0, i, 0]), int(b[0, i, 1]), 0)
            il[SPECULAR, j], il[END, j] = 1, 0


@kernel(linked=AS_LOWERED)
def _advance(cam, opts, seed, tile, s0, total, start, p, sums, grad):
    """Move every lane on: a shaded path adds its light sample where the shadow ray got through
    and turns into its sampled direction (or ends: no sample, below the surface, Russian
    roulette); a path that ended goes into its pixel's running sums, and its lane takes the
    tile's next (pixel, sample) pair, from pair ``start`` of ``total`` (pixel-major within a
    sample, so a packet's camera rays are neighbours). Returns the next pair and the number of
    paths in flight."""
    fl, il = p.fl, p.il
    mis = opts[STRATEGY] == MIS
    layers = opts[LAYERS] != 0
    free = il[LIST]  # shading's lists, free until the paths shade
    nfree = 0
    for j in range(PACKET):
        if il[ALIVE, j] and not il[END, j]:
            if grad is not None:
                _carry(mis, p, j)
            _bounce(opts, mis, layers, p, sums.aov, j)
        if il[ALIVE, j] and il[END, j]:
            if grad is not None:
                _settle_derivatives(fl, il, p.dl, grad.acc, j)
            _settle(layers, fl, il, sums, j)
        free[nfree] = j
        nfree += il[ALIVE, j] == 0
    n = min(nfree, total - start)
    if n > 0:
        _launch(cam, opts, seed, tile, s0, start, free, n, p)
        if grad is not None:
            for t in range(n):
                for c in range(3):
                    for k in range(p.dl.shape[2]):
                        p.dl[0, c, k, free[t]] = p.dl[1, c, k, free[t]] = 0.0
        start += n
    busy = 0
    for j in range(PACKET):
        fl[T, j] = math.inf if il[ALIVE, j] else -1.0
        busy += il[ALIVE, j]
    return start, busy


@inline_kernel
def _vertices(opts, geo, mats, lights, p):
    """Each path at the vertex its ray found: emission seen there (or the environment on a
    miss), the end of the path or its shading frame, parameters and next-event sample. The
    shadow rays fill the first lanes of ``sh``, so that tracing them skips the paths that cast
    none. Returns the numbers of paths to shade and of shadow rays."""
    fl, il, sh, q, lp, li = p.fl, p.il, p.sh, p.q, p.lp, p.li
    prim, pmf, env_light = geo.prim, lights.pmf, lights.env_light
    strategy = opts[STRATEGY]
    nlights = pmf.shape[0]
    shading = shadows = missed = 0
    escaped = il[ENTERS]  # tracing's work row, free until the shadow rays are traced
    env_nee = nlights > 0 and env_light >= 0 and strategy != BSDF
    if env_nee:
        _env_samples(lights, p)
    for j in range(PACKET):
        # MAT -1: no shading batch (_shade), unless the path shades here
        il[NEE, j], il[END, j], il[MAT, j] = -1, 0, -1
        sh[LENGTH, j] = -1.0  # idle (slots below j are taken or idle already)
        if not il[ALIVE, j]:
            continue
        fl[EMIT, j] = fl[EMIT + 1, j] = fl[EMIT + 2, j] = 0.0
        specular = il[SPECULAR, j] != 0
        ox, oy, oz = fl[O, j], fl[O + 1, j], fl[O + 2, j]
        dx, dy, dz = fl[D, j], fl[D + 1, j], fl[D + 2, j]
        slot = il[HIT, j]
        if slot < 0:
            if env_light >= 0 and (strategy != LIGHT or specular):
                escaped[missed] = j  # sees the environment: _escaped adds it
                missed += 1
            il[END, j] = 1
            continue
        t = fl[T, j]
        hit = geo.slots[slot]
        kind = prim[hit, 0]
        a, b = 0.0, 0.0
        if kind != SPHERE:
            a, b = plane_coordinates(geo.planes, slot, ox, oy, oz, dx, dy, dz, t)
        px, py, pz = ox + t * dx, oy + t * dy, oz + t * dz
        m = prim[hit, 2]
        textured = m >= 0 and mats.mint[m, B1] > mats.mint[m, B0]
        nx, ny, nz, sx, sy, sz, tx, ty, tz, u, v = _surface(geo, hit, a, b, px, py, pz,
                                                            textured)
        light = prim[hit, 3]
        if light >= 0 and emits_towards(lights.lf[light], nx, ny, nz, -dx, -dy, -dz):
            if strategy != LIGHT or specular:
                w = 1.0
                if not specular and strategy == MIS:
                    w = _power(fl[PREV, j], pmf[light] * area_pdf(
                        geo, lights.lf[light], ox, oy, oz, t * dx, t * dy, t * dz, t, nx, ny, nz))
                for c in range(3):
                    fl[RAD + c, j] += fl[THR + c, j] * w * lights.lf[light, 3 + c]
                    fl[EMIT + c, j] = w * lights.lf[light, 3 + c]
        if il[DEPTH_, j] + 1 >= opts[DEPTH] or m < 0:
            il[END, j] = 1
            continue
        # shade on the side the ray arrives from (two-sided surfaces); signs, not branches:
        # which side of a wall a path meets it from is a coin toss across the lanes
        side = -1.0 if nx * dx + ny * dy + nz * dz > 0.0 else 1.0
        nx, ny, nz = side * nx, side * ny, side * nz
        side = -1.0 if sx * nx + sy * ny + sz * nz < 0.0 else 1.0
        sx, sy, sz = side * sx, side * sy, side * sz
        fl[N, j], fl[N + 1, j], fl[N + 2, j] = nx, ny, nz
        fl[S, j], fl[S + 1, j], fl[S + 2, j] = sx, sy, sz
        # the frame is completed by _frames, for every lane at once
        fl[A, j], fl[A + 1, j], fl[A + 2, j] = tx, ty, tz
        il[FRAMED, j] = kind == QUAD
        if textured:  # the others' rows are set when they shade (see _shade)
            material_params(mats, m, u, v, lp[j])
        il[MAT, j], il[MATERIAL, j] = mats.mint[m, SHARE], m
        qx, qy, qz = _offset(px, py, pz, nx, ny, nz, 1.0)
        fl[Q, j], fl[Q + 1, j], fl[Q + 2, j] = qx, qy, qz
        # next-event estimation: a light, a point or direction on it, and its shadow ray
        if nlights > 0:
            l, ul = pick_light(pmf, fl[U + PICK, j])
            u2 = fl[U + ON_LIGHT, j]
            if env_nee and l == env_light:
                # drawn by _env_samples, in the rows the shadow ray's sample is kept in
                lvx, lvy, lvz = q[PAIR, DRAWN, j], q[PAIR, DRAWN + 1, j], q[PAIR, DRAWN + 2, j]
                inv, dist, lpdf = 1.0, math.inf, fl[LPDF, j]
                li[0], li[1], li[2] = fl[LI, j], fl[LI + 1, j], fl[LI + 2, j]
            elif strategy != BSDF or (lights.ltype[l] != AREA and lights.ltype[l] != ENV):
                lvx, lvy, lvz, inv, dist, lpdf = sample_light(lights, geo, l, qx, qy, qz, ul, u2,
                                                              li)
            else:
                lvx, lvy, lvz, inv, dist, lpdf = 0.0, 0.0, 0.0, 1.0, 0.0, 0.0  # none
            if (lpdf > 0.0 and (li[0] > 0.0 or li[1] > 0.0 or li[2] > 0.0)
                    and lvx * nx + lvy * ny + lvz * nz > 0.0):
                ldx, ldy, ldz = lvx * inv, lvy * inv, lvz * inv
                k = il[NEE, j] = shadows
                shadows += 1
                sh[ORIGIN, k], sh[ORIGIN + 1, k], sh[ORIGIN + 2, k] = qx, qy, qz
                sh[DIRECTION, k], sh[DIRECTION + 1, k], sh[DIRECTION + 2, k] = ldx, ldy, ldz
                sh[LENGTH, k] = _short_of(dist)
                # in world space until _frames turns it into the local frame
                q[PAIR, DRAWN, j], q[PAIR, DRAWN + 1, j], q[PAIR, DRAWN + 2, j] = (
                    ldx, ldy, ldz)
                for c in range(3):
                    fl[LI + c, j] = li[c]
                fl[LPDF, j], fl[LPICK, j] = lpdf, pmf[l]
        shading += 1
    if missed > 0:
        _escaped(opts, lights, p, escaped, missed)
    _frames(p)
    return shading, shadows


#: Lanes per block of :func:`_escaped` and :func:`_env_samples`.
ESCAPED_BLOCK = 64


@inline_kernel
def _env_samples(lights, p):
    """The environment light's next-event samples of the paths that will pick it (alive, their
    ray hit, pick_light's choice the environment), drawn before the vertex loop, in blocks
    (:func:`._lights.env_samples`): direction into the query set's rows where the vertex loop
    leaves it (``q[PAIR, DRAWN]``), radiance into LI, density into LPDF. The lanes are listed
    without branches, and the rescaled pick of each stored by its place in the list."""
    fl, il, q = p.fl, p.il, p.q
    e = lights.env_light
    lanes = il[CHOSEN]  # shading's work row, free until the paths shade
    u = stack_array(1, PACKET, 2)
    n = 0
    for j in range(PACKET):
        l, ul = pick_light(lights.pmf, fl[U + PICK, j])
        lanes[n] = j
        u[0, n, 0], u[0, n, 1] = ul, fl[U + ON_LIGHT, j]
        n += (il[ALIVE, j] != 0) & (il[HIT, j] >= 0) & (l == e)
    s = stack_array(1, ESCAPED_BLOCK, 7)
    for t0 in range(0, n, ESCAPED_BLOCK):
        m = min(ESCAPED_BLOCK, n - t0)
        env_samples(lights, e, u[:, t0:t0 + m], m, s)
        for k in range(m):
            j = lanes[t0 + k]
            q[PAIR, DRAWN, j], q[PAIR, DRAWN + 1, j], q[PAIR, DRAWN + 2, j] = (
                s[0, k, 0], s[0, k, 1], s[0, k, 2])
            fl[LI, j], fl[LI + 1, j], fl[LI + 2, j] = s[0, k, 3], s[0, k, 4], s[0, k, 5]
            fl[LPDF, j] = s[0, k, 6]


@inline_kernel
def _escaped(opts, lights, p, lanes, n):
    """The environment seen by the paths in ``lanes[:n]``, whose rays escaped the scene: its
    radiance along each ray, weighed by MIS against next-event estimation, into the path's
    radiance and EMIT. In blocks: the lookups of the map (an arccosine, an arctangent, the
    pixel, four texels) in a loop over the block without branches, into work space on the
    stack; then MIS and the sums lane by lane. Made in the vertex loop, one lane at a time,
    with coin-toss branches in the pixel search, the lookups were a sixth of the
    environment-map scene's render (one thread), and this pass saves about a fifth of that."""
    fl, il = p.fl, p.il
    e = lights.env_light
    pick = lights.pmf[e]
    mis = opts[STRATEGY] == MIS
    s = stack_array(1, ESCAPED_BLOCK, 4)
    for t0 in range(0, n, ESCAPED_BLOCK):
        m = min(ESCAPED_BLOCK, n - t0)
        for k in range(m):
            j = lanes[t0 + k]
            s[0, k, 0], s[0, k, 1], s[0, k, 2], s[0, k, 3] = env_lookup(
                lights, e, fl[D, j], fl[D + 1, j], fl[D + 2, j])
        for k in range(m):
            j = lanes[t0 + k]
            le0, le1, le2, epdf = s[0, k, 0], s[0, k, 1], s[0, k, 2], s[0, k, 3]
            w = 1.0
            if il[SPECULAR, j] == 0 and mis:
                w = _power(fl[PREV, j], pick * epdf)
            fl[RAD, j] += fl[THR, j] * w * le0
            fl[RAD + 1, j] += fl[THR + 1, j] * w * le1
            fl[RAD + 2, j] += fl[THR + 2, j] * w * le2
            fl[EMIT, j], fl[EMIT + 1, j], fl[EMIT + 2, j] = w * le0, w * le1, w * le2


@kernel(linked=AS_LOWERED)
def _frames(p):
    """Complete every lane's shading frame and turn its directions into it: from the shading
    normal (row S) and tangent (row A) that :func:`_vertices` leaves, the tangent made
    orthonormal to the normal (:func:`_frame`; a quad's is already: FRAMED) and the bitangent
    (rows A, B); the direction towards the viewer in both query sets, and the light sample's
    direction (set PAIR), in that frame. One pass over the packet, apart from the vertex pass:
    there, lane by lane, Gram-Schmidt's square root and division were its longest wait (sampled
    with perf). LLVM compiles the pass scalar, branching on FRAMED and on the rare tangent
    parallel to the normal; a version in SIMD lanes (the frames in one loop, the parallel
    tangents fixed in a second, the directions through stack rows) kept the bits and rendered
    the furnace 2-8 % slower. Lanes that do not shade get numbers that nothing reads."""
    # rows of a constant length, so that LLVM sees that one row's stores do not reach another's
    fl, il = with_last_axis(p.fl, ROW), with_last_axis(p.il, ROW)
    qp, qd = with_last_axis(p.q[PAIR], ROW), with_last_axis(p.q[DRAW], ROW)
    for j in range(PACKET):
        sx, sy, sz = fl[S, j], fl[S + 1, j], fl[S + 2, j]
        ax, ay, az, bx, by, bz = _frame(sx, sy, sz, fl[A, j], fl[A + 1, j], fl[A + 2, j],
                                        il[FRAMED, j] != 0)
        fl[A, j], fl[A + 1, j], fl[A + 2, j] = ax, ay, az
        fl[B, j], fl[B + 1, j], fl[B + 2, j] = bx, by, bz
        dx, dy, dz = fl[D, j], fl[D + 1, j], fl[D + 2, j]
        vx = -(dx * ax + dy * ay + dz * az)
        vy = -(dx * bx + dy * by + dz * bz)
        vz = -(dx * sx + dy * sy + dz * sz)
        qp[GIVEN, j], qp[GIVEN + 1, j], qp[GIVEN + 2, j] = vx, vy, vz
        qd[GIVEN, j], qd[GIVEN + 1, j], qd[GIVEN + 2, j] = vx, vy, vz
        lx, ly, lz = qp[DRAWN, j], qp[DRAWN + 1, j], qp[DRAWN + 2, j]
        qp[DRAWN, j] = lx * ax + ly * ay + lz * az
        qp[DRAWN + 1, j] = lx * bx + ly * by + lz * bz
        qp[DRAWN + 2, j] = lx * sx + ly * sy + lz * sz


@kernel(linked=OPTIMISED)
def _lit(il, sh, j):
    """Whether path j's shadow ray reached its light (tracing spends an occluded ray's length);
    no branch, since that is a coin toss a branch predictor misses half the time."""
    nee = il[NEE, j]
    return (nee >= 0) & (sh[LENGTH, max(nee, 0)] >= 0.0)


@kernel(linked=AS_LOWERED)
def _shade(opts, mats, p):
    """The BSDF at each shaded path's vertex, one batch per lobe layout (materials that share
    one shade together, each path with its own parameters; see ``SHARE``): a
    sampled next direction (query set DRAW), and towards the light where the shadow ray got
    through (query set PAIR: f, and for MIS the BSDF's density there).

    A batch of one material without textures reads its parameters from one row, written once
    (``lp[PACKET]``, step 0); any other batch from a row per path, a textured material's
    written at its vertex (:func:`_vertices`) and the others' here. Copied for every path,
    the rows were 9-12 % of the white furnace's and the glossy sphere's render (one thread).

    A batch's lists of lanes are made in one pass over the lanes no earlier batch took: a pass
    over the whole packet for each batch (every lane, shaded or not, tested against it) was 8 %
    of the point-light scene's render (two batches; one thread, perf)."""
    fl, il, sh = p.fl, p.il, p.sh
    mis = opts[STRATEGY] == MIS
    lists = il[LIST:LIST + 5]
    counts = il[COUNT]
    # the lanes to shade (MAT >= 0; the others hold -1 from _vertices), listed in ``rest``
    # (tracing's work row, free here); each batch's pass takes its lanes out of the list, so
    # that the next batch's pass reads only the lanes left
    rest = il[ENTERS]
    n = 0
    for j in range(PACKET):
        rest[n] = j
        n += il[MAT, j] >= 0
    while n > 0:
        m = il[MAT, rest[0]]
        material = il[MATERIAL, rest[0]]
        n0 = n2 = n3 = left = 0
        mixed = False
        # no branches (see _lit): each list takes every lane's index, and its length moves
        # where the lane belongs
        for t in range(n):
            j = rest[t]
            here = il[MAT, j] == m
            rest[left] = j
            left += not here
            lists[0, n0] = lists[1, n0] = j
            n0 += here
            mixed |= here & (il[MATERIAL, j] != material)
            lit = here & _lit(il, sh, j)
            lists[2, n2] = j
            n2 += lit
            lists[3, n3] = j
            n3 += lit & mis & (fl[LPDF, j] < math.inf)
        n = left
        counts[0] = counts[1] = n0
        counts[2], counts[3] = n2, n3
        mint = mats.mint
        # a call in each branch, each with a constant step: one call, on rows and a step chosen
        # by the branch, rendered the furnace 9 % slower (one thread, 121-126 against 111-115
        # ns a sample)
        if mixed or mint[material, B1] > mint[material, B0]:
            # a row per path: untextured materials' rows from their parameters
            for t in range(n0):
                j = lists[0, t]
                k = il[MATERIAL, j]
                if mint[k, B1] == mint[k, B0]:
                    material_params(mats, k, 0.0, 0.0, p.lp[j])
            bsdf_shade(mats, m, p.lp, 1, p.q, p.f, fl[U + BSDF_U1], fl[U + BSDF_U2], p.sel,
                       p.work, il[CHOSEN], lists, counts)
        else:
            # one material without textures: its row, once, for every path of the batch
            material_params(mats, material, 0.0, 0.0, p.lp[PACKET])
            bsdf_shade(mats, m, p.lp[PACKET:], 0, p.q, p.f, fl[U + BSDF_U1], fl[U + BSDF_U2],
                       p.sel, p.work, il[CHOSEN], lists, counts)


@inline_kernel
def _light_scale(mis, fl, q, j):
    """What path j's light sample adds per unit of throughput times f times the light's
    radiance: cos over the sample's density and pick probability, times the MIS weight."""
    lpdf, pick = fl[LPDF, j], fl[LPICK, j]
    cos_l = max(q[PAIR, DRAWN + 2, j], 0.0)
    w = _power(pick * lpdf, q[PAIR, PDF, j]) if mis else 1.0
    return cos_l / pick if lpdf == math.inf else w * cos_l / (pick * lpdf)


@inline_kernel
def _carry(mis, p, j):
    """The derivatives of path j's light sample and of its throughput's next factor (forward
    mode, before :func:`_bounce` adds the one and multiplies the other): d(T f L s) =
    (dT f + T df) L s, d(T g) = dT g + T dg, with f and g the path's values at this vertex."""
    fl, q, f, dl, df = p.fl, p.q, p.f, p.dl, p.df
    lit = _lit(p.il, p.sh, j)
    scale = _light_scale(mis, fl, q, j)
    for c in range(3):
        t, fp, g = fl[THR + c, j], f[PAIR, j, c], f[DRAW, j, c]
        li = fl[LI + c, j] * scale
        for k in range(dl.shape[2]):
            dt = dl[0, c, k, j]
            if lit:  # an unlit lane's f and L are stale
                dl[1, c, k, j] += (dt * fp + t * df[PAIR, j, c, k]) * li
            dl[0, c, k, j] = dt * g + t * df[DRAW, j, c, k]


@inline_kernel
def _bounce(opts, mis, layers, p, aov_acc, j):
    """Path j adds its light sample where the shadow ray got through, then turns into its
    sampled direction, or ends (END) where there is none, below the surface, or by Russian
    roulette; at its first vertex it adds the first-hit layers to its pixel's sums if
    ``layers`` (at once: carrying them in rows to the path's end cost more)."""
    fl, il, q, f = p.fl, p.il, p.q, p.f
    # a select, not a branch (see _lit): an unlit lane's numbers are stale, and whatever they
    # make is dropped
    lit = _lit(il, p.sh, j)
    scale = _light_scale(mis, fl, q, j)
    for c in range(3):
        light = fl[THR + c, j] * f[PAIR, j, c] * fl[LI + c, j] * scale
        fl[RAD + c, j] += light if lit else 0.0
    lx, ly, lz = q[DRAW, DRAWN, j], q[DRAW, DRAWN + 1, j], q[DRAW, DRAWN + 2, j]
    pdf = q[DRAW, PDF, j]
    if layers and il[DEPTH_, j] == 0:
        x, y = il[PIXEL_X, j], il[PIXEL_Y, j]
        for c in range(3):
            aov_acc[y, x, c] += f[DRAW, j, c] if pdf != 0.0 else 0.0
            aov_acc[y, x, 3 + c] += fl[S + c, j]
    if pdf == 0.0:
        il[END, j] = 1
        return
    for c in range(3):
        fl[THR + c, j] *= f[DRAW, j, c]
    dx = lx * fl[A, j] + ly * fl[B, j] + lz * fl[S, j]
    dy = lx * fl[A + 1, j] + ly * fl[B + 1, j] + lz * fl[S + 1, j]
    dz = lx * fl[A + 2, j] + ly * fl[B + 2, j] + lz * fl[S + 2, j]
    if dx * fl[N, j] + dy * fl[N + 1, j] + dz * fl[N + 2, j] <= 0.0:
        il[END, j] = 1  # below the geometric surface: the shading normal would leak light
        return
    fl[O, j], fl[O + 1, j], fl[O + 2, j] = fl[Q, j], fl[Q + 1, j], fl[Q + 2, j]
    fl[D, j], fl[D + 1, j], fl[D + 2, j] = dx, dy, dz
    il[SPECULAR, j] = pdf == math.inf
    fl[PREV, j] = pdf
    il[DEPTH_, j] += 1
    if il[DEPTH_, j] >= opts[RR]:
        keep = min(max(fl[THR, j], max(fl[THR + 1, j], fl[THR + 2, j])), 0.95)
        il[END, j] = fl[U + ROULETTE, j] >= keep  # a coin toss: no branch (a path that ends
        for c in range(3):                          # here spends its throughput)
            fl[THR + c, j] /= keep


@inline_kernel
def _settle(layers, fl, il, sums, j):
    """Add the ended path j to its pixel's running sums (:func:`_pixel_sums`) and free its
    lane."""
    _pixel_sums(layers, sums, il[PIXEL_X, j], il[PIXEL_Y, j], fl[RAD, j], fl[RAD + 1, j],
                fl[RAD + 2, j])
    il[ALIVE, j] = 0


@inline_kernel
def _pixel_sums(layers, sums, x, y, r0, r1, r2):
    """Add a path's radiance (r0, r1, r2) to pixel (x, y)'s running sums, and its square's if
    ``layers``; a degenerate path (NaN, inf) is dropped, not spread."""
    for c in range(3):
        r = r0 if c == 0 else (r1 if c == 1 else r2)
        if r != r or r == math.inf:
            r = 0.0
        sums.acc[y, x, c] += r
        if layers:
            sums.acc2[y, x, c] += r * r


@inline_kernel
def _settle_derivatives(fl, il, dl, dacc, j):
    """Add the ended path j's derivatives to its pixel's in ``dacc`` (none where
    :func:`_settle` drops its radiance, or where they are not finite)."""
    x, y = il[PIXEL_X, j], il[PIXEL_Y, j]
    for c in range(3):
        r = fl[RAD + c, j]
        dropped = r != r or r == math.inf
        for k in range(dl.shape[2]):
            d = dl[1, c, k, j]
            dacc[y, x, c, k] += 0.0 if dropped or d - d != 0.0 else d


@kernel(linked=AS_LOWERED)
def _emitted(p):
    """The derivatives of what emission seen at each path's vertex added: dT times it."""
    fl, il, dl = p.fl, p.il, p.dl
    for j in range(PACKET):
        if not il[ALIVE, j]:
            continue
        for c in range(3):
            e = fl[EMIT + c, j]
            if e != 0.0:
                for k in range(dl.shape[2]):
                    dl[1, c, k, j] += dl[0, c, k, j] * e


@kernel(linked=AS_LOWERED)
def _shade_target(opts, mats, slots, p):
    """On the surfaces of material opts[TARGET], f and its derivatives with the parameters of
    material opts[EVALUATE] (see :data:`Gradient`), at the direction towards the light where
    the shadow ray got through (set PAIR: f) and at the sampled one (set DRAW: the weight f cos
    / pdf, pdf the proposal's), into ``f`` and ``df``; every other shaded path's ``df`` is 0."""
    fl, il, q, f, df, fv, dv, theta = p.fl, p.il, p.q, p.f, p.df, p.fv, p.dv, p.theta
    mint = mats.mint
    target, ev = opts[TARGET], opts[EVALUATE]
    kinds = mats.kinds[mint[ev, K0]:mint[ev, K1]]
    offs = mats.offs[mint[ev, O0]:mint[ev, O1]]
    material_params(mats, ev, 0.0, 0.0, theta)
    nd = p.dl.shape[2]
    for j in range(PACKET):
        if not il[ALIVE, j] or il[END, j]:
            continue
        for s in (PAIR, DRAW):
            for c in range(3):
                for k in range(nd):
                    df[s, j, c, k] = 0.0
        if il[MATERIAL, j] != target:
            continue
        for s in (PAIR, DRAW):
            e = q[s]
            w = 1.0
            if s == PAIR:
                if not _lit(il, p.sh, j):
                    continue
            else:
                pdf = e[PDF, j]
                if not (pdf > 0.0 and pdf < math.inf):
                    continue
                w = e[DRAWN + 2, j] / pdf
            # f(wi = l, wo = v), the renderer's order (see _materials)
            mixture_gradient(kinds, offs, theta, e[DRAWN, j], e[DRAWN + 1, j], e[DRAWN + 2, j],
                             e[GIVEN, j], e[GIVEN + 1, j], e[GIVEN + 2, j], fv, dv)
            for c in range(3):
                f[s, j, c] = fv[0, c] * w
                for k in range(nd):
                    d = 0.0
                    for t in range(slots.shape[1]):
                        i = slots[k, t]
                        if i >= 0:
                            d += dv[i, 0, c]
                    df[s, j, c, k] = d * w


@allocating_kernel(linked=AS_LOWERED)
def _clock_space(clock):
    """A thread's counts of ``clock``'s rows (zeroed), or None without a clock."""
    if clock is None:
        return None
    return np.zeros(CLOCK_ROWS, np.int64)


@inline_kernel
def _lap(clock, spent, row, since):
    """With a clock, the time-stamp counter now, after adding the ticks since ``since`` to row
    ``row`` of ``spent`` (a stage's; -1: none); without, 0. Without a clock numba leaves the
    timing out of the compiled kernel."""
    if clock is None:
        return 0
    now = ticks()
    if row >= 0:
        spent[row] += now - since
    return now


@inline_kernel
def _count(clock, spent, shading, shadows):
    """With a clock, count a packet step, its vertices shaded and its shadow rays."""
    if clock is not None:
        spent[CLOCK_STEPS] += 1
        spent[CLOCK_SHADED] += shading
        spent[CLOCK_SHADOWS] += shadows


@inline_kernel
def _clock_in(clock, spent, began):
    """With a clock, a thread's counts added to it (atomically: the threads share it), its
    ticks since ``began`` as the total."""
    if clock is not None:
        _lap(clock, spent, CLOCK_TOTAL, began)
        for r in range(CLOCK_ROWS):
            fetch_add(clock[r:], spent[r])


@allocating_kernel(linked=AS_LOWERED)
def _packet_space(nparams, nlobes, nd):
    """A packet's work space, a :data:`Packet` for ``nd`` derivative images (zeroed: idle
    lanes' leftovers steer the packet's traversal, so they must not depend on what the memory
    held)."""
    return Packet(np.zeros((FLOAT_ROWS, ROW)), np.zeros((INT_ROWS, ROW), np.int64),
                  np.zeros(PACKET, np.uint64), np.zeros((SHADOW_ROWS, ROW)), np.zeros((3, ROW)),
                  np.zeros(2 * STACK, np.int64), np.zeros(LANES), np.zeros((2, QUERY_ROWS, ROW)),
                  np.zeros((2, PACKET, 3)), np.zeros((PACKET + 1, nparams)),
                  np.zeros((PACKET, nlobes)), np.zeros((PACKET, 2)), np.zeros(3),
                  np.zeros((2, 3, nd, ROW)), np.zeros((2, PACKET, 3, nd)), np.zeros((1, 3)),
                  np.zeros((nparams, 1, 3)), np.zeros(nparams))


@nogil_kernel
def trace_tiles(cam, opts, geo, mats, lights, seed, s0, s1, sums, grad, queue, nparams,
                nlobes, clock):
    """Trace tiles of opts[TILE]^2 pixels, each taken from the queue the threads share
    (``queue[0]``, the next tile's number, row-major over the image) as the last is done, until
    none is left: samples s0 .. s1 - 1 of each pixel into the running ``sums`` (see
    :func:`render_pass`), for each the radiance along its camera ray, and with opts[LAYERS] the
    first hit's albedo estimate (f cos / pdf of one BSDF sample) and shading normal; the
    derivative images into ``grad``; with a ``clock`` (else None), the ticks of each stage
    and the counts after them added to its rows (:data:`.stats.CLOCK_ROWS`). Each tile gets a
    new packet work space (:func:`_packet_space`, for materials of at most ``nparams`` packed
    parameters and ``nlobes`` lobes), so that nothing a thread traced before steers it. The
    tile's loop is written here rather than in a kernel of its own: called, it rendered the
    white furnace about 15 % slower (one thread); inlined, its own compile was wasted (11 s of
    CPU)."""
    spent = _clock_space(clock)
    began = _lap(clock, spent, -1, 0)
    w, h, size = opts[W], opts[H], opts[TILE]
    nd = 0
    if grad is not None:
        nd = grad.slots.shape[0]
    tx_n = (w + size - 1) // size
    ntiles = tx_n * ((h + size - 1) // size)
    while True:
        k = fetch_add(queue, 1)
        if k >= ntiles:
            _clock_in(clock, spent, began)
            return
        x0, y0 = (k % tx_n) * size, (k // tx_n) * size
        tile = (x0, y0, min(x0 + size, w), min(y0 + size, h))
        total = (tile[2] - x0) * (tile[3] - y0) * (s1 - s0)
        p = _packet_space(nparams, nlobes, nd)
        fl, il, sh = p.fl, p.il, p.sh
        start = 0
        while True:
            t = _lap(clock, spent, -1, 0)
            start, busy = _advance(cam, opts, seed, tile, s0, total, start, p, sums, grad)
            t = _lap(clock, spent, PATHS, t)
            if busy == 0:
                break
            trace_packet(geo, p.stack, p.dist, fl, p.inv, il[ENTERS], fl[T], il[HIT], False,
                         PACKET)
            t = _lap(clock, spent, RAYS, t)
            _draw(fl, il, p.state)
            t = _lap(clock, spent, NUMBERS, t)
            shading, shadows = _vertices(opts, geo, mats, lights, p)
            if grad is not None:
                _emitted(p)
            t = _lap(clock, spent, VERTICES, t)
            if shadows > 0:
                # whole SIMD registers of lanes (eight numbers: AVX-512)
                trace_packet(geo, p.stack, p.dist, sh, p.inv, il[ENTERS], sh[LENGTH],
                             il[BLOCKER], True, min(PACKET, (shadows + 7) // 8 * 8))
            t = _lap(clock, spent, SHADOW_RAYS, t)
            if shading > 0:
                _shade(opts, mats, p)
                if grad is not None:
                    _shade_target(opts, mats, grad.slots, p)
            _lap(clock, spent, SHADING, t)
            _count(clock, spent, shading, shadows)


# --- paths whole in blocks of lanes -------------------------------------------------------------
#
# Scenes of a few spheres and quads with Lambertian and GGX lobes (:func:`block_scene`) are
# traced by :func:`trace_blocks` instead of the packet's passes: a block of BLOCK paths
# advances vertex by vertex, each step a few loops over the block's lanes without branches or
# calls, its state in work space on the stack (which LLVM knows no other array to alias), every
# primitive tested against every lane's ray in turn, every lobe computed for every lane and
# selected. LLVM runs those loops in SIMD lanes, where the packet's passes branch per lane on
# the kind of primitive, light and lobe. Only the lights' samples other than the
# environment's are drawn lane by lane (:func:`._lights.sample_light`). The paths in flight
# are kept in the first lanes (:func:`_block_compact`), so that the passes run over no lane
# without one. The estimator is the packet's: the same streams and numbers, the same light
# sample, lobe choice, MIS weights, Russian roulette and ends of paths; only the order of some
# floating-point operations differs, so an image differs from the packet's by rounding and by
# the paths it moves (a different rounding can turn a ray's hit into a miss).

#: Paths per block.
BLOCK = 64
#: Packed parameters of a material the blocks cover, at most: Lambert's albedo (3) and a GGX
#: lobe's ks (3), roughness (2), masking and Fresnel term (7).
PARAMS_MAX = 16
#: Primitives at most in a scene traced in blocks: each is tested against every ray, where the
#: packet's tree skips most of them.
BLOCK_PRIMS = 32
#: Whether :func:`render_pass` traces the scenes that :func:`block_scene` covers in blocks
#: (else in the packet, as every other scene; tests compare the two).
use_blocks = True
#: Columns of the block tracer's primitive table: whether it is a sphere, its centre (a
#: quad's corner) and radius (a sphere's), its normal, tangent and dual vectors (a quad's: its
#: texture coordinates are (p - corner) . q1 and . q2), its material's row of the lobes, the
#: light it is (-1: none).
PT_SPHERE, PT_C, PT_R, PT_N, PT_T, PT_Q1, PT_Q2, PT_MAT, PT_LIGHT, PRIM_COLS = (
    0, 1, 4, 5, 8, 11, 14, 17, 18, 19)
#: Columns of the block tracer's lobe table (:func:`block_scene`): whether the Lambertian lobe
#: comes first in the material's mixture, its albedo, GGX's ks, roughness and masking (1:
#: separable), whether the material is traced at all (0: no material, the path ends there),
#: whether textures bind its parameters, and where its Lambertian and GGX lobes' parameters
#: start in its packed row (-1: no such lobe; :func:`._materials.material_params`).
LOBE_FIRST, KD, KS, ALPHA_X, ALPHA_Y, SEPARABLE, SHADED, TEXTURED, OFF_L, OFF_G, LOBE_COLS = (
    0, 1, 4, 7, 8, 9, 10, 11, 12, 13, 14)
#: The lobe parameters a lane carries (:func:`_block_params`), textures applied: the columns
#: KD to ALPHA_Y of the lobe table.
LANE_PARAMS = ALPHA_Y + 1 - KD
#: rows of a block's work space (stack_array(1, BLOCK, BLOCK_ROWS)), a lane per path in flight
BLOCK_LAYOUT = (
    ("BO", 3, "the ray's origin"),
    ("BD", 3, "its direction"),
    ("BT", 1, "its hit distance (inf: none)"),
    ("BHIT", 1, "the primitive it hit"),
    ("BTHR", 3, "the path's throughput"),
    ("BRAD", 3, "its radiance"),
    ("BPREV", 1, "the density of its last bounce (inf: the camera's ray)"),
    ("BLIVE", 1, "1 while the path is in flight, 0 once it ended"),
    ("BDEPTH", 1, "its depth (segments traced)"),
    ("BPX", 2, "its pixel (x, y)"),
    ("BSTATE", 2, "its random stream's state, in two exact halves"),
    ("BU", UNIFORMS, "the vertex's uniform numbers"),
    ("BN", 3, "the vertex's normal, on the ray's side"),
    ("BA", 3, "its shading tangent"),
    ("BB", 3, "its bitangent"),
    ("BQ", 3, "the next rays' origin"),
    ("BMAT", 1, "its material's row of the lobe table"),
    ("BPAR", LANE_PARAMS, "its lobes' parameters there (KD to ALPHA_Y of the lobe table)"),
    ("BSHADED", 1, "1 where the path shades its vertex, 2 where that is its first"),
    ("BL", 3, "the light sample's unit direction (world)"),
    ("BLI", 3, "its radiance, then what it adds to the path's if the shadow ray gets through"),
    ("BLEN", 1, "its density, then the shadow ray's length (-1: none, or occluded)"),
    ("BREACH", 1, "the shadow ray's length short of the light (inf: none)"),
    ("BPICK", 1, "the probability of picking its light"),
    ("BW", 3, "the BSDF sample's weight f cos / pdf"),
)
((BO, BD, BT, BHIT, BTHR, BRAD, BPREV, BLIVE, BDEPTH, BPX, BSTATE, BU, BN, BA, BB, BQ, BMAT,
  BPAR, BSHADED, BL, BLI, BLEN, BREACH, BPICK, BW), BLOCK_ROWS) = _offsets(BLOCK_LAYOUT)
#: The rows a path carries from vertex to vertex (the first ones): what compaction moves.
CARRIED = BU


def block_scene(geo, mats, lights, opts):
    """The tables :func:`trace_blocks` takes, ``(lobes, prims)``, or None where the blocks do
    not cover the render: a scene of 1 to BLOCK_PRIMS spheres and quads (no triangles) with at
    least one light, MIS, and every material a Lambertian lobe, a GGX lobe without a Fresnel
    term, or one of each, textures binding any of their parameters but masking. ``lobes`` has
    a row per material (LOBE_COLS) and a last one of zeros for shapes without one; ``prims``
    a row per primitive (PRIM_COLS)."""
    prim = geo.prim
    if (not use_blocks or geo.tri.shape[0] or not 0 < prim.shape[0] <= BLOCK_PRIMS
            or lights.pmf.shape[0] == 0 or opts[STRATEGY] != MIS):
        return None
    mint = mats.mint
    lobes = np.zeros((mint.shape[0] + 1, LOBE_COLS))
    for m in range(mint.shape[0]):
        if mint[m, TYPE] != MODEL:
            return None
        kinds = [int(k) for k in mats.kinds[mint[m, K0]:mint[m, K1]]]
        offs = mats.offs[mint[m, O0]:mint[m, O1]]
        params = mats.params[mint[m, P0]:mint[m, P1]]
        if sorted(kinds) not in ([_kinds.LAMBERT], [_kinds.GGX],
                                 sorted([_kinds.LAMBERT, _kinds.GGX])):
            return None
        row = lobes[m]
        row[LOBE_FIRST] = float(kinds[0] == _kinds.LAMBERT)
        row[ALPHA_X] = row[ALPHA_Y] = 1.0  # a lobe of ks 0 is never picked nor counted
        row[SEPARABLE] = row[SHADED] = 1.0
        row[OFF_L] = row[OFF_G] = -1.0
        for l, kind in enumerate(kinds):
            q = params[offs[l]:offs[l + 1]]
            if kind == _kinds.LAMBERT:
                row[KD:KD + 3], row[OFF_L] = q[:3], offs[l]
            elif q[6] != fresnel.NONE:  # the layout of brdf.models.microfacet, 3 channels
                return None
            else:
                row[KS:KS + 3], row[ALPHA_X], row[ALPHA_Y] = q[:3], q[3], q[4]
                row[SEPARABLE], row[OFF_G] = float(q[5] == 0.0), offs[l]
        # textures may bind a Lambertian albedo, a GGX lobe's ks and roughness
        row[TEXTURED] = float(mint[m, B1] > mint[m, B0])
        for b in range(mint[m, B0], mint[m, B1]):
            slot = mats.bind[b, 1]
            l = int(np.searchsorted(offs, slot, side="right")) - 1
            if slot - offs[l] >= (3 if kinds[l] == _kinds.LAMBERT else 5):
                return None
    prims = np.zeros((prim.shape[0], PRIM_COLS))
    for i, (kind, j, m, light) in enumerate(prim):
        if kind == SPHERE:
            prims[i, PT_SPHERE] = 1.0
            prims[i, PT_C:PT_C + 3], prims[i, PT_R] = geo.sph[j, :3], geo.sph[j, 3]
        else:
            prims[i, PT_R] = 1.0  # a quad's lanes divide by it too, then select its normal
            prims[i, PT_C:PT_C + 3] = geo.quad[j, 0]
            prims[i, PT_N:PT_N + 3], prims[i, PT_T:PT_T + 3] = geo.quad[j, 3], geo.quad[j, 6]
            prims[i, PT_Q1:PT_Q1 + 3], prims[i, PT_Q2:PT_Q2 + 3] = geo.quad[j, 4], geo.quad[j, 5]
        prims[i, PT_MAT] = m if m >= 0 else mint.shape[0]
        prims[i, PT_LIGHT] = light
    return lobes, prims


@inline_kernel
def _block_hits(geo, s, m, shadow):
    """Each lane's ray (rows BO, BD) against every primitive: the nearest hit's distance and
    primitive into rows BT and BHIT; for ``shadow`` rays (from BQ along BL, of length BLEN),
    BLEN set to -1 where one is hit short of the light. A loop over the lanes per primitive."""
    o, d = (BQ, BL) if shadow else (BO, BD)
    if not shadow:
        for k in range(m):
            s[0, k, BT], s[0, k, BHIT] = math.inf, -1.0
    prim = geo.prim
    for i in range(prim.shape[0]):
        j = prim[i, 1]
        if prim[i, 0] == SPHERE:
            c = (geo.sph[j, 0], geo.sph[j, 1], geo.sph[j, 2], geo.sph[j, 3])
            for k in range(m):
                t = hit_sphere(c, s[0, k, o], s[0, k, o + 1], s[0, k, o + 2], s[0, k, d],
                               s[0, k, d + 1], s[0, k, d + 2], _block_reach(s, k, shadow))
                _block_hit(s, k, t if t > 0.0 else math.inf, i, shadow)
        else:
            g = geo.quad[j]
            plane = ((g[3, 0], g[3, 1], g[3, 2]), (g[0, 0], g[0, 1], g[0, 2]),
                     (g[4, 0], g[4, 1], g[4, 2]), (g[5, 0], g[5, 1], g[5, 2]), 0.0)
            for k in range(m):
                t = plane_distance(plane, s[0, k, o], s[0, k, o + 1], s[0, k, o + 2],
                                   s[0, k, d], s[0, k, d + 1], s[0, k, d + 2],
                                   _block_reach(s, k, shadow))
                _block_hit(s, k, t, i, shadow)


@inline_kernel
def _block_reach(s, k, shadow):
    """How far lane k's ray may go: its shadow ray's length, or its nearest hit so far."""
    return s[0, k, BLEN] if shadow else s[0, k, BT]


@inline_kernel
def _block_hit(s, k, t, i, shadow):
    """Lane k's ray met primitive i at distance t (inf: not within its reach): a shadow ray is
    blocked (BLEN -1); another ray's nearest hit is this one (BT, BHIT)."""
    met = t < math.inf
    if shadow:
        s[0, k, BLEN] = -1.0 if met else s[0, k, BLEN]
    else:
        s[0, k, BT] = t if met else s[0, k, BT]
        s[0, k, BHIT] = float(i) if met else s[0, k, BHIT]


@inline_kernel
def _padded(m):
    """m lanes rounded up to whole SIMD registers (eight lanes: AVX-512), so that a pass over
    them runs without a scalar remainder."""
    return min(BLOCK, (m + 7) // 8 * 8)


@inline_kernel
def _block_idle(s, m):
    """Lanes m to :func:`_padded` (m) made idle (no path, no hit); returns their end."""
    mm = _padded(m)
    for k in range(m, mm):
        s[0, k, BLIVE], s[0, k, BT] = 0.0, math.inf
    return mm


@inline_kernel
def _block_launch(cam, opts, seed, tile, s0, start, n, s):
    """Start the paths of the tile's pairs ``start`` to ``start + n`` (pixel-major within a
    sample, as :func:`_launch`) in lanes 0 to n - 1: each pair's stream, jitter and camera
    ray. The pairs' pixels and samples are stepped along first (:func:`_step_pairs`), then
    the rest runs in a loop without branches over whole SIMD registers (the lanes past n get
    numbers that nothing reads)."""
    jitter = opts[JITTER] != 0
    width = opts[W]
    x, y, smp = _pair_at(tile, start)
    _step_pairs(tile, s0, x, y, smp, n, s, BPX, BPX + 1, BT)
    for k in range(n, _padded(n)):
        s[0, k, BPX] = s[0, k, BPX + 1] = s[0, k, BT] = 0.0
    for k in range(_padded(n)):
        st, s[0, k, BD], s[0, k, BD + 1], s[0, k, BD + 2] = _path_start(
            cam, seed, width, jitter, int(s[0, k, BPX]), int(s[0, k, BPX + 1]), int(s[0, k, BT]))
        s[0, k, BSTATE], s[0, k, BSTATE + 1] = _halves(st)
        s[0, k, BO], s[0, k, BO + 1], s[0, k, BO + 2] = cam[0], cam[1], cam[2]
        s[0, k, BPREV] = math.inf  # the camera's ray: no MIS on what it sees
        s[0, k, BLIVE] = 1.0 if k < n else 0.0
        s[0, k, BDEPTH] = 0.0
        for c in range(3):
            s[0, k, BTHR + c], s[0, k, BRAD + c] = 1.0, 0.0


@inline_kernel
def _block_compact(s, m, sums, layers):
    """Settle the paths in lanes 0 .. m - 1 that ended or whose rays escaped
    (:func:`_pixel_sums`), and move the others into their lanes, so that the paths that go on
    fill lanes 0 .. m' - 1 and the passes over the vertices run over no lane without one (a
    lane from the end into each gap: the order is fixed by the lanes alone). Returns m'."""
    keep = stack_array(1, BLOCK, 1)
    for k in range(m):
        keep[0, k, 0] = (s[0, k, BLIVE] > 0.0) & (s[0, k, BT] < math.inf)
    for k in range(m):
        if keep[0, k, 0] == 0.0:
            _pixel_sums(layers, sums, int(s[0, k, BPX]), int(s[0, k, BPX + 1]), s[0, k, BRAD],
                        s[0, k, BRAD + 1], s[0, k, BRAD + 2])
    i, j = 0, m - 1
    while True:
        while i <= j and keep[0, i, 0] != 0.0:
            i += 1
        while j > i and keep[0, j, 0] == 0.0:
            j -= 1
        if i >= j:
            return i
        for r in range(CARRIED):
            s[0, i, r] = s[0, j, r]
        keep[0, i, 0], keep[0, j, 0] = 1.0, 0.0
        i += 1
        j -= 1


@inline_kernel
def _block_seen(s, k, le0, le1, le2, epdf, pick):
    """Lane k's share of :func:`_block_escaped`, with the environment's radiance and density
    along its ray."""
    w = _power(s[0, k, BPREV], pick * epdf)
    seen = (s[0, k, BLIVE] > 0.0) & (s[0, k, BT] == math.inf)
    s[0, k, BRAD] += s[0, k, BTHR] * w * le0 if seen else 0.0
    s[0, k, BRAD + 1] += s[0, k, BTHR + 1] * w * le1 if seen else 0.0
    s[0, k, BRAD + 2] += s[0, k, BTHR + 2] * w * le2 if seen else 0.0


@inline_kernel
def _block_escaped(lights, s, m):
    """The environment seen by the paths whose rays escaped, weighed against next-event
    estimation (see :func:`_escaped`), added to their radiance. A constant environment is
    looked up once, outside the loop over the lanes; a map along the escaped rays only, listed
    without branches (its lookups kept a loop over every lane scalar)."""
    e = lights.env_light
    if e < 0:
        return
    pick = lights.pmf[e]
    if env_constant(lights, e):
        le0, le1, le2, epdf = env_lookup(lights, e, 0.0, 0.0, 1.0)
        for k in range(m):
            _block_seen(s, k, le0, le1, le2, epdf, pick)
        return
    lanes = stack_array(1, BLOCK, 1)
    looked = stack_array(1, BLOCK, 4)
    n = 0
    for k in range(m):
        lanes[0, n, 0] = k
        n += (s[0, k, BLIVE] > 0.0) & (s[0, k, BT] == math.inf)
    for i in range(n):
        k = int(lanes[0, i, 0])
        looked[0, i, 0], looked[0, i, 1], looked[0, i, 2], looked[0, i, 3] = env_lookup(
            lights, e, s[0, k, BD], s[0, k, BD + 1], s[0, k, BD + 2])
    for i in range(n):
        _block_seen(s, int(lanes[0, i, 0]), looked[0, i, 0], looked[0, i, 1], looked[0, i, 2],
                    looked[0, i, 3], pick)


@inline_kernel
def _block_emission(lights, geo, pt, s, m):
    """Emission seen where the paths' rays hit an area light (see :func:`_vertices`), weighed
    against next-event estimation, added to their radiance: lane by lane, for the lanes
    listed (without branches) whose primitive emits."""
    lanes = stack_array(1, BLOCK, 1)
    n = 0
    for k in range(m):
        i = int(s[0, k, BHIT]) if s[0, k, BT] < math.inf else 0
        lanes[0, n, 0] = k
        n += (s[0, k, BLIVE] > 0.0) & (s[0, k, BT] < math.inf) & (pt[i, PT_LIGHT] >= 0.0)
    for a in range(n):
        k = int(lanes[0, a, 0])
        i = int(s[0, k, BHIT])
        light = int(pt[i, PT_LIGHT])
        f = lights.lf[light]
        t = s[0, k, BT]
        ox, oy, oz = s[0, k, BO], s[0, k, BO + 1], s[0, k, BO + 2]
        dx, dy, dz = s[0, k, BD], s[0, k, BD + 1], s[0, k, BD + 2]
        nx, ny, nz = _block_normal(pt, i, ox + t * dx, oy + t * dy, oz + t * dz)
        if emits_towards(f, nx, ny, nz, -dx, -dy, -dz):
            w = _power(s[0, k, BPREV], lights.pmf[light] * area_pdf(
                geo, f, ox, oy, oz, t * dx, t * dy, t * dz, t, nx, ny, nz))
            for c in range(3):
                s[0, k, BRAD + c] += s[0, k, BTHR + c] * w * f[3 + c]


@inline_kernel
def _block_normal(pt, i, px, py, pz):
    """The geometric normal of primitive i at point p (the outward one; see :func:`_surface`)."""
    sphere = pt[i, PT_SPHERE] != 0.0
    r = pt[i, PT_R]
    return ((px - pt[i, PT_C]) / r if sphere else pt[i, PT_N],
            (py - pt[i, PT_C + 1]) / r if sphere else pt[i, PT_N + 1],
            (pz - pt[i, PT_C + 2]) / r if sphere else pt[i, PT_N + 2])


@inline_kernel
def _block_surface(opts, lobes, pt, s, m):
    """Every lane's vertex (see :func:`_vertices`): the normal on the side the ray arrives
    from, the shading frame (:func:`_frame`), the next rays' origin, the material, and whether
    the path shades here (alive, its ray hit, a material, depth to spare), into rows BN, BA, BB,
    BQ, BMAT and BSHADED. A miss's numbers are computed at primitive 0 and dropped. Returns the
    number of paths that shade."""
    shading = 0
    for k in range(m):
        t = s[0, k, BT]
        hit = t < math.inf
        dx, dy, dz = s[0, k, BD], s[0, k, BD + 1], s[0, k, BD + 2]
        i = int(s[0, k, BHIT]) if hit else 0
        tt = t if hit else 0.0
        px = s[0, k, BO] + tt * dx
        py = s[0, k, BO + 1] + tt * dy
        pz = s[0, k, BO + 2] + tt * dz
        sphere = pt[i, PT_SPHERE] != 0.0
        nx, ny, nz = _block_normal(pt, i, px, py, pz)
        tx = -ny if sphere else pt[i, PT_T]
        ty = nx if sphere else pt[i, PT_T + 1]
        tz = 0.0 if sphere else pt[i, PT_T + 2]
        mat = pt[i, PT_MAT]
        depth = s[0, k, BDEPTH]
        shaded = ((s[0, k, BLIVE] > 0.0) & hit & (depth + 1.0 < opts[DEPTH])
                  & (lobes[int(mat), SHADED] != 0.0))
        # two-sided: the normal on the side the ray arrives from
        side = -1.0 if nx * dx + ny * dy + nz * dz > 0.0 else 1.0
        nx, ny, nz = side * nx, side * ny, side * nz
        ax, ay, az, bx, by, bz = _frame(nx, ny, nz, tx, ty, tz, not sphere)
        s[0, k, BN], s[0, k, BN + 1], s[0, k, BN + 2] = nx, ny, nz
        s[0, k, BA], s[0, k, BA + 1], s[0, k, BA + 2] = ax, ay, az
        s[0, k, BB], s[0, k, BB + 1], s[0, k, BB + 2] = bx, by, bz
        s[0, k, BQ], s[0, k, BQ + 1], s[0, k, BQ + 2] = _offset(px, py, pz, nx, ny, nz, 1.0)
        s[0, k, BMAT] = mat
        s[0, k, BSHADED] = (2.0 if depth == 0.0 else 1.0) if shaded else 0.0
        shading += shaded
    return shading


@inline_kernel
def _block_params(mats, lobes, pt, s, m, textured):
    """Every lane's lobe parameters (rows BPAR): its material's; with ``textured``, those that
    textures bind at a shading vertex of a textured material, looked up there lane by lane
    (:func:`._materials.material_params`, at the texture coordinates :func:`_surface` gives:
    a quad's (a, b), a sphere's longitude and latitude)."""
    for k in range(m):
        mat = int(s[0, k, BMAT])
        for c in range(LANE_PARAMS):
            s[0, k, BPAR + c] = lobes[mat, KD + c]
    if not textured:
        return
    row = stack_array(1, PARAMS_MAX, 1)
    for k in range(m):
        mat = int(s[0, k, BMAT])
        if s[0, k, BSHADED] == 0.0 or lobes[mat, TEXTURED] == 0.0:
            continue
        i = int(s[0, k, BHIT])
        t = s[0, k, BT]
        px = s[0, k, BO] + t * s[0, k, BD]
        py = s[0, k, BO + 1] + t * s[0, k, BD + 1]
        pz = s[0, k, BO + 2] + t * s[0, k, BD + 2]
        if pt[i, PT_SPHERE] != 0.0:
            nx, ny, nz = _block_normal(pt, i, px, py, pz)
            u = sampling.arctan2(ny, nx) / (2.0 * math.pi)
            u = u + 1.0 if u < 0.0 else u
            v = 1.0 - sampling.arccos(nz) / math.pi
        else:
            hx, hy, hz = px - pt[i, PT_C], py - pt[i, PT_C + 1], pz - pt[i, PT_C + 2]
            u = hx * pt[i, PT_Q1] + hy * pt[i, PT_Q1 + 1] + hz * pt[i, PT_Q1 + 2]
            v = hx * pt[i, PT_Q2] + hy * pt[i, PT_Q2 + 1] + hz * pt[i, PT_Q2 + 2]
        material_params(mats, mat, u, v, row[0, :, 0])
        ol, og = int(lobes[mat, OFF_L]), int(lobes[mat, OFF_G])
        if ol >= 0:
            for c in range(3):
                s[0, k, BPAR + c] = row[0, ol + c, 0]
        if og >= 0:
            for c in range(5):
                s[0, k, BPAR + KS - KD + c] = row[0, og + c, 0]


@inline_kernel
def _block_light_samples(lights, geo, s, m):
    """The next-event sample of every path that shades (see :func:`_vertices`): a light picked
    by :func:`._lights.pick_light`, a direction towards it, its radiance and density, the
    shadow ray's length and the pick's probability, into rows BL, BLI, BLEN, BREACH and BPICK.
    The environment's samples are drawn in one loop (:func:`._lights.env_samples`), the other
    lights' lane by lane (:func:`._lights.sample_light`). With the environment the one light,
    every lane draws one, which costs less than listing the lanes."""
    pmf = lights.pmf
    e = lights.env_light
    lanes = stack_array(1, BLOCK, 1)
    u = stack_array(1, BLOCK, 2)
    drawn = stack_array(1, BLOCK, 7)
    n = 0
    if pmf.shape[0] == 1 and e == 0:
        every = env_constant(lights, e)
        p0 = pmf[0]
        for k in range(m):
            lanes[0, n, 0] = k
            u[0, n, 0] = rescaled_pick(s[0, k, BU + PICK], 0.0, p0)
            u[0, n, 1] = s[0, k, BU + ON_LIGHT]
            s[0, k, BPICK] = p0
            n += every | (s[0, k, BSHADED] != 0.0)
    else:
        li = stack_array(1, 3, 1)
        for k in range(m):
            if s[0, k, BSHADED] == 0.0:
                continue
            l, ul = pick_light(pmf, s[0, k, BU + PICK])
            s[0, k, BPICK] = pmf[l]
            if l == e:
                lanes[0, n, 0] = k
                u[0, n, 0], u[0, n, 1] = ul, s[0, k, BU + ON_LIGHT]
                n += 1
                continue
            vx, vy, vz, inv, dist, lpdf = sample_light(
                lights, geo, l, s[0, k, BQ], s[0, k, BQ + 1], s[0, k, BQ + 2], ul,
                s[0, k, BU + ON_LIGHT], li[0, :, 0])
            s[0, k, BL], s[0, k, BL + 1], s[0, k, BL + 2] = vx * inv, vy * inv, vz * inv
            for c in range(3):
                s[0, k, BLI + c] = li[0, c, 0]
            s[0, k, BLEN] = lpdf
            s[0, k, BREACH] = _short_of(dist)
    env_samples(lights, e, u, n, drawn)
    for a in range(n):
        k = int(lanes[0, a, 0])
        for c in range(3):
            s[0, k, BL + c], s[0, k, BLI + c] = drawn[0, a, c], drawn[0, a, 3 + c]
        s[0, k, BLEN] = drawn[0, a, 6]
        s[0, k, BREACH] = math.inf
        s[0, k, BPICK] = pmf[e]


@inline_kernel
def _block_shade(opts, lobes, s, m):
    """Every shading lane's BSDF (see :func:`_shade`, :func:`_bounce`): towards the light
    sample, f and the MIS weight, what the sample adds if its shadow ray gets through (into
    BLI; the ray's length into BLEN, -1 for none); the lobe picked, the BSDF sample, its weight
    and density; the bounce, or the path's end. Every lane computes every lobe, and selects."""
    for k in range(m):
        shaded = s[0, k, BSHADED] != 0.0
        dx, dy, dz = s[0, k, BD], s[0, k, BD + 1], s[0, k, BD + 2]
        nx, ny, nz = s[0, k, BN], s[0, k, BN + 1], s[0, k, BN + 2]
        ax, ay, az = s[0, k, BA], s[0, k, BA + 1], s[0, k, BA + 2]
        bx, by, bz = s[0, k, BB], s[0, k, BB + 1], s[0, k, BB + 2]
        vx = -(dx * ax + dy * ay + dz * az)
        vy = -(dx * bx + dy * by + dz * bz)
        vz = -(dx * nx + dy * ny + dz * nz)
        # the light sample, in the local frame
        lvx, lvy, lvz = s[0, k, BL], s[0, k, BL + 1], s[0, k, BL + 2]
        lpdf, pick = s[0, k, BLEN], s[0, k, BPICK]
        li0, li1, li2 = s[0, k, BLI], s[0, k, BLI + 1], s[0, k, BLI + 2]
        cast = (shaded & (lpdf > 0.0) & ((li0 > 0.0) | (li1 > 0.0) | (li2 > 0.0))
                & (lvx * nx + lvy * ny + lvz * nz > 0.0))
        lx = lvx * ax + lvy * ay + lvz * az
        ly = lvx * bx + lvy * by + lvz * bz
        lz = lvx * nx + lvy * ny + lvz * nz
        # the lobes: Lambert's and GGX's parameters, the probability of picking each (their
        # hints, lambert.hint_ and microfacet.hint_ without a Fresnel term: the albedo's and
        # ks's channel means where v is above the surface; mixture_selection)
        row = lobes[int(s[0, k, BMAT])]
        kd0, kd1, kd2 = s[0, k, BPAR], s[0, k, BPAR + 1], s[0, k, BPAR + 2]
        ks0, ks1, ks2 = s[0, k, BPAR + 3], s[0, k, BPAR + 4], s[0, k, BPAR + 5]
        alx, aly, sep = s[0, k, BPAR + 6], s[0, k, BPAR + 7], row[SEPARABLE] != 0.0
        hd = (kd0 + kd1 + kd2) / 3.0 if vz > 0.0 else 0.0
        hs = (ks0 + ks1 + ks2) / 3.0 if vz > 0.0 else 0.0
        total = max(hd, 0.0) + max(hs, 0.0)
        sel_d = max(hd, 0.0) / total if total > 0.0 else 0.5
        sel_s = max(hs, 0.0) / total if total > 0.0 else 0.5
        # f(l, v) and the density of l given v towards the light (see _light_scale: a delta
        # light's density is inf, and its weight 1)
        fd = lambert.per_albedo(lz, vz)
        fs = microfacet.factor_in_lanes(GGX, alx, aly, sep, lx, ly, lz, vx, vy, vz)
        bpdf = (sel_d * lambert.density_in_lanes(vz, lz)
                + sel_s * microfacet.density_in_lanes(GGX, alx, aly, vx, vy, vz, lx, ly, lz))
        cos_l = max(lz, 0.0)
        scale = (cos_l / pick if lpdf == math.inf
                 else _power(pick * lpdf, bpdf) * cos_l / (pick * lpdf))
        scale = scale if cast else 0.0
        s[0, k, BLI] = s[0, k, BTHR] * (kd0 * fd + ks0 * fs) * li0 * scale
        s[0, k, BLI + 1] = s[0, k, BTHR + 1] * (kd1 * fd + ks1 * fs) * li1 * scale
        s[0, k, BLI + 2] = s[0, k, BTHR + 2] * (kd2 * fd + ks2 * fs) * li2 * scale
        s[0, k, BLEN] = s[0, k, BREACH] if cast else -1.0
        # the BSDF sample: a lobe by u1 (then u1 rescaled within its share), drawn with (u1, u2)
        first = row[LOBE_FIRST] != 0.0
        sel_0 = sel_d if first else sel_s
        u = s[0, k, BU + BSDF_U1]
        past = u >= sel_0
        wl = (sel_s if first else sel_d) if past else sel_0  # the picked lobe's probability
        u = min(max((u - (sel_0 if past else 0.0)) / wl, 0.0), BELOW_ONE) if wl > 0.0 else u
        diffuse = past != first
        u2 = s[0, k, BU + BSDF_U2]
        cx, cy, cz, cpdf = lambert.sample_in_lanes(vz, u, u2)
        gx, gy, gz, gpdf = microfacet.draw_in_lanes(GGX, alx, aly, vx, vy, vz, u, u2)
        ox = cx if diffuse else gx
        oy = cy if diffuse else gy
        oz = cz if diffuse else gz
        drawn = (cpdf if diffuse else gpdf) > 0.0
        fd = lambert.per_albedo(oz, vz)
        fs = microfacet.factor_in_lanes(GGX, alx, aly, sep, ox, oy, oz, vx, vy, vz)
        pdf = (sel_d * lambert.density_in_lanes(vz, oz)
               + sel_s * microfacet.density_in_lanes(GGX, alx, aly, vx, vy, vz, ox, oy, oz))
        ok = shaded & drawn & (wl > 0.0) & (pdf > 0.0)
        c = oz / pdf if ok else 0.0
        w0, w1, w2 = (kd0 * fd + ks0 * fs) * c, (kd1 * fd + ks1 * fs) * c, (kd2 * fd + ks2 * fs) * c
        s[0, k, BW], s[0, k, BW + 1], s[0, k, BW + 2] = w0, w1, w2
        # the bounce: below the geometric surface the shading normal would leak light
        wx = ox * ax + oy * bx + oz * nx
        wy = ox * ay + oy * by + oz * ny
        wz = ox * az + oy * bz + oz * nz
        ok = ok & (wx * nx + wy * ny + wz * nz > 0.0)
        t0, t1, t2 = s[0, k, BTHR] * w0, s[0, k, BTHR + 1] * w1, s[0, k, BTHR + 2] * w2
        keep = min(max(t0, max(t1, t2)), 0.95)
        depth = s[0, k, BDEPTH] + 1.0
        roulette = depth >= opts[RR]
        ok = ok & ((not roulette) | (s[0, k, BU + ROULETTE] < keep))
        d = keep if roulette else 1.0
        s[0, k, BTHR], s[0, k, BTHR + 1], s[0, k, BTHR + 2] = t0 / d, t1 / d, t2 / d
        for c in range(3):
            s[0, k, BO + c] = s[0, k, BQ + c]
        s[0, k, BD], s[0, k, BD + 1], s[0, k, BD + 2] = wx, wy, wz
        s[0, k, BPREV] = pdf
        s[0, k, BDEPTH] = depth
        s[0, k, BLIVE] = 1.0 if ok else 0.0


@inline_kernel
def _block_tile(cam, opts, geo, mats, lights, lobes, pt, seed, tile, s0, total, sums):
    """Trace the tile's ``total`` pairs in blocks of BLOCK paths, each block vertex by vertex
    until its last path ends. The paths still in flight are kept in the first lanes
    (:func:`_block_compact`), so that the passes over the vertices run over those alone as
    paths end at different depths. The order of everything is fixed by the tile."""
    s = stack_array(1, BLOCK, BLOCK_ROWS)
    layers = opts[LAYERS] != 0
    emitters = textured = False
    for i in range(pt.shape[0]):
        emitters |= pt[i, PT_LIGHT] >= 0.0
    for i in range(lobes.shape[0]):
        textured |= lobes[i, TEXTURED] != 0.0
    for start in range(0, total, BLOCK):
        m = min(BLOCK, total - start)
        _block_launch(cam, opts, seed, tile, s0, start, m, s)
        mm = _padded(m)
        while True:
            _block_hits(geo, s, mm, False)
            _block_escaped(lights, s, mm)
            if emitters:
                _block_emission(lights, geo, pt, s, mm)
            m = _block_compact(s, m, sums, layers)
            if m == 0:
                break
            mm = _block_idle(s, m)
            if _block_surface(opts, lobes, pt, s, mm) == 0:
                for k in range(m):
                    s[0, k, BLIVE] = 0.0  # every path ends here
                continue
            # the vertex's numbers
            for k in range(mm):
                st = _joined(s[0, k, BSTATE], s[0, k, BSTATE + 1])
                for u in range(UNIFORMS):
                    st += _GOLDEN
                    s[0, k, BU + u] = _number(st)
                s[0, k, BSTATE], s[0, k, BSTATE + 1] = _halves(st)
            _block_params(mats, lobes, pt, s, mm, textured)
            _block_light_samples(lights, geo, s, mm)
            _block_shade(opts, lobes, s, mm)
            if layers:
                for k in range(m):
                    if s[0, k, BSHADED] == 2.0:
                        x, y = int(s[0, k, BPX]), int(s[0, k, BPX + 1])
                        for c in range(3):
                            sums.aov[y, x, c] += s[0, k, BW + c]
                            sums.aov[y, x, 3 + c] += s[0, k, BN + c]
            _block_hits(geo, s, mm, True)
            for k in range(mm):
                lit = s[0, k, BLEN] >= 0.0
                for c in range(3):
                    s[0, k, BRAD + c] += s[0, k, BLI + c] if lit else 0.0


@nogil_kernel
def trace_blocks(cam, opts, geo, mats, lights, lobes, pt, seed, s0, s1, sums, queue):
    """:func:`trace_tiles` for the scenes that :func:`block_scene` covers: each tile's pairs
    through a block of BLOCK lanes (:func:`_block_tile`), in an order fixed by the tile, so that
    an image is the same whatever the number of threads."""
    w, h, size = opts[W], opts[H], opts[TILE]
    tx_n = (w + size - 1) // size
    ntiles = tx_n * ((h + size - 1) // size)
    while True:
        k = fetch_add(queue, 1)
        if k >= ntiles:
            return
        x0, y0 = (k % tx_n) * size, (k // tx_n) * size
        tile = (x0, y0, min(x0 + size, w), min(y0 + size, h))
        total = (tile[2] - x0) * (tile[3] - y0) * (s1 - s0)
        _block_tile(cam, opts, geo, mats, lights, lobes, pt, seed, tile, s0, total, sums)


def render_pass(cam, geo, mats, lights, opts, seed, s0, s1, sums, grad, clock=None):
    """Add samples s0 .. s1 - 1 of every pixel to the running :data:`Sums`: radiance into
    ``acc``, and if opts[LAYERS] its square into ``acc2`` and the first-hit layers into ``aov``
    (h, w, 6); the derivative images into the :data:`Gradient` ``grad``, or None (a type of
    its own: numba prunes the derivatives' passes from that compilation, which cost a third
    more of the renderer's compile time); with a ``clock`` (int64, CLOCK_ROWS; only where
    :data:`brdf._jit.HAS_TICKS`), the stages' ticks and the counts added to it (None, the
    default, is again a type of its own, without the timing).
    opts[THREADS] threads (:func:`brdf._jit.in_threads`) run :func:`trace_tiles`, taking
    tiles from one queue; a tile's pixels are its own, so the sums do not depend on who traced
    it. Each thread takes the next tile as it finishes one: equal shares would wait on the
    slower core of a shared host, which can run 5-18 % slower than the other for seconds at a
    time (measured per thread on the Cornell box). Returns whether the pass was traced in
    blocks (:func:`trace_blocks`, for the scenes :func:`block_scene` covers, without
    derivative images or a clock), else in the packet (:func:`trace_tiles`)."""
    tile = int(opts[TILE])
    ntiles = -(-int(opts[W]) // tile) * -(-int(opts[H]) // tile)
    nparams = max(mats.params.shape[0], 1)
    nlobes = int(np.max(mats.mint[:, K1] - mats.mint[:, K0], initial=1))
    queue = np.zeros(1, np.int64)

    blocks = None if grad is not None or clock is not None else block_scene(geo, mats, lights,
                                                                            opts)

    def work():
        if blocks is not None:
            trace_blocks(cam, opts, geo, mats, lights, blocks[0], blocks[1], seed, s0, s1, sums,
                         queue)
        else:
            trace_tiles(cam, opts, geo, mats, lights, seed, s0, s1, sums, grad, queue, nparams,
                        nlobes, clock)

    in_threads(max(1, min(int(opts[THREADS]), ntiles)), work)
    return blocks is not None
