"""Default fits on real tables against a 64-start global search in the same run.

Run: ``python benchmarks/bench_fit_robustness.py [--jobs 2] [--only rgl,nist] [--models ggx,...]
[--curet-samples 61] [--reference-starts 64] [--csv out.csv]``

For every real table at hand (the four RGL ``.bsdf`` files bundled in ``measurements/rgl``; the
five Cornell paints, NIST PTFE at each of its four wavelengths and the 61 CUReT samples from the
shared data folder, ``$BRDF_MEASURED`` or ``../shared/measured``) and each of :data:`MODELS`
written with default parameter values, it compares

- the **default fit**: ``brdf.fit(table, spec)`` with no option set, its loss and wall time;
- the **reference**: the best loss of a global search on the same fitting problem
  (:func:`brdf.fitting.mixed_problem.problem_for`, the default loss, cutoff and box): nlopt's
  MLSL (G_MLSL_LDS, Kan & Timmer 1987, low-discrepancy points) with an LD_LBFGS local search,
  and ``--reference-starts`` scrambled Sobol points of the box (``scipy.stats.qmc``; log-scaled
  parameters uniform in their logarithm) each polished by LD_LBFGS to the default tolerance; a
  Sobol point where the model does not exist (an infinite loss: Lafortune's max|C|^n overflows
  there) is first pulled towards the spec's start until it does (:func:`admissible`), and the
  table counts the starts so moved. The reference includes the default fit's own optimum, so the
  ratio is at least 1 where the default fit is the best found; the search's own best over the
  default loss is printed too (about 1 where both find the same optimum, above 1 where the
  default found a better one). The reference does not depend on the default fit:
  ``--reference-cache FILE`` keeps it between runs (reused only for the same free parameters, box and sample
  bytes), and ``--references-only`` fills the cache without fitting.

Targets (issue 21): the default loss within 1 % of the reference in at least 98 % of the cases
and within 5 % in all. The whole table is printed, then the counts and the worst cases.
"""

import argparse
import concurrent.futures
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
#: The model specs of the benchmark, default parameter values.
MODELS = ("lambert + ggx", "lambert + beckmann", "lambert + ward(variant=gmd)",
          "lambert + blinn-phong", "lambert + lafortune")
WITHIN_1, WITHIN_5 = 0.98, 1.0  # shares of cases within 1 % and within 5 % of the reference
REFERENCE_SEED = 20261203  # other than the default fit's seed, so the starts differ
MLSL_EVALS = 5000  # objective evaluations of the MLSL search (each local run counts)


def measured_folder():
    """The shared real-data folder: $BRDF_MEASURED, else ../shared/measured beside the checkout."""
    if os.environ.get("BRDF_MEASURED"):
        return Path(os.environ["BRDF_MEASURED"])
    beside = HERE.parents[1] / "shared" / "measured"
    return beside if beside.is_dir() else Path("/work/shared/measured")


def tables(groups, curet_samples):
    """``[(name, loader)]``: each loader returns the table (read lazily, in the worker)."""
    shared = measured_folder()
    out = []
    if "rgl" in groups:
        for path in sorted((HERE.parent / "measurements" / "rgl").glob("*.bsdf")):
            out.append((f"rgl/{path.stem}", (str(path), None, None)))
    if "cornell" in groups:
        for path in sorted((shared / "cornell-paints").glob("*.brdf")):
            out.append((f"cornell/{path.stem}", (str(path), None, None)))
    if "nist" in groups:
        path = shared / "nist-ptfe" / "PTFE.data.csv"
        if path.is_file():
            for k, nm in enumerate((351, 532, 633, 1064)):
                out.append((f"nist/ptfe-{nm}nm", (str(path), "channel", k)))
    if "curet" in groups:
        path = shared / "curet" / "abrdf.dat"
        if path.is_file():
            for k in range(1, curet_samples + 1):
                out.append((f"curet/{k:02d}", (str(path), "sample", k)))
    return out


def load(how):
    """The table that ``how`` = ``(path, kind, k)`` names: a file, one channel of it (rows
    measured at that wavelength only) or one CUReT sample."""
    import brdf
    path, kind, k = how
    if kind == "sample":
        return brdf.read(path, sample=k)
    table = brdf.read(path)
    if kind == "channel":
        values = table.values[:, k:k + 1]
        keep = np.isfinite(values[:, 0])
        from brdf.table import Table
        return Table(table.wi[keep], table.wo[keep], values[keep],
                     wavelengths=table.wavelengths[k:k + 1], isotropic=table.isotropic,
                     name=f"{table.name} {table.channel_names[k]}")
    return table


def tracked(problem):
    """An nlopt objective of the problem's loss and the one-item list of the lowest loss it saw."""
    best = [math.inf]

    def objective(x, grad):
        if grad.size:
            loss, grad[:] = problem.loss_and_gradient(x)
        else:
            loss = problem.loss(x)
        best[0] = min(best[0], loss) if math.isfinite(loss) else best[0]
        return loss
    return objective, best


def local_polish(problem, x0, max_evals, tol):
    """LD_LBFGS from ``x0`` in the problem's box: the lowest loss it saw (nlopt may raise on a
    round-off stop without returning its point)."""
    import nlopt
    objective, best = tracked(problem)

    opt = nlopt.opt(nlopt.LD_LBFGS, len(x0))
    opt.set_lower_bounds(problem.lower)
    opt.set_upper_bounds(problem.upper)
    opt.set_min_objective(objective)
    opt.set_maxeval(max_evals)
    opt.set_ftol_rel(tol)
    opt.set_xtol_rel(math.sqrt(tol))
    try:
        opt.optimize(np.clip(x0, problem.lower, problem.upper))
    except (nlopt.RoundoffLimited, nlopt.runtime_error, RuntimeError):
        pass
    return best[0]


def mlsl(problem, max_evals, tol, seed):
    """nlopt G_MLSL_LDS with an LD_LBFGS local search over the box: the lowest loss seen."""
    import nlopt
    n = len(problem.free)
    objective, best = tracked(problem)

    nlopt.srand(seed)
    local = nlopt.opt(nlopt.LD_LBFGS, n)
    local.set_ftol_rel(tol)
    local.set_xtol_rel(math.sqrt(tol))
    opt = nlopt.opt(nlopt.G_MLSL_LDS, n)
    opt.set_local_optimizer(local)
    opt.set_lower_bounds(problem.lower)
    opt.set_upper_bounds(problem.upper)
    opt.set_min_objective(objective)
    opt.set_maxeval(max_evals)
    try:
        opt.optimize(np.clip(problem.x0, problem.lower, problem.upper))
    except (nlopt.RoundoffLimited, nlopt.runtime_error, RuntimeError):
        pass
    return best[0]


def sobol_points(problem, n, seed):
    """``n`` scrambled Sobol points of the problem's box (x space: log parameters are already
    logarithms there)."""
    from scipy.stats import qmc
    u = qmc.Sobol(len(problem.free), scramble=True, seed=seed).random(n)
    return problem.lower + (problem.upper - problem.lower) * u


def admissible(problem, x, steps=30):
    """``x`` if the problem has a model there (a finite loss), else the point nearest to ``x``
    on the segment to the spec's start ``problem.x0`` that has one (bisection), and whether
    ``x`` had to move. Families refuse parts of their box (Lafortune's max|C|^n overflows for
    large n), and a start there would end at once on an infinite loss: with 155 free
    parameters (Lafortune on a 31-channel Cornell paint) no Sobol point of the box is
    admissible, and the search would be no reference at all."""
    if math.isfinite(problem.loss(x)):
        return x, False
    x0 = np.clip(problem.x0, problem.lower, problem.upper)
    if not math.isfinite(problem.loss(x0)):
        return x, False
    lo, hi = 0.0, 1.0  # x0 + lo (x - x0) is admissible, x0 + hi (x - x0) is not
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        if math.isfinite(problem.loss(x0 + mid * (x - x0))):
            lo = mid
        else:
            hi = mid
    return x0 + lo * (x - x0), True


def _single_thread():
    """The cases run side by side in processes, one per core: each on one numba thread."""
    import warnings
    warnings.simplefilter("ignore")
    import numba
    numba.set_num_threads(1)


def reference_case(case, reference_starts):
    """The reference search of one (table, model) case: ``{"reference", "box", "seconds",
    "moved"}``, ``box`` naming the problem's free parameters and bounds (a cached reference is
    reused only for the same box) and ``moved`` the Sobol starts that :func:`admissible` had
    to pull into the part of the box where the model exists."""
    _single_thread()
    from brdf.fitting.mixed_problem import problem_for
    from brdf.fitting.nlopt_fit import DEFAULT_MAX_EVALS, DEFAULT_TOL
    name, how, spec = case
    start = time.perf_counter()
    problem = problem_for(load(how), spec)
    losses = [mlsl(problem, MLSL_EVALS, DEFAULT_TOL, REFERENCE_SEED)]
    moved = 0
    for x in sobol_points(problem, reference_starts, REFERENCE_SEED):
        x0, m = admissible(problem, x)
        moved += m
        losses.append(local_polish(problem, x0, DEFAULT_MAX_EVALS, DEFAULT_TOL))
    return {"reference": min(losses), "box": box_of(problem), "moved": moved,
            "seconds": time.perf_counter() - start}


def box_of(problem):
    """What a reference depends on: the free parameters, their box and the samples' bytes."""
    import hashlib
    s = problem.samples
    digest = hashlib.sha256()
    for a in (s.wi, s.wo, s.values, s.weights):
        digest.update(np.ascontiguousarray(a).tobytes())
    return [list(problem.names), problem.lower.tolist(), problem.upper.tolist(),
            digest.hexdigest()]


def default_case(case):
    """The default fit of one case: ``brdf.fit(table, spec)`` with no option set."""
    _single_thread()
    import brdf
    from brdf.fitting.mixed_problem import problem_for
    name, how, spec = case
    table = load(how)
    start = time.perf_counter()
    result = brdf.fit(table, spec)
    seconds = time.perf_counter() - start
    warnings_ = getattr(result, "warnings", None)
    return {"table": name, "model": spec, "samples": result.data["samples_used"],
            "free": len(result.free), "default": result.loss, "default_s": seconds,
            "status": result.status, "box": box_of(problem_for(table, spec)),
            "warnings": "n/a" if warnings_ is None else
            ",".join(sorted({w["kind"] for w in warnings_})) or "-"}


def key_of(case, reference_starts):
    name, _, spec = case
    return f"{name} | {spec} | {reference_starts} admissible starts | MLSL {MLSL_EVALS}"


def load_cache(path):
    import json
    if path and Path(path).is_file():
        return json.loads(Path(path).read_text(encoding="utf-8"))
    return {}


def save_cache(path, cache):
    import json
    if path:
        tmp = Path(path).with_suffix(".tmp")
        tmp.write_text(json.dumps(cache, indent=1), encoding="utf-8")
        tmp.replace(path)


def run(cases, args):
    """Reference searches (those not in the cache) and default fits, ``--jobs`` at a time."""
    cache = load_cache(args.reference_cache)
    rows = {}
    with concurrent.futures.ProcessPoolExecutor(args.jobs) as pool:
        pending = {}
        if not args.references_only:
            for c in cases:
                pending[pool.submit(default_case, c)] = ("default", c)
        for c in cases:
            key = key_of(c, args.reference_starts)
            if key not in cache:
                pending[pool.submit(reference_case, c, args.reference_starts)] = ("reference", c)
        for k, future in enumerate(concurrent.futures.as_completed(pending), 1):
            what, c = pending[future]
            out = future.result()
            if what == "reference":
                cache[key_of(c, args.reference_starts)] = out
                save_cache(args.reference_cache, cache)
            else:
                rows[c] = out
            print(f"[{k}/{len(pending)}] {what:9s} {c[0]:24s} {c[2]:30s}", file=sys.stderr,
                  flush=True)
    if args.references_only:
        return []
    out = []
    for c in cases:
        row, ref = rows[c], cache[key_of(c, args.reference_starts)]
        if ref["box"] != row["box"]:
            sys.exit(f"the cached reference of {key_of(c, args.reference_starts)} has another "
                     "box or other samples than today's problem: delete the cache")
        if not math.isfinite(ref["reference"]):
            sys.exit(f"{key_of(c, args.reference_starts)}: the reference search found no point "
                     "where the model exists")
        reference = min(ref["reference"], row["default"])
        out.append({**row, "reference": reference, "reference_s": ref["seconds"],
                    "moved": ref["moved"], "search": ref["reference"],
                    "ratio": row["default"] / reference if reference > 0 else 1.0})
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                        help="cases fitted side by side, in processes (default: the cores)")
    parser.add_argument("--only", default="rgl,cornell,nist,curet",
                        help="table groups, comma-separated (default: all)")
    parser.add_argument("--models", default=",".join(MODELS),
                        help="model specs, comma-separated (default: the five of the issue)")
    parser.add_argument("--curet-samples", type=int, default=61,
                        help="CUReT samples 1..N (default: all 61)")
    parser.add_argument("--reference-starts", type=int, default=64,
                        help="Sobol starts of the reference search (default: 64)")
    parser.add_argument("--csv", help="also write the table as CSV here")
    parser.add_argument("--reference-cache", help="JSON file keeping the reference losses "
                        "between runs (they do not depend on the default fit)")
    parser.add_argument("--references-only", action="store_true",
                        help="compute the missing references into the cache and stop")
    args = parser.parse_args()
    groups = set(args.only.split(","))
    models = [m.strip() for m in args.models.split(",")]
    cases = [(name, how, spec) for name, how in tables(groups, args.curet_samples)
             for spec in models]
    if not cases:
        sys.exit("no tables found (see --only and $BRDF_MEASURED)")
    print(f"{len(cases)} cases: {len(cases) // len(models)} tables x {len(models)} models; "
          f"reference: MLSL ({MLSL_EVALS} evaluations) and {args.reference_starts} Sobol "
          f"starts polished by LD_LBFGS; {args.jobs} processes", flush=True)
    start = time.perf_counter()
    rows = run(cases, args)
    if not rows:
        return
    rows.sort(key=lambda r: (r["table"], models.index(r["model"])))
    header = ("table", "model", "samples", "free", "default loss", "reference loss", "ratio",
              "search alone / default", "default s", "reference s", "moved starts", "status",
              "warnings")
    print(" | ".join(header))
    for r in rows:
        r.pop("box")
        print(f"{r['table']} | {r['model']} | {r['samples']} | {r['free']} | "
              f"{r['default']:.6e} | {r['reference']:.6e} | {r['ratio']:.6f} | "
              f"{r['search'] / r['default']:.4f} | "
              f"{r['default_s']:.2f} | {r['reference_s']:.1f} | {r['moved']} | {r['status']} | "
              f"{r['warnings']}")
    if args.csv:
        import csv
        with open(args.csv, "w", newline="", encoding="utf-8") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    ratios = np.array([r["ratio"] for r in rows])
    n1, n5 = int((ratios <= 1.01).sum()), int((ratios <= 1.05).sum())
    print(f"\nwithin 1 % of the reference: {n1} of {len(rows)} ({n1 / len(rows):.1%}; target "
          f">= {WITHIN_1:.0%}): {'met' if n1 >= WITHIN_1 * len(rows) else 'NOT met'}")
    print(f"within 5 %: {n5} of {len(rows)} (target all): "
          f"{'met' if n5 == len(rows) else 'NOT met'}")
    print("worst cases:")
    for r in sorted(rows, key=lambda r: -r["ratio"])[:8]:
        print(f"  {r['table']:24s} {r['model']:30s} ratio {r['ratio']:.4f} "
              f"({r['default']:.6e} against {r['reference']:.6e})")
    times = np.array([r["default_s"] for r in rows])
    print(f"default fit time: median {np.median(times):.2f} s, max {times.max():.2f} s; whole "
          f"run {time.perf_counter() - start:.0f} s on {os.cpu_count()} cores")


if __name__ == "__main__":
    main()
