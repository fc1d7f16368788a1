"""Wall time of ``brdf.check`` and of its energy check for one model of every family.

Run: ``python benchmarks/bench_check.py [--repeats 5]``

The target is an energy check under 1 s for any single model; the ``/ 1 s`` column is the
energy time as a fraction of that budget. Times are the best of ``--repeats`` runs after a
warm-up call (numba compiles once per environment and caches to disk), so they still move with
the machine's load. The ``panels`` column does not: it counts the albedo cubature's panels over
the check's incidence grid (49 integrand samples each: 36 + 9 Gauss nodes and 4 corners;
mirror-image incident directions share one integral and cost none), the work itself.
"""

import argparse

import numpy as np

import brdf
from brdf.geometry import spherical_to_cartesian
from brdf.properties import check, incidence_grid
from timing import best_time

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
BUDGET_S = 1.0


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    print(f"{'model':52s} {'energy s':>9s} {'/ 1 s':>6s} {'panels':>8s} {'full check s':>13s}")
    worst = 0.0
    for spec in SPECS:
        model = brdf.parse(spec)
        # the energy check's own grid: 90 incidence angles, or 24 x 8 for anisotropic models
        theta, phi = incidence_grid(*((24, 8) if model.is_anisotropic else (90, 1)))
        wi = spherical_to_cartesian(np.radians(theta)[None, :], np.radians(phi)[:, None])
        energy, _ = best_time(lambda: model.albedo(wi, return_error=True), args.repeats)
        panels = int(model._albedo_cubature(wi)[2].sum())
        full, _ = best_time(lambda: check(model), args.repeats)
        worst = max(worst, energy)
        print(f"{spec:52s} {energy:9.3f} {energy / BUDGET_S:6.2f} {panels:8d} {full:13.3f}")
    verdict = "within" if worst < BUDGET_S else "OVER"
    print(f"slowest energy check {worst:.3f} s: {verdict} the {BUDGET_S:g} s budget")


if __name__ == "__main__":
    main()
