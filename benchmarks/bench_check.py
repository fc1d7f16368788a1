"""Wall time of ``brdf.check`` and of its energy check for one model of every family.

Run: ``python benchmarks/bench_check.py [--repeats 3]``

The target is an energy check under 1 s for any single model. Times are after a warm-up call
(numba compilation is cached to disk and reported separately by the first call). The baseline
named in the ratio column is that 1 s budget.
"""

import argparse
import time

import numpy as np

import brdf
from brdf.geometry import spherical_to_cartesian
from brdf.properties import check, incidence_grid

SPECS = [
    "lambert(albedo=0.8)",
    "mirror(fresnel=dielectric(eta=1.5))",
    "phong(ks=0.5, n=20)",
    "modified-phong(ks=0.5, n=200)",
    "blinn-phong(n=100)",
    "ward(alpha=0.2, variant=gmd)",
    "ward(alpha=0.1, alpha_y=0.4, variant=gmd)",
    "ggx(alpha=0.2, fresnel=schlick(f0=0.04))",
    "ggx(alpha=0.05, alpha_y=0.3)",
    "beckmann(alpha=0.2)",
    "beckmann(alpha=0.1, alpha_y=0.4)",
    "lafortune(cx=-1, cy=-1, cz=0.95, n=30)",
    "ashikhmin-shirley(rd=0.3, rs=0.6, nu=100, nv=1000)",
    "lambert(albedo=0.5) + ggx(alpha=0.2)",
]


def timed(fn, repeats):
    fn()
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(f"{'model':52s} {'energy s':>9s} {'/ 1 s':>6s} {'full check s':>13s}")
    for spec in SPECS:
        model = brdf.parse(spec)
        # the energy check's own grid: 90 incidence angles, or 24 x 8 for anisotropic models
        theta, phi = incidence_grid(*((24, 8) if model.is_anisotropic else (90, 1)))
        wi = spherical_to_cartesian(np.radians(theta)[None, :], np.radians(phi)[:, None])
        energy = timed(lambda: model.albedo(wi, return_error=True), args.repeats)
        full = timed(lambda: check(model), args.repeats)
        print(f"{spec:52s} {energy:9.3f} {energy:6.2f} {full:13.3f}")


if __name__ == "__main__":
    main()
