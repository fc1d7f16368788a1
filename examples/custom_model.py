"""Write and register your own BRDF family: the Oren-Nayar rough-diffuse model.

Run: ``python examples/custom_model.py``

Oren & Nayar 1994 ("Generalization of Lambert's Reflectance Model", SIGGRAPH, eq. 30) model a
rough diffuse surface (clay, plaster, the Moon) as V-cavities of Lambertian facets whose slopes
have standard deviation ``sigma``; their "qualitative" model keeps the main effect, a surface
that grows brighter towards the light at grazing angles. It is not in the library, so this
script writes it as a :class:`brdf.CustomModel` (parameters declared like a built-in family, one
vectorised numpy formula), registers it, checks it, fits it to a virtual gonioreflectometer
measurement and prints the recovered parameters next to the truth.

From the command line, the same file registers the model for ``brdf-fit``::

    brdf-fit --plugin examples/custom_model.py models
    brdf-fit --plugin examples/custom_model.py check "oren-nayar(albedo=0.8, sigma=0.5)"
"""

import math
import time

import numpy as np

import brdf
from brdf.models import Param

INV_PI = 1.0 / math.pi
TRUTH = "oren-nayar(albedo=[0.62,0.48,0.33], sigma=0.45)"


@brdf.register_model
class OrenNayar(brdf.CustomModel):
    """Oren-Nayar rough diffuse reflection, qualitative model.

    f = albedo / pi (A + B max(0, cos(phi_i - phi_o)) sin(alpha) tan(beta)), with
    alpha = max(theta_i, theta_o), beta = min(theta_i, theta_o),
    A = 1 - 0.5 sigma^2 / (sigma^2 + 0.33) and B = 0.45 sigma^2 / (sigma^2 + 0.09).
    sigma = 0 is Lambert's law.
    """

    name = "oren-nayar"
    aliases = ("oren_nayar",)
    summary = "rough diffuse (V-cavities of Lambertian facets), qualitative model"
    citation = ("Oren & Nayar 1994, Generalization of Lambert's Reflectance Model, SIGGRAPH, "
                "eq. 30")
    PARAMS = (
        Param("albedo", 0.5, (0.0, 1.0), per_channel=True, aliases=("rho",),
              doc="albedo of the Lambertian facets"),
        Param("sigma", 0.3, (0.0, 0.5 * math.pi), units="rad", fit_bounds=(0.0, 1.0),
              doc="standard deviation of the facet slope angle"),
    )
    reciprocal = True        # symmetric in wi and wo (brdf.check tests it)
    energy_conserving = True  # albedo <= 1 for albedo <= 1 (brdf.check tests it)
    isotropic = True         # depends on the azimuths through their difference only

    def formula(self, wi, wo):
        s2 = self["sigma"] ** 2
        a = 1.0 - 0.5 * s2 / (s2 + 0.33)  # eq. 30
        b = 0.45 * s2 / (s2 + 0.09)
        # max(0, cos(phi_i - phi_o)) sin(alpha) tan(beta) without angles: sin(theta_i)
        # sin(theta_o) cos(phi_i - phi_o) is the dot product of the directions' xy parts, and
        # sin(alpha) tan(beta) / (sin(theta_i) sin(theta_o)) = 1 / cos(beta), the larger cosine
        g = np.maximum(0.0, wi[:, 0] * wo[:, 0] + wi[:, 1] * wo[:, 1]) \
            / np.maximum(wi[:, 2], wo[:, 2])
        # albedo times 1/pi, as the Lambert kernel computes it: sigma = 0 gives Lambert exactly
        return self["albedo"] * INV_PI * (a + b * g)[:, None]


def main():
    start = time.perf_counter()
    model = brdf.parse(TRUTH)
    print(f"model: {model}   ({OrenNayar.citation})")

    report = brdf.check(model, pairs=20_000, theta_steps=30)
    for c in report.checks:
        print(f"  check {c.name:15s} {'pass' if c.passed else 'FAIL'}  worst {c.worst:.4g}")
    wi = brdf.geometry.directions_from_degrees(np.array([0.0, 60.0, 85.0]), np.zeros(3))
    print("  albedo at theta_i = 0, 60, 85 deg (red):",
          np.array2string(model.albedo(wi)[:, 0], precision=4))

    # a gonioreflectometer scan with 1 % noise, then fits of Lambert and Oren-Nayar
    table = brdf.measure(model, "grid:10,30", noise="relative:0.01", seed=1)
    lambert = brdf.fit(table, "lambert")
    fit = brdf.fit(table, "oren-nayar")
    print(f"measured {len(table.values)} samples; cosine-l2 loss: lambert "
          f"{lambert.loss:.3g}, oren-nayar {fit.loss:.3g} ({fit.status})")
    truth = model.params
    print(f"  {'parameter':22s} {'truth':>8s} {'fitted':>8s}")
    for name, value in fit.params.items():
        print(f"  {name:22s} {truth[name]:8.4f} {value:8.4f}")
    print(f"done in {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
