"""brdf.viz.lobes: the lobe mesh is r(wo) wo with r = f cos(theta_o) from the subject's own eval,
measured samples land where they were measured, and the off-screen PNG shows something that
changes with the parameters."""

import math
import os

import numpy as np
import pytest

import brdf
from brdf.errors import BRDFError, InputError, OutputError
from brdf.geometry import spherical_to_cartesian
from brdf.viz import lobes, plot_lobes
from brdf.models import Lambert
from brdf.viz.lobes import MAX_RESOLUTION, lobe_plotter, lobe_surface
from brdf.viz.samples import in_plane, incidence, samples_near
from pictures import changed_fraction, distinct_colours, drawn_fraction, read_png

SMALL = {"window_size": (260, 220), "resolution": 24}
GGX = "lambert(albedo=0.3) + ggx(alpha={alpha}, ks=0.6)"


@pytest.fixture(scope="module")
def pictures(tmp_path_factory):
    """Images of the same scene at two roughnesses, and log and no-cosine variants."""
    folder = tmp_path_factory.mktemp("lobes")
    out = {}
    for key, alpha, options in [("0.1", 0.1, {}), ("0.4", 0.4, {}), ("log", 0.1, {"log": True}),
                                ("f", 0.1, {"cosine": False})]:
        path = folder / f"{key}.png"
        returned = plot_lobes(brdf.parse(GGX.format(alpha=alpha)), [45.0], path=path,
                              **SMALL, **options)
        out[key] = (path, returned)
    return out


def test_the_png_is_a_picture_of_the_lobe(pictures):
    path, returned = pictures["0.1"]
    img = read_png(path)
    assert img.shape == (220, 260, 3)
    assert np.array_equal(img, returned[..., :3])
    assert distinct_colours(img) > 200      # shading, colour map, arrows, text
    assert 0.1 < drawn_fraction(img) < 0.95


@pytest.mark.parametrize("other", ["0.4", "log", "f"])
def test_the_picture_changes_with_the_parameters_and_options(pictures, other):
    a, b = read_png(pictures["0.1"][0]), read_png(pictures[other][0])
    assert changed_fraction(a, b) > 0.03


def test_several_incidences_make_one_view_each(tmp_path):
    img = plot_lobes(brdf.parse(GGX.format(alpha=0.2)), [20.0, 60.0], path=tmp_path / "two.png",
                     window_size=(400, 200), resolution=16)
    assert img.shape[:2] == (200, 400)
    # the views differ: the lobe leans further over at 60 degrees
    assert changed_fraction(img[:, :200], img[:, 200:]) > 0.03


def test_lambert_lobes_are_a_hemisphere_and_a_sphere_tangent_at_the_origin():
    model = brdf.parse("lambert(albedo=0.5)")
    wi = incidence(30.0)
    bare = lobe_surface(model, wi, cosine=False, resolution=12)
    np.testing.assert_allclose(np.linalg.norm(bare.points, axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(bare["value"], 0.5 / math.pi, rtol=1e-6)
    # r = (rho/pi) cos(theta_o), scaled by the peak rho/pi: a sphere of diameter 1 on the origin
    lobe = lobe_surface(model, wi, resolution=12)
    np.testing.assert_allclose(np.linalg.norm(lobe.points - [0, 0, 0.5], axis=1), 0.5,
                               atol=1e-6)


def test_surface_values_are_the_models_eval_times_the_cosine():
    model = brdf.parse("lambert(albedo=[0.2,0.4,0.6]) + ggx(alpha=0.3, ks=0.5)")
    wi = incidence(40.0, 25.0)
    mesh = lobe_surface(model, wi, resolution=10, channel=2)
    wo = mesh.points / np.linalg.norm(mesh.points, axis=1, keepdims=True)
    expected = model.eval(np.broadcast_to(wi, wo.shape), wo)[:, 2] * wo[:, 2]
    np.testing.assert_allclose(mesh["value"], expected, rtol=1e-6)
    peak = mesh["value"].max()
    np.testing.assert_allclose(np.linalg.norm(mesh.points, axis=1), mesh["value"] / peak,
                               rtol=1e-6)


def test_log_radius_spans_the_stated_decades():
    model = brdf.parse(GGX.format(alpha=0.1))
    mesh = lobe_surface(model, incidence(45.0), log=True, resolution=16)
    r = np.linalg.norm(mesh.points, axis=1)
    value = mesh["value"]
    peak = value.max()
    expected = np.clip(np.log10(np.maximum(value, peak * 1e-3) / (peak * 1e-3)) / 3.0, 0, None)
    np.testing.assert_allclose(r, expected, atol=1e-6)
    assert r.max() == pytest.approx(1.0)


def test_isotropic_samples_are_turned_onto_the_asked_azimuth():
    model = brdf.parse("lambert(albedo=0.3) + ggx(alpha=0.3, ks=0.6)")
    table = brdf.measure(model, "grid:10,30", "none", seed=0)
    wi = incidence(30.0, 40.0)    # the grid measured at phi_i = 0 only
    wo, values = samples_near(table, wi)
    assert len(wo) > 20
    np.testing.assert_allclose(model.eval(np.broadcast_to(wi, wo.shape), wo), values, rtol=1e-6)


def test_in_plane_sign_convention_matches_the_predictive_bands():
    wi = incidence(30.0, 70.0)
    mirror = np.array([-wi[0], -wi[1], wi[2]])
    out_of_plane = spherical_to_cartesian(math.radians(30.0), math.radians(160.0))
    keep, signed = in_plane(wi, np.stack([wi, mirror, out_of_plane]))
    assert keep.tolist() == [True, True, False]
    np.testing.assert_allclose(signed[:2], [-30.0, 30.0])


def test_bad_incidence_and_channel_are_one_line_errors(tmp_path):
    model = brdf.parse("lambert(albedo=[0.2,0.4,0.6])")
    with pytest.raises(InputError, match="theta_i 90 must be in"):
        plot_lobes(model, [90.0], path=tmp_path / "x.png")
    with pytest.raises(InputError, match="channel 3 does not exist; the subject has 3"):
        plot_lobes(model, [30.0], path=tmp_path / "x.png", channel=3)
    with pytest.raises(InputError, match="PNG"):
        plot_lobes(model, [30.0], path=tmp_path / "x.jpg")
    with pytest.raises(InputError, match="zero everywhere"):
        plot_lobes(brdf.parse("lambert(albedo=0)"), [30.0], path=tmp_path / "x.png")
    assert not list(tmp_path.iterdir())


def test_an_existing_png_is_kept_without_force(tmp_path):
    path = tmp_path / "lobe.png"
    path.write_bytes(b"mine")
    model = brdf.parse("lambert(albedo=0.5)")
    with pytest.raises(OutputError, match="exists"):
        plot_lobes(model, [30.0], path=path, **SMALL)
    assert path.read_bytes() == b"mine"
    plot_lobes(model, [30.0], path=path, force=True, **SMALL)
    assert read_png(path).shape == (220, 260, 3)
    assert [p.name for p in tmp_path.iterdir()] == ["lobe.png"]   # no temporary left behind


def test_display_detection(monkeypatch):
    import pyvista
    monkeypatch.setattr(lobes.sys, "platform", "linux")
    monkeypatch.setattr(pyvista, "OFF_SCREEN", False)
    monkeypatch.setenv("DISPLAY", ":0")
    assert lobes.has_display()
    monkeypatch.setattr(pyvista, "OFF_SCREEN", True)
    assert not lobes.has_display()
    monkeypatch.setattr(pyvista, "OFF_SCREEN", False)
    monkeypatch.delenv("DISPLAY")
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert not lobes.has_display()
    with pytest.raises(BRDFError, match="no display"):
        plot_lobes(brdf.parse("lambert"), [30.0])


def test_headless_without_egl_says_which_packages_to_install(monkeypatch, tmp_path):
    monkeypatch.setattr(lobes.sys, "platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.setattr(lobes.ctypes.util, "find_library", lambda name: None)
    with pytest.raises(BRDFError, match="apt-get install -y --no-install-recommends libegl1 "
                                        "libgl1-mesa-dri"):
        plot_lobes(brdf.parse("lambert"), [30.0], path=tmp_path / "x.png")
    assert not os.listdir(tmp_path)


def test_dense_tables_show_the_samples_taken_closest_to_the_incidence():
    from brdf.viz.samples import ENOUGH
    model = brdf.parse("lambert(albedo=0.3) + ggx(alpha=0.1, ks=0.6)")
    dense = brdf.measure(model, "random:40000", "none", seed=2)
    wi = incidence(30.0)
    tight, _ = samples_near(dense, wi, max_points=None)
    band, _ = samples_near(dense, wi, tol_deg=2.5, max_points=None)
    assert ENOUGH <= len(tight) < len(band) / 5
    # a sparse table falls back to the wide band
    sparse = brdf.measure(model, "random:800", "none", seed=2)
    assert len(samples_near(sparse, wi, max_points=None)[0]) == len(
        samples_near(sparse, wi, tol_deg=2.5, max_points=None)[0])


@pytest.mark.parametrize("resolution", [3, 2.5, "48", True, MAX_RESOLUTION + 1])
def test_resolution_is_an_integer_in_range(resolution):
    with pytest.raises(InputError, match="resolution must be an integer from 4"):
        lobe_surface(Lambert(), incidence(30.0), resolution=resolution)
    with pytest.raises(InputError, match="lobe_plotter: resolution"):
        lobe_plotter(Lambert(), (30.0,), resolution=resolution, off_screen=True)
