"""Compare the energy behaviour of a few classic models, the way a shading researcher would.

Run: ``python examples/check_models.py``

Prints, for each model, its albedo at normal and grazing incidence and the verdict of the three
physical checks; then shows where the worst violation of a failing model lies.
"""

import numpy as np

import brdf
from brdf.geometry import spherical_to_cartesian

SPECS = [
    "lambert(albedo=0.8) + ggx(alpha=0.2, ks=0.2, fresnel=schlick(f0=0.04))",
    "blinn-phong(n=10, normalization=approx)",
    "blinn-phong(n=10, normalization=exact)",
    "ward(alpha=0.2, variant=duer)",
    "ward(alpha=0.2, variant=gmd)",
    "phong(ks=0.5, n=20)",
]


def main():
    wi = spherical_to_cartesian(np.radians([0.0, 85.0]), 0.0)
    print(f"{'model':70s} {'a(0)':>7s} {'a(85)':>7s}  checks")
    for spec in SPECS:
        model = brdf.parse(spec)
        a = model.albedo(wi).mean(axis=-1)
        report = brdf.check(model)
        verdicts = ", ".join(f"{c.name} {'ok' if c.passed else 'FAIL'}" for c in report.checks)
        print(f"{spec:70s} {a[0]:7.4f} {a[1]:7.4f}  {verdicts}")
    worst = brdf.check("ward(alpha=0.2, variant=duer)").checks[-1]
    print(f"\nDuer's Ward: largest albedo {worst.worst:.3f} at theta_i = "
          f"{worst.where['theta_i']:.1f} degrees (tolerance {worst.tolerance:.2g})")


if __name__ == "__main__":
    main()
