"""Path-tracing throughput on the Cornell box against Mitsuba 3, in the same run.

Run: ``python benchmarks/bench_render.py [--size 256] [--spp 64] [--depth 8] [--repeats 5]
[--layers]``

Both render Mitsuba 3's ``cornell_box()`` (ours: ``brdf.render.builtin("cornell")``, the same
geometry, colours, light and camera) at the same size, samples per pixel and maximum depth:

- ``brdf``: :func:`brdf.render.render` (numba, all cores, float64); its one-time compilation
  (or cache load) is reported apart. Like ``mi.render``, it estimates the image alone
  (``layers=False``); ``--layers`` times it with the variance, albedo and normal layers too;
- ``mitsuba``: ``mi.render`` with the ``llvm_ad_rgb`` variant (Dr.Jit's LLVM back end, SIMD
  float32 on all cores; it needs Debian's libllvm19, found as in ``mitsuba_baseline``); the
  first render, which traces and compiles its kernels, is reported apart too.

Prints samples (paths) per second of each, best of ``--repeats`` renders taken in turns (ours,
theirs, ours, ...), their ratio and the range of the turn-by-turn ratios, and the mean image of
each with the relative difference (the goal: within 1 %).
"""

import argparse
import time

import numpy as np

from mitsuba_baseline import setup_llvm


def _timed(fn, seed):
    t = time.perf_counter()
    out = fn(seed)
    return time.perf_counter() - t, out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--depth", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--layers", action="store_true",
                    help="ours also estimates the variance, albedo and normal layers")
    args = ap.parse_args()
    n = args.size * args.size * args.spp

    from brdf import render
    scene = render.builtin("cornell")
    compile_seconds = []

    def ours(seed):
        r = render.render(scene, spp=args.spp, size=args.size, seed=seed, max_depth=args.depth,
                          layers=args.layers)
        compile_seconds.append(r.compile_seconds)
        return r.image

    mi = setup_llvm()
    d = mi.cornell_box()
    d["integrator"]["max_depth"] = args.depth
    d["sensor"]["film"]["width"] = d["sensor"]["film"]["height"] = args.size
    mscene = mi.load_dict(d)

    def theirs(seed):
        return np.array(mi.render(mscene, spp=args.spp, seed=seed))

    first, img = _timed(ours, 0)
    mfirst, mimg = _timed(theirs, 0)
    # the two take turns, so that the shared host's drift touches both alike
    times, mtimes = [], []
    for r in range(args.repeats):
        times.append(_timed(ours, r + 1)[0])
        mtimes.append(_timed(theirs, r + 1)[0])
    ours_rate, mrate = n / min(times), n / min(mtimes)
    pairs = sorted(m / t for t, m in zip(times, mtimes))
    print(f"brdf     first call {first:7.2f} s (compile or cache load {compile_seconds[0]:.2f} s), "
          f"best {min(times):6.3f} s, {ours_rate / 1e6:6.3f} M samples/s "
          f"({'with' if args.layers else 'without'} layers)")
    print(f"mitsuba  first call {mfirst:7.2f} s (trace + kernel compile), best {min(mtimes):6.3f} s, "
          f"{mrate / 1e6:6.3f} M samples/s  ({mi.variant()})")
    print(f"ratio brdf / mitsuba: {ours_rate / mrate:.2f}x (best against best); turn by turn "
          f"{pairs[0]:.2f}-{pairs[-1]:.2f}x, median {pairs[len(pairs) // 2]:.2f}x")
    a, b = img.mean(axis=(0, 1)), mimg[..., :3].mean(axis=(0, 1))
    rel = np.abs(a - b) / b
    print(f"mean image  brdf {np.round(a, 5)}  mitsuba {np.round(b, 5)}  "
          f"relative difference {np.round(rel * 100, 2)} %  (goal < 1 %)")


if __name__ == "__main__":
    main()
