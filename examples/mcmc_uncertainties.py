"""Honest uncertainties: how well does a noisy measurement pin down a model's parameters?

Run: ``python examples/mcmc_uncertainties.py``

A virtual gonioreflectometer measures a known plastic-like material with 2 % relative noise
(seeded), ``brdf.fit`` finds the optimum and ``brdf.mcmc`` samples the posterior (emcee, a small
budget here: 32 walkers, at most 4,000 steps). It prints each parameter's truth, median and 95 %
credible interval, whether the truth lies inside, and the strongest correlation between two
parameters: what the measurement cannot tell apart (here the diffuse albedo trades against the
specular scale).
"""

import numpy as np

import brdf

TRUTH = "lambert(albedo=0.4) + ggx(ks=0.3, alpha=0.25)"
START = "lambert(albedo=0.5) + ggx(ks=0.5, alpha=0.4)"


def main():
    table = brdf.measure(TRUTH, "random:400", noise="relative:0.02", seed=3)
    result = brdf.fit(table, START, loss="chi-square", seed=3)
    post = brdf.mcmc(table, result, walkers=32, max_steps=4000, seed=3)
    truth = brdf.parse(TRUTH).params
    print(f"{'parameter':16s} {'truth':>8s} {'median':>8s} {'95% interval':>22s}  inside")
    for name in (n for n in post.names if n in truth):
        lo, hi = post.interval(name, 95)
        inside = lo <= truth[name] <= hi
        print(f"{name:16s} {truth[name]:8.4f} {post.median[name]:8.4f} "
              f"[{lo:9.4f}, {hi:9.4f}]  {'yes' if inside else 'NO'}")
    corr = np.array(post.correlation)
    np.fill_diagonal(corr, 0.0)
    i, j = np.unravel_index(np.abs(corr).argmax(), corr.shape)
    print(f"strongest correlation: {post.names[i]} ~ {post.names[j]}: {corr[i, j]:+.2f}")
    print(f"converged: {post.converged} (tau {max(post.tau):.0f} steps, "
          f"acceptance {post.acceptance:.2f})")


if __name__ == "__main__":
    main()
