"""What the white furnace's paths cost when every lane runs the same branch-free code: a bound
for issue 27's renderer redesign, timed against ``brdf.render`` and Mitsuba 3 in the same run.

Run: ``python benchmarks/furnace_bound.py [--size 256] [--spp 64] [--repeats 5]``

The furnace of ``bench_render.py`` (a unit sphere of white GGX, alpha 0.5, no Fresnel, in a
constant environment of radiance 1, camera at z = 4 with a 32 degree field of view) has paths
of at most two segments: the camera ray; at a hit, next-event estimation towards the
environment (a uniform direction on the sphere, its shadow ray) and a GGX sample, whose ray
escapes; both weighed by the power heuristic. This script computes exactly that estimator,
float64 like the renderer, each path's numbers from its own SplitMix64 stream, with every
branch written as a select, so that LLVM can run it in SIMD lanes. It is not a renderer (one
sphere, one material, one light, a fixed depth, no tree); its time is what the furnace's
arithmetic costs when nothing else is in the way. Three ways over blocks of LANES paths:

- ``fused loop``: each path whole in one iteration (:func:`_fused`), its numbers in registers;
- ``three passes``: camera rays, then scattering, then the two rays' tests, each a loop over
  the block that reads the last pass's rows and writes its own (:func:`_three_passes`), as a
  wavefront renderer's passes do; numba cannot tell LLVM that the rows of two arrays, or of
  two views of one, do not overlap, and LLVM leaves a pass that reads one and writes the
  other in scalar code;
- ``passes, noalias``: the same passes compiled with numba's ``noalias`` flag on their
  arguments (:func:`_noalias`), which tells LLVM exactly that.

Prints samples per second of each (all threads, best of the repeats), of
``brdf.render.render`` on the same scene (``layers=False``) and of Mitsuba's ``mi.render``
(``llvm_ad_rgb``), taken in turns, the ratios of the bests, and every mean image (the same
estimator: they agree to the noise).
"""

import argparse
import contextlib
import math
import os
import sys
import tempfile
import time

import numpy as np
from numba import get_num_threads, njit, prange

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_render  # noqa: E402  (the scene, both renderers' builders)
from brdf.sampling import sincos_turn  # noqa: E402  (the renderer's azimuths)

#: the renderer's fast-math flags (brdf._jit.FASTMATH): no assumption about inf or NaN
FM = {"nsz", "arcp", "contract", "afn", "reassoc"}
#: paths per block: the renderer's packet
LANES = 512
ALPHA = 0.5
EYE = 4.0
HALF_FOV = math.radians(16.0)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


@njit(fastmath=FM, error_model="numpy", inline="always")
def _hash(z):
    """SplitMix64's output function (Steele et al. 2014, OOPSLA), as the renderer's streams."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@njit(fastmath=FM, error_model="numpy", inline="always")
def _number(state, k):
    """The k-th number in [0, 1) of the stream that starts at ``state`` (53 bits)."""
    return float(_hash(state + np.uint64(k) * _GOLDEN) >> np.uint64(11)) * 2.0 ** -53


@njit(fastmath=FM, error_model="numpy", inline="always")
def _unit_sphere(ox, oy, oz, dx, dy, dz):
    """Nearest t > 0 of the ray on the unit sphere at the origin, inf on a miss (the
    discriminant from the closest approach: Haines et al. 2019, Ray Tracing Gems, eq. 7.10)."""
    b = -(ox * dx + oy * dy + oz * dz)
    lx, ly, lz = ox + b * dx, oy + b * dy, oz + b * dz
    disc = 1.0 - (lx * lx + ly * ly + lz * lz)
    q = math.sqrt(max(disc, 0.0))
    t = b - q if b - q > 1e-9 else b + q
    return t if (disc >= 0.0) & (t > 1e-9) else math.inf


@njit(fastmath=FM, error_model="numpy", inline="always")
def _ggx(a2, ox, oy, oz, ix, iy, iz):
    """f cos(i) and the sampling density of i, for a GGX lobe without Fresnel (Walter et al.
    2007, EGSR: D eq. 33, Smith G1 eq. 34, the density of a reflected D cos(m) sample eq. 14
    with the Jacobian of eq. 14's reflection, 1 / (4 o.m)); 0 and 0 below the surface."""
    hx, hy, hz = ox + ix, oy + iy, oz + iz
    inv = 1.0 / math.sqrt(hx * hx + hy * hy + hz * hz)
    cm = hz * inv
    den = cm * cm * (a2 - 1.0) + 1.0
    d = a2 / (math.pi * den * den)
    g_o = 2.0 * oz / (oz + math.sqrt(a2 + (1.0 - a2) * oz * oz))
    g_i = 2.0 * iz / (iz + math.sqrt(a2 + (1.0 - a2) * iz * iz))
    above = (oz > 0.0) & (iz > 0.0)
    om = (ox * hx + oy * hy + oz * hz) * inv
    return (d * g_o * g_i / (4.0 * oz) if above else 0.0,
            d * cm / (4.0 * om) if above else 0.0)


@njit(fastmath=FM, error_model="numpy", inline="always")
def _camera(k, width, height, seed):
    """Path k's camera ray direction, its distance to the sphere (inf: a miss) and its six
    numbers for the vertex."""
    npix = width * height
    pixel, sample = k % npix, k // npix
    state = _hash(_hash(_hash(np.uint64(seed) + _GOLDEN) ^ np.uint64(pixel))
                  ^ np.uint64(sample))
    x, y = pixel % width, pixel // width
    tan_half = math.tan(HALF_FOV)
    dx = ((x + _number(state, 1)) * (2.0 / width) - 1.0) * tan_half
    dy = (1.0 - (y + _number(state, 2)) * (2.0 / height)) * tan_half
    inv = 1.0 / math.sqrt(dx * dx + dy * dy + 1.0)
    dx, dy, dz = dx * inv, dy * inv, -inv
    return (dx, dy, dz, _unit_sphere(0.0, 0.0, EYE, dx, dy, dz), _number(state, 3),
            _number(state, 4), _number(state, 5), _number(state, 6))


@njit(fastmath=FM, error_model="numpy", inline="always")
def _scatter(a2, dx, dy, dz, t, u1, u2, u3, u4):
    """At the hit: the next-event direction and what it adds if unoccluded, the BSDF
    sample's direction and what it adds if it escapes, and the point (the normal)."""
    env_pdf = 1.0 / (4.0 * math.pi)
    t = t if t < math.inf else 0.0
    nx, ny, nz = t * dx, t * dy, EYE + t * dz  # the unit sphere's normal is the point
    # the frame about n (Duff et al. 2017, JCGT 6(1), listing 3)
    sign = 1.0 if nz >= 0.0 else -1.0
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    tx, ty, tz = 1.0 + sign * nx * nx * a, sign * b, -sign * nx
    bx, by, bz = b, sign + ny * ny * a, -ny
    ox, oy, oz = (-(dx * tx + dy * ty + dz * tz), -(dx * bx + dy * by + dz * bz),
                  -(dx * nx + dy * ny + dz * nz))
    # next event: a uniform direction (the constant environment's density)
    lz = 1.0 - 2.0 * u1
    r = math.sqrt(max(0.0, 1.0 - lz * lz))
    s, c = sincos_turn(u2)
    lx, ly = r * c, r * s
    f_l, p_l = _ggx(a2, ox, oy, oz, lx * tx + ly * ty + lz * tz,
                    lx * bx + ly * by + lz * bz, lx * nx + ly * ny + lz * nz)
    # the power heuristic (Veach 1997, thesis, eq. 9.13)
    light = f_l / env_pdf * (env_pdf * env_pdf / (env_pdf * env_pdf + p_l * p_l))
    # a BSDF sample: m from D cos(m) (Walter et al. 2007, eqs. 35-36), i reflected about m
    cm = 1.0 / math.sqrt(1.0 + a2 * u3 / (1.0 - u3))
    sm = math.sqrt(max(0.0, 1.0 - cm * cm))
    s, c = sincos_turn(u4)
    mx, my, mz = sm * c, sm * s, cm
    om = ox * mx + oy * my + oz * mz
    ix, iy, iz = 2.0 * om * mx - ox, 2.0 * om * my - oy, 2.0 * om * mz - oz
    f_b, p_b = _ggx(a2, ox, oy, oz, ix, iy, iz)
    bounce = f_b / p_b * (p_b * p_b / (p_b * p_b + env_pdf * env_pdf)) if p_b > 0.0 else 0.0
    return (lx, ly, lz, light, ix * tx + iy * bx + iz * nx, ix * ty + iy * by + iz * ny,
            ix * tz + iy * bz + iz * nz, bounce, nx, ny, nz)


@njit(fastmath=FM, error_model="numpy", inline="always")
def _gather(hit, lx, ly, lz, light, gx, gy, gz, bounce, nx, ny, nz):
    """The path's radiance: both rays tested against the sphere from just off the surface; a
    camera ray that missed sees the environment."""
    eps = 1e-7 * (1.0 + max(abs(nx), max(abs(ny), abs(nz))))
    qx, qy, qz = nx * (1.0 + eps), ny * (1.0 + eps), nz * (1.0 + eps)
    lit = _unit_sphere(qx, qy, qz, lx, ly, lz) == math.inf
    escapes = _unit_sphere(qx, qy, qz, gx, gy, gz) == math.inf
    radiance = (light if lit else 0.0) + (bounce if escapes else 0.0)
    return radiance if hit else 1.0


@njit(fastmath=FM, error_model="numpy")
def _fused(first, n, width, height, seed, a2, rows, out):
    """Radiance of paths first .. first + n - 1 (pixel-major within a sample) into out[:n],
    each path in one loop iteration (``rows`` unused)."""
    for j in range(n):
        dx, dy, dz, t, u1, u2, u3, u4 = _camera(first + j, width, height, seed)
        lx, ly, lz, light, gx, gy, gz, bounce, nx, ny, nz = _scatter(a2, dx, dy, dz, t, u1,
                                                                      u2, u3, u4)
        out[j] = _gather(t < math.inf, lx, ly, lz, light, gx, gy, gz, bounce, nx, ny, nz)


@njit(fastmath=FM, error_model="numpy")
def _stage_camera(first, n, width, height, seed, cam):
    for j in range(n):
        (cam[0, j], cam[1, j], cam[2, j], cam[3, j], cam[4, j], cam[5, j], cam[6, j],
         cam[7, j]) = _camera(first + j, width, height, seed)


@njit(fastmath=FM, error_model="numpy")
def _stage_scatter(n, a2, cam, hit):
    for j in range(n):
        (hit[0, j], hit[1, j], hit[2, j], hit[3, j], hit[4, j], hit[5, j], hit[6, j],
         hit[7, j], hit[8, j], hit[9, j], hit[10, j]) = _scatter(
            a2, cam[0, j], cam[1, j], cam[2, j], cam[3, j], cam[4, j], cam[5, j], cam[6, j],
            cam[7, j])


@njit(fastmath=FM, error_model="numpy")
def _stage_gather(n, cam, hit, out):
    for j in range(n):
        out[j] = _gather(cam[3, j] < math.inf, hit[0, j], hit[1, j], hit[2, j], hit[3, j],
                         hit[4, j], hit[5, j], hit[6, j], hit[7, j], hit[8, j], hit[9, j],
                         hit[10, j])


def _three_passes(camera, scatter, gather):
    """The same paths in three passes over the block, as a wavefront renderer runs them:
    each pass reads its inputs from rows of ``rows`` (8 camera rows, then 11 hit rows)."""
    @njit(fastmath=FM, error_model="numpy")
    def passes(first, n, width, height, seed, a2, rows, out):
        cam, hit = rows[:8], rows[8:]
        camera(first, n, width, height, seed, cam)
        scatter(n, a2, cam, hit)
        gather(n, cam, hit, out)
    return passes


_passes = _three_passes(_stage_camera, _stage_scatter, _stage_gather)


@contextlib.contextmanager
def _noalias():
    """numba's compiles within the block mark every pointer argument ``noalias`` (numba's
    own ``noalias`` flag, which its parallel loops set): LLVM then knows that a pass's rows
    and another array's do not overlap. It reaches into numba's function descriptors, as a
    benchmark may; the package does not."""
    from numba.core import funcdesc
    make = funcdesc.PythonFunctionDescriptor.from_specialized_function

    def marked(func_ir, typemap, restype, calltypes, mangler, inline, noalias, abi_tags):
        return make(func_ir, typemap, restype, calltypes, mangler, inline, True, abi_tags)

    funcdesc.PythonFunctionDescriptor.from_specialized_function = marked
    try:
        yield
    finally:
        funcdesc.PythonFunctionDescriptor.from_specialized_function = make


def _passes_noalias():
    """:func:`_three_passes` of fresh copies of the stages, to be compiled under
    :func:`_noalias`."""
    return _three_passes(*(njit(fastmath=FM, error_model="numpy")(f.py_func)
                           for f in (_stage_camera, _stage_scatter, _stage_gather)))


@njit(fastmath=FM, error_model="numpy", parallel=True)
def _image(block, width, height, spp, seed, sums, rows, work):
    """Every path of the image through ``block`` (:func:`_fused` or a version of
    :func:`_three_passes`), block b on thread b % threads, into each thread's ``sums`` (the
    same blocks on the same threads every run: the same bytes)."""
    threads, n = work.shape
    total = width * height * spp
    npix = width * height
    blocks = (total + n - 1) // n
    for th in prange(threads):
        for b in range(th, blocks, threads):
            first = b * n
            m = min(n, total - first)
            block(first, m, width, height, seed, ALPHA * ALPHA, rows[th], work[th])
            for j in range(m):
                sums[th, (first + j) % npix] += work[th, j]


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=256)
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--repeats", type=int, default=5)
    args = p.parse_args()
    from brdf import render
    desc = bench_render.SCENES["furnace"]
    with tempfile.TemporaryDirectory() as tmp:  # the furnace writes no file there
        scene = bench_render.build_ours(desc, {"dir": tmp})
    try:
        mi = bench_render.setup_llvm()
    except Exception as e:  # Mitsuba is a test extra
        print(f"Mitsuba 3 not timed ({e})")
        mi = None
    mscene = bench_render.build_theirs(mi, desc, {}, args.size, 8) if mi else None
    size, spp, threads = args.size, args.spp, get_num_threads()
    sums, work = np.zeros((threads, size * size)), np.zeros((threads, LANES))
    # rows padded past a power of two of numbers, as the renderer's work arrays
    rows = np.zeros((threads, 19, LANES + 8))

    def loop(block):
        def run(seed):
            sums[:] = 0.0
            _image(block, size, size, spp, seed, sums, rows, work)
            return sums.sum(axis=0).mean() / spp
        return run

    noalias = _passes_noalias()
    with _noalias():
        loop(noalias)(0)

    def ours(seed):
        return render.render(scene, spp=spp, size=size, seed=seed, max_depth=8, layers=False,
                             progress=False).image.mean()

    def theirs(seed):
        return float(np.array(mi.render(mscene, spp=spp, seed=seed))[..., :3].mean())

    runs = [("fused loop", loop(_fused)), ("three passes", loop(_passes)),
            ("passes, noalias", loop(noalias)), ("brdf.render", ours)] + (
        [("Mitsuba 3", theirs)] if mi else [])
    for _, fn in runs:  # compile, load, trace
        fn(0)
    best, means = {}, {}
    for r in range(args.repeats):
        for name, fn in runs:
            t = time.perf_counter()
            means.setdefault(name, []).append(fn(r + 1))
            best[name] = min(best.get(name, math.inf), time.perf_counter() - t)
    n = size * size * spp
    print(f"white furnace {size} x {size} x {spp}, {threads} threads, best of {args.repeats} "
          "in turns")
    for name, _ in runs:
        print(f"  {name:16s} {n / best[name] / 1e6:7.2f} M samples/s   mean image "
              f"{np.mean(means[name]):.5f}")
    for name in ("fused loop", "three passes", "passes, noalias"):
        print(f"{name} / brdf.render {best['brdf.render'] / best[name]:.2f}x"
              + (f", / Mitsuba 3 {best['Mitsuba 3'] / best[name]:.2f}x" if mi else ""))
    if mi:
        print(f"brdf.render / Mitsuba 3 {best['Mitsuba 3'] / best['brdf.render']:.2f}x")


if __name__ == "__main__":
    main()
