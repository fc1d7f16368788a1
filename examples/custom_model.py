"""Write and register your own BRDF family: Minnaert's limb-darkening law.

Run: ``python examples/custom_model.py``

Minnaert 1941 ("The reciprocity principle in lunar photometry", ApJ 93, 403, eq. 2) fits the
brightness of the Moon and planets by I = I_0 cos^k(i) cos^(k-1)(e): a reciprocal law that is
Lambert's for k = 1 and darkens towards the limb for k > 1. It is not in the library, so this
script writes it as a :class:`brdf.CustomModel` (parameters declared like a built-in family, one
vectorised numpy formula), registers it, checks it, fits it to a virtual gonioreflectometer
measurement and prints the recovered parameters next to the truth.

From the command line, the same file registers the model for ``brdf-fit``::

    brdf-fit --plugin examples/custom_model.py models
    brdf-fit --plugin examples/custom_model.py check "minnaert(albedo=0.8, k=1.5)"
"""

import math
import time

import numpy as np

import brdf
from brdf.models import Param

TRUTH = "minnaert(albedo=[0.62,0.48,0.33], k=1.6)"


@brdf.register_model
class Minnaert(brdf.CustomModel):
    """Minnaert's law as a BRDF, normalised to albedo ``albedo`` at normal incidence.

    f = albedo (k + 1) / (2 pi) (cos(theta_i) cos(theta_o))^(k - 1): the radiance
    I_0 cos^k(i) cos^(k-1)(e) of Minnaert 1941 over the irradiance cos(i), with the constant
    that makes the albedo at normal incidence equal ``albedo`` (the integral of
    cos^k(theta_o) over the hemisphere is 2 pi / (k + 1)). The albedo at theta_i is
    albedo cos^(k-1)(theta_i), at most ``albedo`` for k >= 1. k = 1 is Lambert's law.
    """

    name = "minnaert"
    aliases = ("minnaert-1941",)
    summary = "limb darkening, f ~ (cos theta_i cos theta_o)^(k - 1)"
    citation = "Minnaert 1941, The reciprocity principle in lunar photometry, ApJ 93, 403, eq. 2"
    PARAMS = (
        Param("albedo", 0.5, (0.0, 1.0), per_channel=True, aliases=("rho",),
              doc="albedo at normal incidence"),
        Param("k", 1.5, (1.0, 4.0), fit_bounds=(1.0, 3.0),
              doc="Minnaert exponent (1: Lambert; larger: darker towards the limb)"),
    )
    reciprocal = True        # symmetric in wi and wo (brdf.check tests it)
    energy_conserving = True  # albedo cos^(k-1)(theta_i) <= albedo for k >= 1 (tested too)
    isotropic = True         # no azimuth at all

    def formula(self, wi, wo):
        k = self["k"]
        # Minnaert 1941, eq. 2, divided by the irradiance cos(i) and normalised (see above)
        return self["albedo"] * ((k + 1.0) / (2.0 * math.pi)
                                 * (wi[:, 2] * wo[:, 2]) ** (k - 1.0))[:, None]


def main():
    start = time.perf_counter()
    model = brdf.parse(TRUTH)
    print(f"model: {model}   ({Minnaert.citation})")

    report = brdf.check(model, pairs=20_000, theta_steps=30)
    for c in report.checks:
        print(f"  check {c.name:15s} {'pass' if c.passed else 'FAIL'}  worst {c.worst:.4g}")
    wi = brdf.geometry.directions_from_degrees(np.array([0.0, 60.0, 85.0]), np.zeros(3))
    print("  albedo at theta_i = 0, 60, 85 deg (red):",
          np.array2string(model.albedo(wi)[:, 0], precision=4))

    # a gonioreflectometer scan with 1 % noise, then fits of Lambert and Minnaert
    table = brdf.measure(model, "grid:10,30", noise="relative:0.01", seed=1)
    lambert = brdf.fit(table, "lambert")
    fit = brdf.fit(table, "minnaert")
    print(f"measured {len(table.values)} samples; cosine-l2 loss: lambert "
          f"{lambert.loss:.3g}, minnaert {fit.loss:.3g} ({fit.status})")
    truth = model.params
    print(f"  {'parameter':22s} {'truth':>8s} {'fitted':>8s}")
    for name, value in fit.params.items():
        print(f"  {name:22s} {truth[name]:8.4f} {value:8.4f}")
    print(f"done in {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
