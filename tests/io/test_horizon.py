"""Every reader's eval up to the horizon: finite, and beyond the measured range held within
the measured values (RGL, whose eval combines both orders of the measured f cos(theta), is
tested in test_rgl_bsdf.py)."""

import math

import numpy as np
import pytest

import brdf
from brdf.geometry import spherical_to_cartesian
from brdf.io import curet, merl
from measured_data import measured

BUNDLED = "measurements/synthetic"


def _grid(anisotropic):
    """Direction pairs with both polar angles up to 1e-9 degrees from the horizon."""
    theta = np.radians(np.concatenate([np.arange(0.0, 90.0, 6.0),
                                       90.0 - np.logspace(-9.0, -1.0, 9)]))
    ti, to, dphi = np.meshgrid(theta, theta, np.radians(np.arange(0.0, 360.0, 30.0)),
                               indexing="ij")
    phi_i = np.radians(40.0) if anisotropic else 0.0
    wi = spherical_to_cartesian(ti.ravel(), phi_i)
    wo = spherical_to_cartesian(to.ravel(), phi_i + dphi.ravel())
    return wi, wo


def _merl(tmp_path):
    model = brdf.parse("lambert(albedo=0.4) + ggx(ks=0.5, alpha=0.2)")
    wi, wo = merl.grid_directions()
    path = tmp_path / "model.binary"
    merl.write(merl.MerlTable.from_grid_values(np.broadcast_to(model.eval(wi, wo),
                                                               (len(wi), 3))), path)
    return brdf.read(path)


def _npz(tmp_path):
    path = tmp_path / "plastic.npz"
    brdf.write(brdf.read(f"{BUNDLED}/plastic_grid.csv"), path)
    return brdf.read(path)


READERS = {
    "merl": _merl,
    "gonio-csv grid": lambda tmp: brdf.read(f"{BUNDLED}/plastic_grid.csv"),
    "gonio-csv scattered anisotropic": lambda tmp: brdf.read(
        f"{BUNDLED}/brushed_metal_random.csv"),
    "gonio-csv rgb": lambda tmp: brdf.read("tests/data/gonio_rgb.csv"),
    "npz": _npz,
    "nist-ptfe": lambda tmp: brdf.read(measured("nist-ptfe/PTFE.data.csv")),
    "cornell": lambda tmp: brdf.read(measured("cornell-paints/cayman.brdf")),
    "curet": lambda tmp: curet.read(measured("curet/abrdf.dat"), sample=7),
}


@pytest.mark.parametrize("reader", sorted(READERS))
def test_eval_is_finite_and_held_within_the_measured_values_to_the_horizon(reader, tmp_path):
    t = READERS[reader](tmp_path)
    wi, wo = _grid(t.is_anisotropic)
    f = np.asarray(t.eval(wi, wo))
    assert f.shape == (len(wi), t.channels) and np.all(np.isfinite(f))
    # every interpolant is a convex combination of samples, the nearest sample beyond them
    low, high = np.nanmin(t.values, axis=0), np.nanmax(t.values, axis=0)
    slack = 1e-9 * np.maximum(np.abs(low), np.abs(high))
    assert np.all(f >= low - slack) and np.all(f <= high + slack), reader
    # the last 0.1 degree adds nothing: f at 1e-9 degrees from the horizon is that at 0.1
    # degree for an interpolant held beyond its last measured polar angle (MERL: within the
    # half-vector cell the last angles share)
    near = math.radians(90.0 - 1e-9)
    last = math.radians(90.0 - 0.1)
    w_in = spherical_to_cartesian(math.radians(30.0), 0.0)
    if reader != "merl":
        np.testing.assert_allclose(t.eval(w_in, spherical_to_cartesian(near, 2.0)),
                                   t.eval(w_in, spherical_to_cartesian(last, 2.0)),
                                   rtol=1e-6, atol=1e-12)
