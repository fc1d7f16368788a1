"""Posterior of ``lambert + ggx`` (RGB albedo and ks, one shared alpha) on a 20,000-sample table
with 2 % relative noise: wall time to a converged chain (target under 90 s), with tau, steps and
walkers, against the point fit that starts it, for our default moves (differential evolution)
and for emcee's default (the stretch move) in the same run.

Run: ``python benchmarks/bench_mcmc.py [--samples 20000] [--seed 1]``
"""

import argparse
import time

import brdf

TRUTH = "lambert(albedo=[0.5,0.4,0.3]) + ggx(ks=[0.6,0.5,0.4], alpha=0.2)"
START = "lambert(albedo=0.5) + ggx(alpha=0.3, ks=0.5)"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=20000)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    table = brdf.measure(TRUTH, f"random:{args.samples}", "relative:0.02", seed=args.seed)
    # warm-up: compile the kernels outside the timed runs
    brdf.mcmc(table, START, shared=["ggx.alpha"], max_steps=200, seed=0, progress=False)
    began = time.perf_counter()
    fit = brdf.fit(table, START, shared=["ggx.alpha"], seed=args.seed)
    fitted = time.perf_counter()
    print(f"lambert + ggx, {args.samples:,} samples (2% relative noise, stated sigma); "
          f"nlopt fit {fitted - began:.2f} s")
    seconds, posts = {}, {}
    for moves in ("de", "stretch"):
        t = time.perf_counter()
        post = posts[moves] = brdf.mcmc(table, fit, seed=args.seed, moves=moves, progress=False)
        seconds[moves] = time.perf_counter() - t
        print(f"\n--- moves={moves}\n{post}")
        print(f"emcee {seconds[moves]:.1f} s ({post.walkers} walkers x {post.steps} steps = "
              f"{post.walkers * post.steps / seconds[moves]:,.0f} log-posteriors/s)")
    met = posts["de"].converged and seconds["de"] < 90
    print(f"\ndefault (de) {seconds['de']:.1f} s against emcee's stretch move "
          f"{seconds['stretch']:.1f} s: {seconds['stretch'] / seconds['de']:.1f}x faster")
    print(f"target < 90 s to a converged chain: {'met' if met else 'NOT met'}")


if __name__ == "__main__":
    main()
