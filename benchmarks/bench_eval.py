"""Evaluation throughput of ``lambert + ggx`` (RGB, float64) against Mitsuba 3 and plain numpy.

Run: ``python benchmarks/bench_eval.py [--pairs 1458000] [--repeats 15]``

All three evaluate the same 1,458,000 random direction pairs (the size of the MERL grid) with
Fresnel disabled (Mitsuba's ``roughconductor`` with ``material='none'`` has F = 1 exactly and
separable Smith masking, which is our default):

- ``brdf``: ``Model.eval(wi, wo)``, numpy float64 arrays in and out, called again and again
  as a caller does (each result dropped before the next call, so its memory is reused:
  ``brdf.memory.empty``); and the same with ``brdf.memory.trim()`` before each call, so every
  result is written to new memory whose pages fault in as it is written (a first call);
- ``mitsuba (numpy in/out)``: Mitsuba 3 ``llvm_ad_rgb`` from the same numpy arrays to a numpy
  result, the same contract as ours (conversion to and from Dr.Jit included);
- ``mitsuba (kernel only)``: the same with the inputs already resident as Dr.Jit float32 arrays,
  timing only the fused evaluation kernel;
- ``numpy``: a plain vectorised numpy float64 formula;
- ``memory bound``: a numba kernel on both cores that only reads the same float64 arrays and
  writes an output of the same shape into a fresh ``np.empty`` array (no formula): the limit
  of an evaluation into new memory, set by memory traffic and page faults.

Ratios are printed against each baseline; the values of all three are compared too. Then the
same two with the output array given (``Model.eval(wi, wo, out=out)``, numpy's idiom for a
caller that evaluates batch after batch): without a fresh array's page faults, against the
memory bound writing into the same array.

Then the cost of a call on few pairs (``--small``, default 16 and 1,305: a plot's or a table
row's worth), where fixed costs dominate: ``Model.eval`` against Mitsuba 3 with its BSDFs built
once (numpy in and out, as above) and against the numpy formula, microseconds per call.
"""

import argparse
import sys
from pathlib import Path

import numba
import numpy as np

import brdf
from timing import best_time, random_pairs

ALBEDO = (0.5, 0.4, 0.3)
KS = (0.6, 0.5, 0.4)
ALPHA = 0.3


def numpy_lambert_ggx(wi, wo):
    """Reference formula: rho / pi + ks D G1 G1 / (4 cos_i cos_o) (Walter et al. 2007, eq. 20)."""
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    a2 = ALPHA * ALPHA
    cos_h2 = h[:, 2] ** 2
    d = a2 / (np.pi * (cos_h2 * (a2 - 1.0) + 1.0) ** 2)  # Walter et al. 2007, eq. 33

    def g1(z):  # eq. 34
        return 2.0 / (1.0 + np.sqrt(1.0 + a2 * (1.0 - z * z) / (z * z)))

    spec = d * g1(wi[:, 2]) * g1(wo[:, 2]) / (4.0 * wi[:, 2] * wo[:, 2])
    return np.asarray(ALBEDO) / np.pi + np.asarray(KS) * spec[:, None]


@numba.njit(parallel=True)
def read_write(wi, wo, out):
    """Reads every input value and writes every output value, nothing else."""
    for k in numba.prange(wi.shape[0]):
        s = wi[k, 0] + wi[k, 1] + wi[k, 2] + wo[k, 0] + wo[k, 1] + wo[k, 2]
        out[k, 0] = s
        out[k, 1] = s
        out[k, 2] = s


def memory_bound(wi, wo, out=None):
    out = np.empty((len(wi), 3)) if out is None else out
    read_write(wi, wo, out)
    return out


def mitsuba_baseline():
    """``(mitsuba_baseline module, Mitsuba set up for llvm_ad_rgb)``; RuntimeError or ImportError
    where Mitsuba 3 is missing."""
    sys.path.insert(0, str(Path(__file__).parent))
    import mitsuba_baseline as mb
    return mb, mb.setup_llvm()


def small_calls(model, sizes, repeats, mitsuba):
    """Per-call seconds ``(size, ours, mitsuba or None, numpy)``, best of ``repeats`` rounds of
    calls on ``size`` random pairs; ``mitsuba``: :func:`mitsuba_baseline`'s pair, or None."""
    theirs = None
    if mitsuba is not None:
        mb, mi = mitsuba
        bsdfs = mb.make_bsdfs(mi, ALBEDO, ALPHA, KS)

        def theirs(wi, wo):
            return mb.eval_lambert_ggx(mi, wi, wo, ALBEDO, ALPHA, KS, bsdfs=bsdfs)
    rows = []
    for size in sizes:
        wi, wo = random_pairs(size, seed=1)
        calls = max(3, 20_000 // size)

        def per_call(fn):
            return best_time(lambda: [fn(wi, wo) for _ in range(calls)], repeats)[0] / calls

        rows.append((size, per_call(model.eval), theirs and per_call(theirs),
                     per_call(numpy_lambert_ggx)))
    return rows


def mitsuba_rows(mitsuba, wi, wo, repeats):
    mb, mi = mitsuba
    ref = mb.eval_lambert_ggx(mi, wi, wo, ALBEDO, ALPHA, KS)
    e2e = best_time(lambda: mb.eval_lambert_ggx(mi, wi, wo, ALBEDO, ALPHA, KS), repeats)
    kernel = mb.time_eval(mi, wi, wo, ALBEDO, ALPHA, KS, repeats=repeats)
    return ref, [("mitsuba 3 llvm_ad_rgb (numpy in/out)", *e2e),
                 ("mitsuba 3 llvm_ad_rgb (kernel only, float32)",
                  kernel["best_s"], kernel["median_s"])]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=1_458_000)
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--small", type=int, nargs="*", default=[16, 1305],
                        help="pair counts of the per-call timings (none: skip them)")
    args = parser.parse_args()

    wi, wo = random_pairs(args.pairs)
    model = brdf.models.Lambert(albedo=ALBEDO) + brdf.models.GGX(alpha=ALPHA, ks=KS)
    ours = model.eval(wi, wo)

    def new_memory():
        brdf.memory.trim()
        return model.eval(wi, wo)

    rows = [("brdf Model.eval (float64)", *best_time(lambda: model.eval(wi, wo), args.repeats)),
            ("brdf Model.eval, new memory each call", *best_time(new_memory, args.repeats)),
            ("plain numpy formula (float64)",
             *best_time(lambda: numpy_lambert_ggx(wi, wo), args.repeats)),
            ("memory bound: read inputs, write output (numba)",
             *best_time(lambda: memory_bound(wi, wo), args.repeats))]
    checks = [("numpy", numpy_lambert_ggx(wi, wo))]
    try:
        mitsuba = mitsuba_baseline()
        ref, extra = mitsuba_rows(mitsuba, wi, wo, args.repeats)
        rows += extra
        checks.append(("mitsuba", ref))
    except (RuntimeError, ImportError) as exc:
        mitsuba = None
        print(f"mitsuba baseline skipped: {exc}")

    print(f"lambert + ggx, RGB, {args.pairs:,} random direction pairs, best of {args.repeats}")
    print(f"{'implementation':48s} {'best ms':>9s} {'median ms':>10s} {'M pairs/s':>10s}")
    for name, best, median in rows:
        print(f"{name:48s} {best * 1e3:9.2f} {median * 1e3:10.2f} {args.pairs / best / 1e6:10.1f}")
    ours_best = rows[0][1]
    for name, best, _ in rows[1:]:
        print(f"ratio brdf / {name}: {best / ours_best:.2f}x")
    for name, values in checks:
        rel = np.max(np.abs(ours - values) / np.maximum(np.abs(values), 1e-6))
        print(f"max relative difference to {name}: {rel:.2e}")
    out = np.empty_like(ours)
    given = [("brdf Model.eval(out=out)", *best_time(lambda: model.eval(wi, wo, out=out),
                                                      args.repeats)),
             ("memory bound, output given", *best_time(lambda: memory_bound(wi, wo, out),
                                                      args.repeats))]
    print(f"\nthe output array given (out=), best of {args.repeats}")
    for name, best, median in given:
        print(f"{name:48s} {best * 1e3:9.2f} {median * 1e3:10.2f} {args.pairs / best / 1e6:10.1f}")
    print(f"ratio brdf / memory bound, output given: {given[1][1] / given[0][1]:.2f}x; "
          f"brdf with out= / brdf without: {ours_best / given[0][1]:.2f}x")
    if args.small:
        print(f"\nper call, best of {args.repeats} rounds")
        print(f"{'pairs':>7s} {'brdf us':>9s} {'mitsuba us':>11s} {'numpy us':>9s} "
              f"{'vs mitsuba':>11s} {'vs numpy':>9s}")
        for size, ours_s, mitsuba_s, numpy_s in small_calls(model, args.small, args.repeats,
                                                            mitsuba):
            mi_us = f"{mitsuba_s * 1e6:11.1f}" if mitsuba_s else f"{'-':>11s}"
            mi_ratio = f"{mitsuba_s / ours_s:10.2f}x" if mitsuba_s else f"{'-':>11s}"
            print(f"{size:7d} {ours_s * 1e6:9.1f} {mi_us} {numpy_s * 1e6:9.1f} {mi_ratio} "
                  f"{numpy_s / ours_s:8.2f}x")


if __name__ == "__main__":
    main()
