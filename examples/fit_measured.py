"""Fit a diffuse-plus-specular model to a real measurement bundled in measurements/.

Run: ``python examples/fit_measured.py [TABLE] [SPEC]``

By default it fits ``lambert + ggx`` with one roughness for the three channels to the RGL
white paper (EPFL's RGL material database, CC0; measurements/rgl/README), prints the fit
report (parameters, metrics, the optimizer's verdict, the physical checks of the result) and
the directional albedo of the fitted model. When the free fit reflects more than it receives
(the white paper's blue channel does, at grazing incidence), it fits again with the energy
constraint and prints what that costs in loss. It writes nothing.
"""

import sys
from pathlib import Path

import numpy as np

import brdf
from brdf.geometry import directions_from_degrees

ROOT = Path(__file__).resolve().parent.parent
TABLE = ROOT / "measurements" / "rgl" / "paper_white_rgb.bsdf"
SPEC = "lambert(albedo=0.5) + ggx(alpha=0.2, ks=0.1)"


def main(table=TABLE, spec=SPEC):
    data = brdf.read(table)
    print(f"{Path(table).name}: {len(data):,} samples, {data.channels} channels")
    result = brdf.fit(data, spec, shared=["ggx.alpha"], seed=0)
    print(result)
    if not result.energy["holds"]:
        free = result
        result = brdf.fit(data, spec, shared=["ggx.alpha"], seed=0, optimizer="LD_SLSQP",
                          energy_constraint=True)
        print(f"\nwith the energy constraint (LD_SLSQP): worst albedo "
              f"{result.energy['worst_albedo']:.6f}, loss {result.loss:.6g} "
              f"({result.loss / free.loss - 1.0:+.2%} against the free fit)")
        print(f"fitted: {result.spec}")
    theta = np.array([0.0, 30.0, 60.0, 80.0])
    albedo = result.model.albedo(directions_from_degrees(theta, np.zeros_like(theta)))
    print("\ndirectional albedo of the fit (channels R, G, B):")
    for t, a in zip(theta, albedo):
        print(f"  theta_i = {t:4.0f} deg: " + "  ".join(f"{v:.4f}" for v in a))
    return 0 if result.converged else 1


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
