"""Posterior of ``lambert + ggx`` (RGB albedo and ks, one shared alpha) on a 20,000-sample table
with 2 % relative noise: wall time to a converged chain (target under 90 s), with tau, steps and
walkers, against the point fit that starts it.

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
    post = brdf.mcmc(table, fit, seed=args.seed, progress=False)
    done = time.perf_counter()
    print(f"lambert + ggx, {args.samples:,} samples (2% relative noise, stated sigma), "
          f"{len(post.names)} parameters")
    print(post)
    print(f"nlopt fit {fitted - began:.2f} s; emcee {done - fitted:.1f} s "
          f"({post.walkers} walkers x {post.steps} steps = "
          f"{post.walkers * post.steps / (done - fitted):,.0f} log-posteriors/s)")
    print(f"target < 90 s to a converged chain: {'met' if post.converged and done - fitted < 90 else 'NOT met'}")


if __name__ == "__main__":
    main()
