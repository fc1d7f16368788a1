"""The path tracer's kernel: unidirectional path tracing with next-event estimation, multiple
importance sampling and Russian roulette, parallel over image tiles.

Each (pixel, sample) pair owns a random stream derived from (seed, pixel, sample index) alone,
so an image is the same to the last bit whatever the number of threads or of passes the
samples are split into.
"""

import math

import numpy as np
from numba import prange

from .._jit import inline_kernel, kernel, parallel_kernel
from .. import sampling
from ._intersect import LANES, QUAD, SPHERE, STACK, closest_hit, occluded
from ._lights import (AREA, ENV, area_pdf, emits_towards, env_pdf, env_radiance,
                      pick_light, sample_light)
from ._materials import bsdf_eval, bsdf_pdf, bsdf_sample, material_params

MIS, BSDF, LIGHT = 0, 1, 2
#: ``opts`` layout: width, height, max depth, Russian-roulette depth, strategy, jitter, tile
W, H, DEPTH, RR, STRATEGY, JITTER, TILE = range(7)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


# --- random numbers ---------------------------------------------------------------------------

@kernel
def _mix(z):
    """SplitMix64's output function (Steele et al. 2014, "Fast Splittable Pseudorandom Number
    Generators", OOPSLA; constants of Vigna's reference code)."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@kernel
def _stream(seed, pixel, s):
    """Starting state of the stream of sample s of a pixel: hashes of the three, chained."""
    return _mix(_mix(_mix(np.uint64(seed) + _GOLDEN) ^ np.uint64(pixel)) ^ np.uint64(s))


@inline_kernel
def _uniform(state):
    """Next number in [0, 1) (53 random bits) of a stream held in ``state[0]``."""
    state[0] += _GOLDEN
    return float(_mix(state[0]) >> np.uint64(11)) * (1.0 / 9007199254740992.0)


# --- geometry at a hit --------------------------------------------------------------------------

@inline_kernel
def _surface(prim, sph, quad, tri, tri_n, tri_uv, i, a, b, px, py, pz):
    """Geometric normal n, shading normal s, tangent t and texture coordinates (u, v) at point
    p of primitive i hit with parameters (a, b)."""
    j = prim[i, 1]
    kind = prim[i, 0]
    if kind == SPHERE:
        c = sph[j]
        nx, ny, nz = (px - c[0]) / c[3], (py - c[1]) / c[3], (pz - c[2]) / c[3]
        u = (math.atan2(ny, nx) / (2.0 * math.pi)) % 1.0
        v = 1.0 - math.acos(min(max(nz, -1.0), 1.0)) / math.pi
        return nx, ny, nz, nx, ny, nz, -ny, nx, 0.0, u, v
    if kind == QUAD:
        g = quad[j]
        return (g[3, 0], g[3, 1], g[3, 2], g[3, 0], g[3, 1], g[3, 2], g[1, 0], g[1, 1], g[1, 2],
                a, b)
    v3 = tri[j]
    e1x, e1y, e1z = v3[1, 0] - v3[0, 0], v3[1, 1] - v3[0, 1], v3[1, 2] - v3[0, 2]
    e2x, e2y, e2z = v3[2, 0] - v3[0, 0], v3[2, 1] - v3[0, 1], v3[2, 2] - v3[0, 2]
    nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
    inv = 1.0 / math.sqrt(nx * nx + ny * ny + nz * nz)
    nx, ny, nz = nx * inv, ny * inv, nz * inv
    w0 = 1.0 - a - b
    vn = tri_n[j]
    sx = w0 * vn[0, 0] + a * vn[1, 0] + b * vn[2, 0]
    sy = w0 * vn[0, 1] + a * vn[1, 1] + b * vn[2, 1]
    sz = w0 * vn[0, 2] + a * vn[1, 2] + b * vn[2, 2]
    sn = math.sqrt(sx * sx + sy * sy + sz * sz)
    if sn > 0.0:
        sx, sy, sz = sx / sn, sy / sn, sz / sn
    else:
        sx, sy, sz = nx, ny, nz
    uv = tri_uv[j]
    u = w0 * uv[0, 0] + a * uv[1, 0] + b * uv[2, 0]
    v = w0 * uv[0, 1] + a * uv[1, 1] + b * uv[2, 1]
    return nx, ny, nz, sx, sy, sz, e1x, e1y, e1z, u, v


@kernel
def _frame(sx, sy, sz, tx, ty, tz):
    """Orthonormal tangent and bitangent about the shading normal s, the tangent following t
    (Gram-Schmidt), any tangent where t is parallel to s."""
    d = tx * sx + ty * sy + tz * sz
    tx, ty, tz = tx - d * sx, ty - d * sy, tz - d * sz
    n = math.sqrt(tx * tx + ty * ty + tz * tz)
    if n < 1e-9:
        t, b = sampling.basis_from_axis(sx, sy, sz)
        return t[0], t[1], t[2], b[0], b[1], b[2]
    tx, ty, tz = tx / n, ty / n, tz / n
    return tx, ty, tz, sy * tz - sz * ty, sz * tx - sx * tz, sx * ty - sy * tx


@kernel
def _offset(px, py, pz, nx, ny, nz, side):
    """Ray origin pushed off the surface along the normal, to the side ``side`` (+1 or -1), by
    a margin relative to the point's magnitude (avoids self-intersection)."""
    eps = 1e-7 * (1.0 + max(abs(px), max(abs(py), abs(pz))))
    return px + side * eps * nx, py + side * eps * ny, pz + side * eps * nz


@kernel
def _power(a, b):
    """Veach's power heuristic with beta = 2 (Veach 1997, thesis, eq. 9.13) for density a."""
    if a == math.inf:
        return 1.0
    a2, b2 = a * a, b * b
    return a2 / (a2 + b2) if a2 + b2 > 0.0 else 0.0


# --- one path ---------------------------------------------------------------------------------

@inline_kernel
def _camera_ray(cam, opts, x, y, state):
    jx = _uniform(state) if opts[JITTER] else 0.5
    jy = _uniform(state) if opts[JITTER] else 0.5
    sx = 2.0 * (x + jx) / opts[W] - 1.0
    sy = 1.0 - 2.0 * (y + jy) / opts[H]
    dx = cam[3] + sx * cam[6] + sy * cam[9]
    dy = cam[4] + sx * cam[7] + sy * cam[10]
    dz = cam[5] + sx * cam[8] + sy * cam[11]
    n = math.sqrt(dx * dx + dy * dy + dz * dz)
    return cam[0], cam[1], cam[2], dx / n, dy / n, dz / n


@kernel
def trace(cam, opts, prim, sph, quad, tri, tri_n, tri_uv, box, child, slots, planes,
          mint, kinds, offs, params, grids, filled, tables, bind, tex, texmeta,
          ltype, lf, pmf, gonio, env, rows, cols, env_light,
          seed, x, y, s0, s1, acc, acc2, aov_acc, state, radiance, aov, f, li, stack, leaf_t,
          scratch):
    """Samples s0 .. s1 - 1 of pixel (x, y) into the running sums (see :func:`render_pass`):
    for each, the radiance along its camera ray, and the first hit's albedo estimate (f cos /
    pdf of one BSDF sample) and shading normal. One call serves all the pixel's samples: when
    kernels still counted references, a call per sample cost 0.5 us in counts on its 40
    arrays (a depth-1 Cornell-box sample: 0.76 us then, 0.23 us with a call per pixel). ``state``,
    ``radiance``, ``aov``, ``f``, ``li``, ``stack``, ``leaf_t`` and ``scratch`` are work space."""
    strategy = opts[STRATEGY]
    nlights = pmf.shape[0]
    for sample in range(s0, s1):
        state[0] = _stream(seed, y * opts[W] + x, sample)
        for c in range(6):
            aov[c] = 0.0
        for c in range(3):
            radiance[c] = 0.0
        thr0, thr1, thr2 = 1.0, 1.0, 1.0
        ox, oy, oz, dx, dy, dz = _camera_ray(cam, opts, x, y, state)
        specular = True
        prev_pdf = 0.0
        for depth in range(opts[DEPTH]):
            t, hit, a, b = closest_hit(prim, sph, planes, box, child, slots, stack, leaf_t,
                                       ox, oy, oz, dx, dy, dz, math.inf)
            if hit < 0:
                if env_light >= 0 and (strategy != LIGHT or specular):
                    w = 1.0
                    if not specular and strategy == MIS:
                        w = _power(prev_pdf, pmf[env_light] * env_pdf(lf, env, rows, cols,
                                                                      env_light, dx, dy, dz))
                    le0, le1, le2 = env_radiance(lf, env, env_light, dx, dy, dz)
                    radiance[0] += thr0 * w * le0
                    radiance[1] += thr1 * w * le1
                    radiance[2] += thr2 * w * le2
                break
            px, py, pz = ox + t * dx, oy + t * dy, oz + t * dz
            nx, ny, nz, sx, sy, sz, tx, ty, tz, u, v = _surface(prim, sph, quad, tri, tri_n, tri_uv,
                                                                hit, a, b, px, py, pz)
            light = prim[hit, 3]
            if light >= 0 and emits_towards(lf[light], nx, ny, nz, -dx, -dy, -dz):
                if strategy != LIGHT or specular:
                    w = 1.0
                    if not specular and strategy == MIS:
                        w = _power(prev_pdf, pmf[light] * area_pdf(prim, sph, lf[light], ox, oy, oz,
                                                                   px, py, pz, nx, ny, nz))
                    radiance[0] += thr0 * w * lf[light, 3]
                    radiance[1] += thr1 * w * lf[light, 4]
                    radiance[2] += thr2 * w * lf[light, 5]
            m = prim[hit, 2]
            if depth + 1 >= opts[DEPTH] or m < 0:
                break
            # shade on the side the ray arrives from (two-sided surfaces)
            if nx * dx + ny * dy + nz * dz > 0.0:
                nx, ny, nz = -nx, -ny, -nz
            if sx * nx + sy * ny + sz * nz < 0.0:
                sx, sy, sz = -sx, -sy, -sz
            ax, ay, az, bx, by, bz = _frame(sx, sy, sz, tx, ty, tz)
            vx = -(dx * ax + dy * ay + dz * az)
            vy = -(dx * bx + dy * by + dz * bz)
            vz = -(dx * sx + dy * sy + dz * sz)
            p = material_params(mint, params, bind, tex, texmeta, m, u, v, scratch)
            qx, qy, qz = _offset(px, py, pz, nx, ny, nz, 1.0)
            # next-event estimation
            if nlights > 0:
                l, ul = pick_light(pmf, _uniform(state))
                u2 = _uniform(state)
                delta_light = ltype[l] != AREA and ltype[l] != ENV
                if strategy != BSDF or delta_light:
                    ldx, ldy, ldz, dist, lpdf = sample_light(ltype, lf, gonio, env, rows, cols,
                                                             prim, sph, quad, l, qx, qy, qz, ul,
                                                             u2, li)
                    if (lpdf > 0.0 and (li[0] > 0.0 or li[1] > 0.0 or li[2] > 0.0)
                            and ldx * nx + ldy * ny + ldz * nz > 0.0):
                        tmax = dist * (1.0 - 1e-7) if dist < math.inf else math.inf
                        if not occluded(prim, sph, planes, box, child, slots, stack, leaf_t,
                                        qx, qy, qz, ldx, ldy, ldz, tmax):
                            lx = ldx * ax + ldy * ay + ldz * az
                            ly = ldx * bx + ldy * by + ldz * bz
                            lz = ldx * sx + ldy * sy + ldz * sz
                            bsdf_eval(mint, kinds, offs, grids, filled, m, p, vx, vy, vz, lx, ly,
                                      lz, f)
                            cos_l = max(lz, 0.0)
                            if lpdf == math.inf:
                                scale = cos_l / pmf[l]
                            else:
                                w = 1.0
                                if strategy == MIS:
                                    w = _power(pmf[l] * lpdf, bsdf_pdf(mint, kinds, offs, tables, m,
                                                                       p, vx, vy, vz, lx, ly, lz))
                                scale = w * cos_l / (pmf[l] * lpdf)
                            radiance[0] += thr0 * f[0, 0] * li[0] * scale
                            radiance[1] += thr1 * f[0, 1] * li[1] * scale
                            radiance[2] += thr2 * f[0, 2] * li[2] * scale
            # continue the path by sampling the BSDF
            lx, ly, lz, pdf = bsdf_sample(mint, kinds, offs, grids, filled, tables, m, p, vx, vy,
                                          vz, _uniform(state), _uniform(state), f)
            if depth == 0:
                aov[0], aov[1], aov[2] = f[0, 0], f[0, 1], f[0, 2]
                aov[3], aov[4], aov[5] = sx, sy, sz
                if pdf == 0.0:
                    aov[0], aov[1], aov[2] = 0.0, 0.0, 0.0
            if pdf == 0.0:
                break
            thr0 *= f[0, 0]
            thr1 *= f[0, 1]
            thr2 *= f[0, 2]
            dx = lx * ax + ly * bx + lz * sx
            dy = lx * ay + ly * by + lz * sy
            dz = lx * az + ly * bz + lz * sz
            if dx * nx + dy * ny + dz * nz <= 0.0:
                break  # below the geometric surface: the shading normal would leak light
            ox, oy, oz = qx, qy, qz
            specular = pdf == math.inf
            prev_pdf = pdf
            if depth + 1 >= opts[RR]:
                q = min(max(thr0, max(thr1, thr2)), 0.95)
                if _uniform(state) >= q:
                    break
                thr0, thr1, thr2 = thr0 / q, thr1 / q, thr2 / q
        for c in range(3):
            r = radiance[c]
            if r != r or r == math.inf:
                r = 0.0  # a degenerate path (NaN, inf) is dropped, not spread
            acc[y, x, c] += r
            acc2[y, x, c] += r * r
        for c in range(6):
            aov_acc[y, x, c] += aov[c]


@parallel_kernel
def render_pass(cam, geo, mats, lights, opts, seed, s0, s1, acc, acc2, aov_acc):
    """Add samples s0 .. s1 - 1 of every pixel to the running sums: radiance into ``acc``, its
    square into ``acc2`` and the first-hit layers into ``aov_acc`` (h, w, 6). Tiles of
    opts[TILE]^2 pixels are the parallel work items; ``trace`` runs a pixel's samples. The
    scene's tuples are unpacked here, once (see :mod:`._intersect` on why the kernels take
    plain arrays)."""
    prim, sph, quad, tri, tri_n, tri_uv, box, child, slots, planes = geo
    mint, kinds, offs, params, grids, filled, tables, bind, tex, texmeta = mats
    ltype, lf, pmf, gonio, env, rows, cols, env_light = lights
    w, h, tile = opts[W], opts[H], opts[TILE]
    tx_n = (w + tile - 1) // tile
    ntiles = tx_n * ((h + tile - 1) // tile)
    for k in prange(ntiles):
        state = np.empty(1, dtype=np.uint64)
        radiance = np.empty(3)
        aov = np.empty(6)
        f = np.zeros((1, 3))
        li = np.empty(3)
        stack = np.empty(STACK, dtype=np.int64)
        leaf_t = np.empty(LANES)
        scratch = np.empty(max(params.shape[0], 1))
        x0, y0 = (k % tx_n) * tile, (k // tx_n) * tile
        for y in range(y0, min(y0 + tile, h)):
            for x in range(x0, min(x0 + tile, w)):
                trace(cam, opts, prim, sph, quad, tri, tri_n, tri_uv, box, child, slots, planes,
                      mint, kinds, offs, params, grids, filled, tables, bind, tex, texmeta,
                      ltype, lf, pmf, gonio, env, rows, cols, env_light,
                      seed, x, y, s0, s1, acc, acc2, aov_acc, state, radiance, aov, f, li,
                      stack, leaf_t, scratch)
