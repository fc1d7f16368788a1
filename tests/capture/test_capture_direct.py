"""The direct method against Mitsuba 3 (an independent renderer): a ``lambert + ggx`` sphere
under a point light recovered within 2 %, an area light with and without interreflection, and
the 95 % intervals of a noisy 8-bit photograph with an unknown exposure; and the rays it casts
against closed forms."""

import numpy as np
import pytest

import brdf
from brdf import render
from brdf.render.image import write_exr
from brdf.render.rays import camera_rays, first_hits, occluded, to_local

from capture_scenes import (FLOOR_ALBEDO, TRUTH, max_relative_error, photograph, render_case,
                            scene_file)


def test_first_hits_on_a_sphere_match_the_closed_form():
    shapes = [render.Sphere((0, 0, 0), 1.0, "lambert"),
              render.Quad((-3, -1, 3), (6, 0, 0), (0, 0, -6), "lambert")]
    scene = render.Scene(render.Camera(origin=(0, 0, 4)), shapes)
    c = scene.compile()
    d, o = camera_rays(scene.camera, 32, 24)
    h = first_hits(c, o, d.reshape(-1, 3))
    on = h.shape == 0
    assert on.sum() > 50 and (h.shape == 1).sum() > 50
    # |p| = 1, the normal is p, the frame is orthonormal, the ray meets the front
    assert np.allclose(np.linalg.norm(h.position[on], axis=1), 1.0, atol=1e-9)
    assert np.allclose(h.normal[on], h.position[on], atol=1e-9)
    wo = to_local(h, -d.reshape(-1, 3))
    assert np.all(wo[h.hit, 2] > 0) and np.allclose(np.linalg.norm(wo[h.hit], axis=1), 1.0)
    assert np.allclose(np.sum(h.tangent[on] * h.shading[on], axis=1), 0.0, atol=1e-12)
    # straight down from above the sphere: blocked within 5, free past its side
    down = np.array([[0.0, -1.0, 0.0], [0.0, -1.0, 0.0]])
    blocked = occluded(c, np.array([[0.0, 3.0, 0.0], [2.0, 3.0, 0.0]]), down,
                       np.array([5.0, 3.5]))
    assert blocked.tolist() == [True, False]


@pytest.fixture(scope="module")
def case_a(tmp_path_factory):
    pytest.importorskip("mitsuba", reason="Mitsuba 3 renders the test images")
    tmp = tmp_path_factory.mktemp("case_a")
    write_exr(tmp / "a.exr", render_case("a", spp=512))
    return scene_file(tmp / "a.json", "a"), tmp / "a.exr"


def test_sphere_under_a_point_light_is_recovered_within_2_percent(case_a):
    r = brdf.fit_images("lambert + ggx", [case_a], progress=False)
    # measured: 0.21 % (alpha), the rest below 0.15 %, with Mitsuba's 512-spp noise
    assert max_relative_error(r.params) < 0.02, r.params
    c = r.capture
    assert c["method"] == "direct" and c["pixels_used"] > 1000
    assert c["image_loss"]["relative_rmse"] < 0.01
    doc = r.to_dict()
    assert list(doc)[-2:] == ["capture", "timing"] and doc["schema"] == "brdf.fit/1"


def test_report_loads_and_exports_and_cli_matches_the_library(case_a, tmp_path, capsys):
    from brdf_cli.main import main
    out = tmp_path / "r.json"
    status = main(["fit-images", "lambert + ggx", "--view", str(case_a[0]), str(case_a[1]),
                   "-o", str(out)])
    capsys.readouterr()
    assert status == 0
    rep = brdf.load_report(out)
    assert max_relative_error(rep.params) < 0.02
    assert rep.capture["views"][0]["image"] == str(case_a[1])
    assert brdf.export(rep, "mitsuba", tmp_path / "m.xml").exact


@pytest.mark.slow
def test_area_light_direct_only_and_the_interreflection_bias(tmp_path):
    pytest.importorskip("mitsuba", reason="Mitsuba 3 renders the test images")
    scene = scene_file(tmp_path / "b.json", "b")
    errors = {}
    for depth in (2, -1):
        write_exr(tmp_path / f"b{depth}.exr", render_case("b", spp=512, max_depth=depth))
        r = brdf.fit_images("lambert + ggx", [(scene, tmp_path / f"b{depth}.exr")],
                            progress=False)
        errors[depth] = {k: (v - TRUTH[k]) / TRUTH[k] for k, v in r.params.items()}
    # direct light only (Mitsuba max_depth 2): the area light's quadrature and the fixed-point
    # correction recover the truth (measured: within 0.9 % at 64 x 48 and 512 spp)
    assert max(abs(e) for e in errors[2].values()) < 0.02, errors[2]
    # with the floor's light reflected onto the sphere the albedo comes out high (measured
    # +1.7 to +1.8 %): the bias benchmarks/bench_inverse.py quotes
    bias = [errors[-1][f"lambert.albedo[{c}]"] - errors[2][f"lambert.albedo[{c}]"]
            for c in range(3)]
    assert all(0.005 < b < 0.05 for b in bias), bias


@pytest.mark.slow
def test_noisy_8bit_photograph_with_unknown_exposure_intervals_cover_the_truth(tmp_path):
    pytest.importorskip("mitsuba", reason="Mitsuba 3 renders the test images")
    from PIL import Image
    scene = scene_file(tmp_path / "n.json", "a", floor=True)
    # direct light only: the statistics are under test here, not interreflection
    linear = render_case("a", spp=256, max_depth=2, floor=True)
    photons, exposure = 2000, 1.2
    Image.fromarray(photograph(linear, photons, exposure, seed=1)).save(tmp_path / "n.png")
    r = brdf.fit_images("lambert + ggx", [(scene, tmp_path / "n.png")], response="srgb",
                        gain=photons, free_scale=True, mcmc=True, seed=0, progress=False)
    s = r.capture["scale"]
    assert abs(s["value"] - exposure) < 3 * s["sigma"], s
    assert s["reference_pixels"] > 200
    assert r.posterior.converged
    for name, truth in TRUTH.items():
        lo, hi = r.interval(name)
        assert lo <= truth <= hi, (name, truth, lo, hi)
    # the amplitudes' intervals carry the exposure's 0.36 % uncertainty
    lo, hi = r.interval("lambert.albedo[0]")
    assert (hi - lo) / r.params["lambert.albedo[0]"] > 2 * 1.96 * s["sigma"] / s["value"]
    assert FLOOR_ALBEDO == 0.6


@pytest.mark.slow
def test_directional_light_and_sky_in_two_views_within_2_percent(tmp_path):
    pytest.importorskip("mitsuba", reason="Mitsuba 3 renders the test images")
    from capture_scenes import render_sky, sky_file
    views = []
    for k, (direction, origin) in enumerate((((-1, -1, -1), None), ((1, -0.5, -1), (3, 1, 3)))):
        write_exr(tmp_path / f"v{k}.exr", render_sky(direction, spp=2048, origin=origin))
        views.append((sky_file(tmp_path / f"v{k}.json", direction, origin=origin),
                      tmp_path / f"v{k}.exr"))
    r = brdf.fit_images("lambert + ggx", views, progress=False)
    # the sky (radiance 0.3) is a third of the light on the lit side: predicted as L times
    # the model's albedo towards wo, the pixels it dominates left out; measured: within 1.2 %
    assert max_relative_error(r.params) < 0.02, r.params
    assert all(v["pixels_on_material"] > 500 for v in r.capture["views"])
    assert r.capture["iterations"] < 8


def test_two_point_lights_within_2_percent(tmp_path):
    mi = pytest.importorskip("mitsuba", reason="Mitsuba 3 renders the test images")
    import json
    from capture_scenes import CAMERA, _bsdf, _sensor
    mi.set_variant("scalar_rgb")
    lights = [{"position": [2.5, 2.5, 3.0], "intensity": 12.0},
              {"position": [-3.0, 0.5, 2.0], "intensity": 6.0}]
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": 2},
         "sensor": _sensor(mi, 64, 48, 512),
         "sphere": {"type": "sphere", "center": [0, 0, 0], "radius": 1.0, "bsdf": _bsdf()}}
    for k, light in enumerate(lights):
        d[f"light{k}"] = {"type": "point", "position": light["position"],
                          "intensity": {"type": "rgb", "value": [light["intensity"]] * 3}}
    write_exr(tmp_path / "two.exr", np.array(mi.render(mi.load_dict(d)), float)[..., :3])
    (tmp_path / "two.json").write_text(json.dumps({
        "camera": CAMERA, "lights": [{"type": "point", **light} for light in lights],
        "shapes": [{"type": "sphere", "centre": [0, 0, 0], "radius": 1.0,
                    "material": "@material"}]}))
    r = brdf.fit_images("lambert + ggx", [(tmp_path / "two.json", tmp_path / "two.exr")],
                        progress=False)
    # each pixel's sample is taken towards the light that dominates it, the other's share
    # carried by the fixed-point correction; measured: within 0.14 % at 1024 spp
    assert max_relative_error(r.params) < 0.02, r.params
    assert r.capture["iterations"] > 1


def test_spot_light_profile_against_our_renderer(tmp_path):
    # Mitsuba's spot has a smooth-step edge, ours the cos^n profile of classic course notes:
    # the reference here is our path tracer (direct light only), whose lights are tested
    # against closed forms in tests/render
    import json
    from capture_scenes import CAMERA, TRUTH_SPEC
    (tmp_path / "spot.json").write_text(json.dumps({
        "camera": CAMERA, "shapes": [{"type": "sphere", "centre": [0, 0, 0], "radius": 1.0,
                                      "material": "@material"}],
        "lights": [{"type": "spot", "position": [2.5, 2.5, 3.0], "direction": [-2.5, -2.5, -3.0],
                    "intensity": 15, "cutoff": 20, "exponent": 3}]}))
    scene = render.load(tmp_path / "spot.json", material=TRUTH_SPEC)
    photo = render.render(scene, spp=256, size=(64, 48), max_depth=2, progress=False,
                          layers=False, seed=2)
    photo.save(tmp_path / "spot.exr")
    r = brdf.fit_images("lambert + ggx", [(tmp_path / "spot.json", tmp_path / "spot.exr")],
                        progress=False)
    # measured: within 0.2 % at 512 spp; pixels across the cone's edge are left out
    assert max_relative_error(r.params) < 0.02, r.params


def test_a_mask_limits_the_pixels_and_keeps_the_fit(case_a, tmp_path):
    from PIL import Image
    mask = np.zeros((48, 64), np.uint8)
    mask[:, :32] = 255                      # the left half of the sphere only
    Image.fromarray(mask).save(tmp_path / "left.png")
    full = brdf.fit_images("lambert + ggx", [case_a], progress=False)
    half = brdf.fit_images("lambert + ggx", [(*case_a, tmp_path / "left.png")], progress=False)
    n_full, n_half = full.capture["pixels_used"], half.capture["pixels_used"]
    assert 0.3 * n_full < n_half < 0.7 * n_full
    assert half.capture["views"][0]["pixels_masked"] == 48 * 32
    assert max_relative_error(half.params) < 0.02, half.params


def test_cli_free_scale_from_a_reference_floor(tmp_path, capsys):
    pytest.importorskip("mitsuba", reason="Mitsuba 3 renders the test images")
    import json
    from PIL import Image
    from brdf_cli.main import main
    scene = scene_file(tmp_path / "n.json", "a", floor=True)
    linear = render_case("a", spp=128, max_depth=2, floor=True)
    Image.fromarray(photograph(linear, 4000, 0.8, seed=3)).save(tmp_path / "n.png")
    status = main(["fit-images", "lambert + ggx", "--view", str(scene), str(tmp_path / "n.png"),
                   "--response", "srgb", "--gain", "4000", "--free-scale", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert status == 0
    s = report["capture"]["scale"]
    assert s["free"] and abs(s["value"] - 0.8) < 4 * s["sigma"] + 0.002, s
    assert report["loss"]["name"] == "chi-square"
    assert max_relative_error(report["params"]) < 0.03, report["params"]


def test_residual_images_show_the_fit_on_the_pixels_used(case_a, tmp_path):
    import OpenEXR
    r = brdf.fit_images("lambert + ggx", [case_a], residuals=tmp_path / "res", progress=False)
    (path,) = r.capture["residual_images"]
    with OpenEXR.File(path) as f:
        ch = f.channels()
        resid = np.array(ch["RGB"].pixels, float)
        used = np.array(ch["used"].pixels, float)
        pred = np.array(ch["prediction"].pixels, float)
    assert int(used[..., 0].sum()) == r.capture["views"][0]["pixels_on_material"]
    on = used[..., 0] > 0
    # small against the pixels, zero off them
    assert np.abs(resid[on]).mean() < 0.01 * pred[on].mean()
    assert not resid[~on].any()
    with pytest.raises(brdf.OutputError):
        brdf.fit_images("lambert + ggx", [case_a], residuals=tmp_path / "res", progress=False)
