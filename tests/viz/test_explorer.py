"""The interactive explorer: its view arrays against independent results (analytic Lambert
shading, the library's own albedo and in-plane evaluation, the declarations), and the page in a
real headless browser (Debian's chromium and chromedriver, driven by selenium)."""

import math
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

import brdf
from brdf.errors import InputError, SpecError
from brdf.geometry import reflect, spherical_to_cartesian
from brdf.viz import view_data

ROOT = Path(__file__).resolve().parents[2]
SPEC = "lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.2, fresnel=schlick(f0=0.04))"


# -- sliders from the declarations ------------------------------------------------------------

def test_sliders_follow_the_declarations():
    model = brdf.parse(SPEC)
    sliders = {s.name: s for s in view_data.parameter_sliders(model)}
    # one per channel of a per-channel value, nested components included
    assert list(sliders) == ["lambert.albedo[0]", "lambert.albedo[1]", "lambert.albedo[2]",
                             "ggx.ks", "ggx.alpha", "ggx.fresnel.f0"]
    assert set(sliders) == set(model.params)
    alpha = type(model.lobes[1]).declaration("alpha")
    assert alpha.prior == "log" and sliders["ggx.alpha"].log
    assert (sliders["ggx.alpha"].low, sliders["ggx.alpha"].high) == alpha.fit_bounds
    assert not sliders["lambert.albedo[0]"].log
    assert (sliders["lambert.albedo[1]"].value, sliders["lambert.albedo[1]"].low,
            sliders["lambert.albedo[1]"].high) == (0.4, 0.0, 1.0)
    # every range is finite and holds the value
    for s in sliders.values():
        assert math.isfinite(s.low) and math.isfinite(s.high) and s.low <= s.value <= s.high


def test_an_open_fit_box_gets_a_finite_log_range():
    model = brdf.parse("phong(n=2000)")
    for s in view_data.parameter_sliders(model):
        assert 0 < s.high and math.isfinite(s.high) and s.low <= s.value <= s.high
        if s.log:
            assert s.low > 0


def test_with_parameter_sets_one_value_and_validates():
    model = brdf.parse(SPEC)
    changed = view_data.with_parameter(model, "lambert.albedo[1]", 0.9)
    assert changed.params["lambert.albedo[1]"] == 0.9
    assert {k: v for k, v in changed.params.items() if k != "lambert.albedo[1]"} == \
        {k: v for k, v in model.params.items() if k != "lambert.albedo[1]"}
    assert view_data.with_parameter(model, "ggx.fresnel.f0", 0.5).params["ggx.fresnel.f0"] == 0.5
    single = view_data.with_parameter(brdf.parse("ggx"), "ggx.alpha", 0.3)
    assert single == brdf.parse("ggx(alpha=0.3)")
    with pytest.raises(SpecError, match="bounds"):
        view_data.with_parameter(model, "ggx.alpha", 10.0)
    with pytest.raises(InputError, match="no parameter"):
        view_data.with_parameter(model, "beckmann.alpha", 0.1)


# -- lobe and curves --------------------------------------------------------------------------

def test_lobe_mesh_is_closed_and_peaks_at_the_mirror_direction():
    model = brdf.parse("ggx(alpha=0.05)")
    wi = spherical_to_cartesian(math.radians(40.0), math.radians(30.0))
    points, triangles, values, peak, directions = view_data.lobe_mesh(model, wi, cosine=False,
                                                                      resolution=64)
    assert triangles.min() == 0 and triangles.max() == len(points) - 1
    # every edge of the hemisphere's cap is shared by two triangles except the rim's
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]],
                                    triangles[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert set(counts) == {1, 2} and (counts == 1).sum() == 2 * 64
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0, atol=1e-12)
    assert np.isclose(peak, values.max())
    top = directions[np.argmax(values)]
    assert np.degrees(np.arccos(np.clip(top @ reflect(wi), -1, 1))) < 3.0
    # the radius is f / peak: the model's own values
    np.testing.assert_allclose(np.linalg.norm(points, axis=1) * peak,
                               model.eval(np.broadcast_to(wi, directions.shape),
                                          directions)[:, 0], rtol=1e-12)


def test_log_lobe_radius_spans_the_stated_decades():
    values = np.array([1.0, 0.1, 1e-3, 1e-5])
    np.testing.assert_allclose(view_data.lobe_radius(values, 1.0, log=True),
                               [1.0, 2 / 3, 0.0, 0.0])
    np.testing.assert_allclose(view_data.lobe_radius(values, 2.0), values / 2)


def test_polar_curve_is_the_in_plane_brdf():
    model = brdf.parse(SPEC)
    wi = spherical_to_cartesian(math.radians(30.0), 0.0)
    angles, f = view_data.polar_curve(model, wi, step=1.0)
    assert angles[0] == -89 and angles[-1] == 89 and f.shape == (179, 3)
    # +30 degrees on the specular side is the mirror direction of wi (phi_o = 180)
    k = int(np.argmin(abs(angles - 30)))
    np.testing.assert_allclose(f[k], model.eval(wi, reflect(wi)), rtol=1e-12)
    _, fc = view_data.polar_curve(model, wi, step=1.0, cosine=True)
    np.testing.assert_allclose(fc[:, 0], f[:, 0] * np.cos(np.radians(angles)), rtol=1e-12)


def test_measured_samples_in_the_plane_are_the_measured_values():
    model = brdf.parse("lambert(albedo=0.3) + ggx(alpha=0.3)")
    table = brdf.measure(model, "inplane:5")  # noiseless: the values are the model's
    wi = spherical_to_cartesian(math.radians(30.0), 0.0)
    angles, f = view_data.measured_in_plane(table, wi)
    # both sides of the normal, every 5 degrees
    assert len(angles) >= 30 and angles.min() < -60 and angles.max() > 60
    np.testing.assert_allclose(angles / 5, np.round(angles / 5), atol=1e-9)
    from brdf.viz.samples import in_plane_directions
    wo = in_plane_directions(wi, angles)
    np.testing.assert_allclose(f, model.eval(np.broadcast_to(wi, wo.shape), wo), rtol=1e-9)
    _, fc = view_data.measured_in_plane(table, wi, cosine=True)
    np.testing.assert_allclose(fc, f * wo[:, 2:3], rtol=1e-12)


def test_slice_image_is_the_brdf_at_its_half_and_difference_angles():
    model = brdf.parse(SPEC)
    image = view_data.slice_image(model, phi_d=90.0, resolution=30)
    assert image.shape == (30, 30, 3)
    # pixel (row i, column j): theta_d = 90 (i + 0.5) / 30, theta_h = 90 ((j + 0.5) / 30)^2
    for i, j in ((0, 0), (7, 19), (29, 3), (15, 15)):
        th, td = math.pi / 2 * ((j + 0.5) / 30) ** 2, math.pi / 2 * (i + 0.5) / 30
        h = spherical_to_cartesian(th, 0.0)
        # wi from (theta_d, phi_d) about h: Rusinkiewicz 1998, built here with a rotation
        # matrix of its own rather than brdf.geometry's
        d = spherical_to_cartesian(td, math.pi / 2)
        c, s_ = math.cos(th), math.sin(th)
        wi = np.array([[c, 0, s_], [0, 1, 0], [-s_, 0, c]]) @ d
        wo = 2 * (wi @ h) * h - wi
        if wi[2] <= 0 or wo[2] <= 0:
            assert np.isnan(image[i, j]).all()
        else:
            np.testing.assert_allclose(image[i, j], model.eval(wi, wo), rtol=1e-9)
    assert np.isfinite(image).all()  # at phi_d = 90 both directions stay above the horizon
    # at phi_d = 0 they leave it where theta_h + theta_d > 90 degrees: the top right corner
    image = view_data.slice_image(model, phi_d=0.0, resolution=30)
    th = 90 * ((np.arange(30) + 0.5) / 30) ** 2
    td = 90 * (np.arange(30) + 0.5) / 30
    np.testing.assert_array_equal(np.isnan(image[..., 0]), td[:, None] + th[None, :] > 90)


def test_measured_samples_near_the_incidence_carry_the_lobes_quantity():
    model = brdf.parse("lambert(albedo=0.3) + ggx(alpha=0.3)")
    table = brdf.measure(model, "grid:10,30")
    wi = spherical_to_cartesian(math.radians(30.0), 0.0)
    wo, r = view_data.measured_near(table, wi)
    assert len(wo) > 20
    np.testing.assert_allclose(r, model.eval(np.broadcast_to(wi, wo.shape), wo) * wo[:, 2:3],
                               rtol=1e-9)


def test_albedo_curve_is_the_models_albedo():
    model = brdf.parse(SPEC)
    theta = np.array([0.0, 45.0, 80.0])
    curve = view_data.albedo_curve(model, theta, tol=1e-6)
    wi = spherical_to_cartesian(np.radians(theta), np.zeros(3))
    np.testing.assert_allclose(curve, model.albedo(wi, tol=1e-6), rtol=1e-9)
    # Lambert: the albedo parameter at every angle
    np.testing.assert_allclose(view_data.albedo_curve(brdf.parse("lambert(albedo=0.7)"),
                                                      theta), 0.7, rtol=1e-6)


# -- lit sphere -------------------------------------------------------------------------------

def _sphere_normals(size):
    """Independent ray-sphere hits: the camera of brdf.render.scenes.lit_sphere (pinhole at
    z = 4, 32 degrees across), pixel centres, row 0 at the top."""
    half = math.tan(math.radians(16.0))
    out = np.full((size, size, 3), np.nan)
    for row in range(size):
        for col in range(size):
            x = ((col + 0.5) / size * 2 - 1) * half
            y = -((row + 0.5) / size * 2 - 1) * half
            d = np.array([x, y, -1.0]) / math.sqrt(x * x + y * y + 1)
            o = np.array([0.0, 0.0, 4.0])
            b = o @ d
            disc = b * b - 15.0
            if disc > 0:
                out[row, col] = o + (-b - math.sqrt(disc)) * d
    return out


def test_lambert_sphere_is_albedo_over_pi_cos_irradiance_plus_environment():
    albedo = np.array([0.8, 0.5, 0.2])
    size = 24
    image = view_data.sphere_preview(brdf.parse("lambert(albedo=[0.8,0.5,0.2])"), size)
    n = _sphere_normals(size)
    hit = ~np.isnan(n[..., 0])
    assert (~np.isnan(image[..., 0]) == hit).all() and hit.sum() > 0.5 * size * size
    cos = np.maximum(n[hit] @ view_data.KEY_LIGHT, 0.0)
    # Lambert under a parallel light: L = (albedo / pi) E cos(theta_i); a uniform environment
    # of radiance L_env adds albedo L_env (Pharr et al., PBR 4th ed., eq. 4.14)
    expected = (albedo / math.pi * view_data.KEY_IRRADIANCE * cos[:, None]
                + albedo * view_data.ENVIRONMENT)
    np.testing.assert_allclose(image[hit], expected, rtol=1e-6)


def test_sphere_highlight_sits_at_the_half_vector():
    image = view_data.sphere_preview(brdf.parse("ggx(alpha=0.05)"), 64, environment=0.0)
    n = _sphere_normals(64)
    row, col = np.unravel_index(np.nanargmax(image[..., 0]), image.shape[:2])
    view = np.array([0.0, 0.0, 4.0]) - n[row, col]
    half = view / np.linalg.norm(view) + view_data.KEY_LIGHT
    half /= np.linalg.norm(half)
    assert math.degrees(math.acos(min(1.0, n[row, col] @ half))) < 3.0


def test_path_traced_sphere_agrees_with_the_preview():
    # a lone convex sphere has no interreflection: the path tracer's estimate of the same
    # direct and environment light converges to the preview
    model = brdf.parse("lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.2)")
    preview = view_data.sphere_preview(model, 32)
    traced = view_data.sphere_render(model, 32, spp=256, seed=1)
    hit = ~np.isnan(preview[..., 0])
    assert (np.isnan(traced[..., 0]) == ~hit).all()
    # the interior, away from the silhouette, which the renderer antialiases and the preview
    # samples at pixel centres
    inner = hit.copy()
    for axis in (0, 1):
        for shift in (1, -1):
            inner &= np.roll(hit, shift, axis)
    ratio = traced[inner].mean(axis=0) / preview[inner].mean(axis=0)
    np.testing.assert_allclose(ratio, 1.0, atol=0.02)
    assert np.median(abs(traced[inner] / preview[inner] - 1)) < 0.05


def test_torus_mesh_is_closed_and_its_normals_face_out():
    mesh = view_data.torus_mesh(segments=(24, 12))
    faces = mesh.faces
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]),
                    axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert set(counts) == {2}  # a closed surface
    a, b, c = (mesh.vertices[faces[:, k]] for k in range(3))
    facet = np.cross(b - a, c - a)
    assert (np.einsum("ij,ij->i", facet, mesh.normals[faces].mean(axis=1)) > 0).all()
    # every vertex on the torus (R - sqrt(x^2 + z^2))^2 + y^2 = r^2 in its own frame
    tilt = math.radians(view_data.TORUS_TILT)
    rot = np.array([[1, 0, 0], [0, math.cos(tilt), -math.sin(tilt)],
                    [0, math.sin(tilt), math.cos(tilt)]])
    local = mesh.vertices @ rot
    big, small = view_data.TORUS_RADII
    np.testing.assert_allclose(np.hypot(np.hypot(local[:, 0], local[:, 2]) - big,
                                        local[:, 1]), small, rtol=1e-12)


def test_lit_object_preview_agrees_with_the_path_tracer():
    # direct light only (no environment, paths of two segments): the preview's shading and
    # shadows against the renderer's estimate for the mesh of the same torus
    model = brdf.parse("lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.2)")
    preview = view_data.object_preview(model, 48, environment=0.0)
    traced = view_data.object_render(model, 48, spp=256, seed=1, environment=0.0, max_depth=2)
    hit = ~np.isnan(preview[..., 0])
    assert 0.3 < hit.mean() < 0.7
    inner = hit.copy()
    for axis in (0, 1):
        for shift in (1, -1):
            inner &= np.roll(hit, shift, axis)
    ratio = traced[inner].mean(axis=0) / preview[inner].mean(axis=0)
    np.testing.assert_allclose(ratio, 1.0, atol=0.02)
    lit = preview[inner][:, 0] > 0.02
    assert np.median(abs(traced[inner][lit] / preview[inner][lit] - 1)) < 0.03
    # the key light's shadow: a part of the torus is dark in both
    dark = preview[inner][:, 0] == 0.0
    assert dark.sum() > 20 and (traced[inner][dark][:, 0] < 0.02).mean() > 0.8


def test_sky_lights_carry_the_maps_irradiance():
    directions, irradiance = view_data.sky_lights(16)
    assert directions.shape == irradiance.shape == (16, 3)
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0, rtol=1e-12)
    # the map's irradiance, sum of radiance times pixel solid angle 2 pi^2 sin(theta) / (h w)
    # (PBR 3rd ed. eq. 14.9), computed here over the pixel grid
    sky = view_data.sky_map()
    h, w = sky.shape[:2]
    theta = np.pi * (np.arange(h) + 0.5) / h
    total = (sky * (2 * np.pi ** 2 * np.sin(theta) / (h * w))[:, None, None]).sum((0, 1))
    np.testing.assert_allclose(irradiance.sum(0), total, rtol=1e-12)
    # regions of equal energy (Debevec 2005): the lights crowd into the sun as its share of
    # the map's luminance says, give or take a region's worth on each side
    directions, irradiance = view_data.sky_lights(64)
    phi = 2 * np.pi * (np.arange(w) + 0.5) / w
    T, P = np.meshgrid(theta, phi, indexing="ij")
    d = np.stack([np.sin(T) * np.sin(P), np.cos(T), -np.sin(T) * np.cos(P)], -1)
    luminance = (sky @ [0.2126, 0.7152, 0.0722]) * np.sin(T)
    near = d @ view_data.SUN > math.cos(math.radians(15.0))
    share = luminance[near].sum() / luminance.sum()
    count = (directions @ view_data.SUN > math.cos(math.radians(15.0))).sum()
    assert 0.3 < share and abs(count - 64 * share) <= 4, (count, share)


@pytest.mark.parametrize("spec", ["lambert(albedo=[0.5,0.4,0.3])",
                                  "lambert(albedo=0.5) + ggx(alpha=0.3)"])
def test_sky_preview_agrees_with_the_path_tracer_under_the_map(spec):
    # the renderer reads the map through its own envmap lookup: a preview built on another
    # orientation of the map would light the sphere from elsewhere
    model = brdf.parse(spec)
    preview = view_data.sphere_preview(model, 48, lights=view_data.sky_lights())
    traced = view_data.sphere_render(model, 48, spp=256, seed=1, lighting="sky", max_depth=2)
    hit = ~np.isnan(preview[..., 0])
    inner = hit.copy()
    for axis in (0, 1):
        for shift in (1, -1):
            inner &= np.roll(hit, shift, axis)
    np.testing.assert_allclose(traced[inner].mean(0) / preview[inner].mean(0), 1.0, atol=0.02)
    # 64 lights stand for a smooth map: a few per cent per pixel on a rough material
    assert np.median(abs(traced[inner] / preview[inner] - 1)) < 0.06
    mirror = view_data.sphere_preview(model, 48, lights=(-view_data.sky_lights()[0],
                                                         view_data.sky_lights()[1]))
    assert np.median(abs(traced[inner] / np.maximum(mirror[inner], 1e-9) - 1)) > 0.3


def _two_lamps(shape=(32, 64)):
    """A map unlike the sky: two warm and cool blobs on a dim grey, Mitsuba's envmap layout."""
    h, w = shape
    theta = np.pi * (np.arange(h) + 0.5) / h
    phi = 2 * np.pi * (np.arange(w) + 0.5) / w
    T, P = np.meshgrid(theta, phi, indexing="ij")
    d = np.stack([np.sin(T) * np.sin(P), np.cos(T), -np.sin(T) * np.cos(P)], -1)
    out = np.full(shape + (3,), 0.05)
    for towards, colour in (([0.7, 0.5, 0.5], (4.0, 2.5, 1.0)), ([-0.5, 0.2, 0.8], (0.5, 1.5, 3.0))):
        towards = np.array(towards) / np.linalg.norm(towards)
        out += np.array(colour) * np.exp(-8.0 * (1 - d @ towards))[..., None]
    return out


def _write_exr(path, image):
    from brdf.render.image import write_exr
    write_exr(path, image, force=True)
    return path


def test_environment_map_reads_an_exr_and_refuses_bad_ones(tmp_path):
    from brdf.errors import FormatError
    lamps = _two_lamps()
    # float32 in the file
    np.testing.assert_allclose(view_data.environment_map(_write_exr(tmp_path / "l.exr", lamps)),
                               lamps, rtol=1e-6)
    negative = lamps.copy()
    negative[3, 5, 1] = -0.5
    cases = {"square.exr": (np.ones((8, 8, 3)), "twice as wide as high, got 8 x 8 pixels"),
             "negative.exr": (negative, "row 3, column 5: environment map: radiance -0.5 is "
                                        "negative (expected >= 0)"),
             "nan.exr": (np.where(lamps > 1, np.nan, lamps), "NaN or infinite values"),
             "black.exr": (np.zeros((4, 8, 3)), "black everywhere")}
    for name, (image, expected) in cases.items():
        path = _write_exr(tmp_path / name, image)
        with pytest.raises(FormatError) as refused:
            view_data.environment_map(path)
        assert str(refused.value).startswith(str(path)) and expected in str(refused.value)
        assert "\n" not in str(refused.value)
    (tmp_path / "cut.exr").write_bytes((tmp_path / "l.exr").read_bytes()[:300])
    with pytest.raises(FormatError, match="not a readable OpenEXR file"):
        view_data.environment_map(tmp_path / "cut.exr")
    (tmp_path / "map.png").write_bytes(b"not an exr")
    with pytest.raises(FormatError, match="expected a lat-long OpenEXR file"):
        view_data.environment_map(tmp_path / "map.png")
    with pytest.raises(InputError, match="negative"):
        view_data.environment_map(negative)


def test_map_lights_of_a_large_map_keep_its_irradiance():
    # a 1024-wide map is cut on 2 x 2 blocks of pixels: its lights carry the map's irradiance
    # (the integral of radiance times solid angle, summed here over the pixel grid)
    lamps = _two_lamps((64, 128))
    big = np.kron(lamps, np.ones((8, 8, 1)))
    h, w = big.shape[:2]
    theta = np.pi * (np.arange(h) + 0.5) / h
    total = (big * (2 * np.pi ** 2 * np.sin(theta) / (h * w))[:, None, None]).sum((0, 1))
    directions, irradiance = view_data.map_lights(big, 32)
    np.testing.assert_allclose(irradiance.sum(0), total, rtol=1e-9)
    # regions of equal energy (Debevec 2005), to a block's worth
    energy = irradiance @ [0.2126, 0.7152, 0.0722]
    np.testing.assert_allclose(energy / energy.mean(), 1.0, atol=0.2)
    # the sky's lights are the map's lights of the sky
    np.testing.assert_array_equal(view_data.sky_lights(16)[1],
                                  view_data.map_lights(view_data.sky_map(), 16)[1])


def test_a_large_maps_cut_grid_holds_its_pixels_sums():
    # a map of 512 rows is cut on 2 x 2 blocks: each block's power, luminance, luminance-
    # weighted direction and solid angle are the sums over its pixels, computed here pixel by
    # pixel (Mitsuba 3's envmap layout; solid angle 2 pi^2 sin(theta) / (h w), PBR 3rd ed.
    # eq. 14.9); the explorer takes them by rows and columns
    rng = np.random.default_rng(3)
    big = np.kron(_two_lamps((64, 128)), np.ones((8, 8, 1)))
    big *= rng.uniform(0.5, 1.5, (512, 1024, 1))  # no two pixels of a block alike
    h, w = big.shape[:2]
    theta = np.pi * (np.arange(h) + 0.5) / h
    phi = 2 * np.pi * (np.arange(w) + 0.5) / w
    T, P = np.meshgrid(theta, phi, indexing="ij")
    d = np.stack([np.sin(T) * np.sin(P), np.cos(T), -np.sin(T) * np.cos(P)], -1)
    omega = 2 * np.pi ** 2 * np.sin(T) / (h * w)
    power = big * omega[..., None]
    energy = power @ [0.2126, 0.7152, 0.0722]
    blocks = lambda a: a.reshape(h // 2, 2, w // 2, 2, *a.shape[2:]).sum((1, 3))
    expected = (blocks(power), blocks(energy), blocks(d * energy[..., None]), blocks(omega))
    got = view_data._median_cut(big, 16)
    for want, have in zip(expected, got[:4]):
        np.testing.assert_allclose(have, want, rtol=1e-10, atol=1e-14 * abs(want).max())
    # 16 regions of equal energy (Debevec 2005), to a block's worth
    regions = got[4]
    shares = np.array([expected[1][r0:r1, c0:c1].sum() for r0, r1, c0, c1 in regions])
    np.testing.assert_allclose(shares / shares.mean(), 1.0, atol=0.1)
    # the strata of several counts from one sum of the map are each count's own
    both = view_data.map_strata_of_counts(big, (16, 32))
    for count in (16, 32):
        alone = view_data.map_strata(big, count)
        for a, b in zip(both[count].points, alone.points):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(both[count].cumulative, alone.cumulative)


def test_a_users_map_preview_agrees_with_the_path_tracer(tmp_path):
    model = brdf.parse("lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.3)")
    lamps = view_data.environment_map(_write_exr(tmp_path / "lamps.exr", _two_lamps()))
    preview = view_data.sphere_preview(model, 48, lights=view_data.map_lights(lamps, 64))
    traced = view_data.sphere_render(model, 48, spp=256, seed=1, lighting=lamps, max_depth=2)
    hit = ~np.isnan(preview[..., 0])
    np.testing.assert_allclose(traced[hit].mean(0) / preview[hit].mean(0), 1.0, atol=0.03)
    # the map turned round (its lamps elsewhere) does not match
    turned = view_data.sphere_preview(model, 48, lights=view_data.map_lights(
        np.roll(lamps, lamps.shape[1] // 2, axis=1), 64))
    assert np.median(abs(traced[hit] / np.maximum(turned[hit], 1e-9) - 1)) > 0.3


def _sky_previews_against_the_path_tracer(material):
    """The 64-pixel sphere preview of ``material`` under the sky map from the strata and from
    the median cut's 16 point lights, with the oracle they are judged by: the path tracer
    (its own importance sampling of map and material, 256 spp). Returns (strata, points,
    the median error per pixel of an image, the ratio of an image's mean to the oracle's)."""
    traced = view_data.sphere_render(material, 64, spp=256, seed=1, lighting="sky",
                                     max_depth=2)
    hit = ~np.isnan(traced[..., 0])
    strata = view_data.sphere_preview(material, 64, lights=view_data.sky_strata(16))
    points = view_data.sphere_preview(material, 64, lights=view_data.sky_lights(16))
    return (strata, points,
            lambda image: np.median(abs(image[hit] / np.maximum(traced[hit], 1e-9) - 1)),
            lambda image: image[hit].mean(0) / traced[hit].mean(0))


@pytest.mark.parametrize("spec", ["lambert(albedo=[0.2,0.2,0.2]) + ggx(alpha=0.05)",
                                  "lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.3)"])
def test_strata_show_a_glossy_highlight_under_the_map_as_the_path_tracer(spec):
    # the path tracer (its own importance sampling of map and material, 256 spp) is the
    # oracle: the median cut's 16 point lights put dots on a glossy sphere (off by tens of
    # per cent per pixel), its strata with the material's sampler do not
    model = brdf.parse(spec)
    strata, points, error, mean_ratio = _sky_previews_against_the_path_tracer(model)
    assert error(strata) < 0.08, error(strata)
    np.testing.assert_allclose(mean_ratio(strata), 1.0, atol=0.03)
    if "0.05" in spec:
        assert error(points) > 0.3
    # the same pixels draw the same directions at every call: the noise stands still
    np.testing.assert_array_equal(
        strata, view_data.sphere_preview(model, 64, lights=view_data.sky_strata(16)))


def _glossy_table():
    """A glossy MERL table, measured from a model by the library's virtual
    gonioreflectometer (the sharpest highlight the previews have to draw from a table)."""
    return brdf.measure(brdf.parse("lambert(albedo=[0.2,0.2,0.2]) + ggx(alpha=0.08)"), "merl")


def test_table_sampler_draws_as_its_density_says():
    # the mean of f cos / pdf over the draws is the table's own albedo (its cubature, an
    # independent integral) only if the draws follow the density reported
    table = _glossy_table()
    sampler = view_data.table_sampler(table)
    assert view_data.table_sampler(table) is sampler  # made once per table
    rng = np.random.default_rng(0)
    for theta in (10.0, 45.0, 70.0):
        wo = spherical_to_cartesian(math.radians(theta), 0.3)
        u = rng.random((200_000, 2))
        wi, pdf, weight = sampler.sample_weighted(np.broadcast_to(wo, (len(u), 3)), u)
        assert np.all(pdf > 0) and np.all(wi[:, 2] > 0)
        np.testing.assert_allclose(np.linalg.norm(wi, axis=1), 1.0, rtol=1e-12)
        np.testing.assert_allclose(sampler.pdf(np.broadcast_to(wo, wi.shape), wi), pdf,
                                   rtol=1e-12)
        np.testing.assert_allclose(weight.mean(0), table.albedo(wo[None])[0], rtol=0.01)
        # the density integrates to 1 over the hemisphere: the midpoint rule on a fine grid,
        # sin(theta) dtheta dphi per point
        t = (np.arange(720) + 0.5) * (math.pi / 2) / 720
        p = (np.arange(1440) + 0.5) * (2 * math.pi) / 1440
        T, P = np.meshgrid(t, p, indexing="ij")
        v = spherical_to_cartesian(T, P)
        total = (sampler.pdf(np.broadcast_to(wo, v.shape), v) * np.sin(T)).sum() \
            * (math.pi / 2 / 720) * (2 * math.pi / 1440)
        assert abs(total - 1.0) < 0.005, total


@pytest.mark.slow
def test_a_tables_highlight_under_the_map_as_the_path_tracer():
    # the path tracer (its own tabulated sampling of tables, 256 spp) is the oracle: the
    # median cut's 16 point lights put dots on a glossy table (off by 55 % per pixel), the
    # strata with the table's sampler do not (5 %)
    strata, points, error, mean_ratio = _sky_previews_against_the_path_tracer(_glossy_table())
    assert error(strata) < 0.08, error(strata)
    assert error(points) > 0.3, error(points)
    np.testing.assert_allclose(mean_ratio(strata), 1.0, atol=0.03)


def test_to_rgba_encodes_srgb_and_leaves_the_background_transparent():
    image = np.array([[[0.0], [1.0]], [[0.2], [np.nan]]])
    pixels = view_data.to_rgba(image).view(np.uint8).reshape(2, 2, 4)
    # row 0 of the output is the bottom row of the image (Bokeh's image origin)
    assert pixels[1, 0].tolist() == [0, 0, 0, 255] and pixels[1, 1].tolist() == [255] * 4
    # sRGB of 0.2 is 0.4845 (IEC 61966-2-1): 124 of 255
    assert pixels[0, 0, :3].tolist() == [124] * 3 and pixels[0, 1, 3] == 0


# -- the app, without a browser ---------------------------------------------------------------

pytest.importorskip("panel", reason="the explorer's extra: pip install 'brdf[explore]'")


def test_a_fit_in_the_background_adds_the_fitted_model_and_exports_it():
    from brdf.viz.explorer import Explorer
    table = ROOT / "measurements" / "rgl" / "paper_white_rgb.bsdf"
    app = Explorer([str(table)])
    shown, texts = [], []
    app.materials[0].fit_progress.param.watch(lambda e: shown.append(e.new), "value")
    app.materials[0].fit_status.param.watch(lambda e: texts.append(e.new), "object")
    app.start_fit(0, "lambert + beckmann").join(120)
    assert len(app.materials) == 2 and not app.error.visible
    # the percentage of the fit's planned runs, counting up to 100 before it ends
    assert shown == sorted(shown) and 0 <= shown[0] < 100 == shown[-1] and len(set(shown)) >= 2
    assert "fitting `lambert + beckmann`: 100% (" in texts[-2]
    # the same fit as the library's, run here on the same data and options
    expected = brdf.fit(brdf.read(table), "lambert + beckmann", seed=0, progress=False)
    assert app.materials[1].model == expected.model
    assert "fitted in" in app.materials[0].fit_status.object
    assert not app.materials[0].fit_progress.visible
    text = app._export_callback(app.materials[1], "mitsuba")().getvalue()
    assert text == brdf.export(expected.model, "mitsuba").text
    # a bad spec in the fit box: the library's line in the page, no new material
    app.start_fit(0, "ggx(alpha=-3)").join(60)
    assert len(app.materials) == 2 and "outside its bounds" in app.error.object
    # a model without an export: the message, an empty file
    app.add("mirror")
    assert app._export_callback(app.materials[2], "gltf")().getvalue() == ""
    assert "mirror" in app.error.object


def test_a_per_channel_parameter_splits_into_one_slider_per_channel():
    from brdf.viz.explorer import Explorer
    app = Explorer(["ggx(alpha=0.2)", "lambert(albedo=0.5) + ggx(alpha=0.2)"])
    sliders = {s.name: s for s in view_data.parameter_sliders(app.materials[1].model)}
    assert sliders["lambert.albedo"].splits and not sliders["ggx.alpha"].splits
    app.split_channels(1, "lambert.albedo")
    assert app.materials[1].model == brdf.parse("lambert(albedo=[0.5,0.5,0.5]) + ggx(alpha=0.2)")
    assert len(app.cards) == 2 and app.cards[1] is app.materials[1].card
    labels = [w.label for w in app.materials[1].widgets if hasattr(w, "label")]
    assert {"lambert.albedo[0]", "lambert.albedo[1]", "lambert.albedo[2]"} <= set(labels)
    # after the first material goes, the second's sliders still move the second
    app.remove(0)
    slider = next(w for w in app.materials[0].widgets
                  if getattr(w, "label", None) == "lambert.albedo[2]")
    slider.value = 0.25
    assert app.materials[0].model.params["lambert.albedo[2]"] == 0.25


def test_explorer_updates_its_sources_and_reports_bad_input():
    from brdf.viz.explorer import Explorer
    app = Explorer([SPEC])
    before = np.array(app.materials[0].polar_source.data["y"])
    app.set_parameter(0, "ggx.alpha", 0.5)
    after = np.array(app.materials[0].polar_source.data["y"])
    # a full update is followed by the path-traced sphere, a draft is not
    app.refine_thread.join(120)
    assert app.sphere.title.text == "lit sphere (path traced, 64 spp)"
    assert app.object_view.title.text == "lit object (path traced, 64 spp)"
    preview = app.sphere_source.data["image"]
    lit_object = app.object_source.data["image"][0]
    app.set_parameter(0, "ggx.alpha", 0.4, draft=True)
    assert app.sphere.title.text == "lit sphere (direct light)"
    assert app.object_view.title.text == "lit object (direct light)"
    assert app.sphere_source.data["image"] is not preview
    # the object's draft: the preview of the new model, at the draft's size
    from brdf.viz.explorer import DRAFT_ALBEDO_THETA, DRAFT_ALBEDO_TOL, DRAFT_SPHERE_SIZE
    np.testing.assert_array_equal(app.object_source.data["image"][0], view_data.to_rgba(
        view_data.object_preview(app.materials[0].model, DRAFT_SPHERE_SIZE,
                                 albedo=(DRAFT_ALBEDO_THETA, view_data.albedo_curve(
                                     app.materials[0].model, DRAFT_ALBEDO_THETA,
                                     tol=DRAFT_ALBEDO_TOL)))))
    assert lit_object.shape != app.object_source.data["image"][0].shape
    assert not np.allclose(before, after)
    assert set(app.timings) >= {"lobe", "polar", "albedo", "sphere", "total"}
    # a tap in the polar plot at 45 degrees from the normal sets theta_i, slider too
    app._drag_incidence(-0.5, 0.5, draft=False)
    assert app.theta_i == 45.0 and app.theta_slider.value == 45.0
    assert app.albedo_marker.location == 45.0
    app.theta_slider.value = 30.0  # back where RGL measured (no sample within 2.5 deg of 45)
    assert app.theta_i == 30.0
    assert app.add_from_text("ggx(alpha=-1)") is False
    assert app.error.visible and "alpha" in app.error.object and "bounds" in app.error.object
    assert app.add_from_text("/no/such/file.binary") is False
    assert "\n" not in app.error.object
    assert app.add_from_text("beckmann(alpha=0.3)") is True and len(app.materials) == 2
    assert not app.error.visible
    # a measured file: its in-plane samples drawn over the curves
    table = ROOT / "measurements" / "rgl" / "paper_white_rgb.bsdf"
    assert app.add_from_text(str(table)) is True and len(app.materials) == 3
    assert len(app.materials[2].samples_source.data["x"]) > 10
    assert "samples" in app.lobe.lobes[2] and "samples" not in app.lobe.lobes[0]
    app.remove(1)
    assert len(app.materials) == 2 and len(app.cards) == 2


def test_uploads_add_a_measured_file_or_a_fit_report_and_refuse_a_bad_file(tmp_path):
    from brdf.viz.explorer import Explorer
    app = Explorer(["ggx(alpha=0.2)"])
    app.refine = False
    table = ROOT / "measurements" / "rgl" / "paper_white_rgb.bsdf"
    data = table.read_bytes()
    # what the page's file input sends: the file's name and bytes
    app.upload_input.param.update(filename="paper_white_rgb.bsdf", value=data)
    assert len(app.materials) == 2 and not app.error.visible
    m = app.materials[1]
    assert m.label == "paper_white_rgb.bsdf" and m.card.title == "paper_white_rgb.bsdf"
    # the same samples as the library reads from the original file
    expected = brdf.read(table)
    np.testing.assert_array_equal(m.model.values, expected.values)
    assert len(m.samples_source.data["x"]) > 10
    # the same file again: a second material (the input forgot the first)
    app.upload_input.param.update(filename="paper_white_rgb.bsdf", value=data)
    assert len(app.materials) == 3 and app.materials[2].label == "paper_white_rgb.bsdf"
    app.remove(2)
    # a fit report: its model
    report = tmp_path / "fit.json"
    brdf.fit(brdf.measure("lambert(albedo=0.4)", "inplane:15"), "lambert", starts=1,
             progress=False).save(report)
    assert app.upload("fit.json", report.read_bytes()) is True
    assert app.materials[2].model == brdf.load_report(report).model
    # a truncated file and a file of no known format: the library's one line, naming the
    # file as uploaded (not the server's folder), nothing added, the page still answers
    for name, payload in (("paper_white_rgb.bsdf", data[:len(data) // 3]),
                          ("notes.txt", b"hello"), ("fit.json", b"{")):
        assert app.upload(name, payload) is False
        message = app.error.object
        assert message.startswith(name) and "\n" not in message and "brdf-explore-" not in message
        assert len(app.materials) == 3
    # the message is the library's own for that file, with the name as uploaded
    truncated = tmp_path / "x.bsdf"
    truncated.write_bytes(data[:len(data) // 3])
    with pytest.raises(brdf.errors.FormatError) as refused:
        brdf.read(truncated)
    assert app.upload("x.bsdf", truncated.read_bytes()) is False
    assert app.error.object == " ".join(str(refused.value).split()).replace(
        str(truncated), "x.bsdf")
    assert app.add_from_text("beckmann(alpha=0.3)") and not app.error.visible


def test_the_previews_switch_to_the_sky_map_and_back():
    from brdf.viz.explorer import DRAFT_SKY_LIGHTS, SKY_LIGHTS, SPHERE_SIZE, Explorer
    app = Explorer([SPEC])
    key = app.sphere_source.data["image"][0]
    app.refine_thread.join(120)
    app.lighting_select.value = "sky map"  # as the page's button does
    assert app.lighting == "sky"
    model = app.materials[0].model
    lights = view_data.sky_strata(SKY_LIGHTS)
    np.testing.assert_array_equal(app.sphere_source.data["image"][0], view_data.to_rgba(
        view_data.sphere_preview(model, SPHERE_SIZE, lights=lights)))
    np.testing.assert_array_equal(app.object_source.data["image"][0], view_data.to_rgba(
        view_data.object_preview(model, SPHERE_SIZE, lights=lights)))
    # refined by the path tracer under the same map: close to the preview on average
    app.refine_thread.join(120)
    assert app.object_view.title.text == "lit object (path traced, 64 spp)"
    traced = view_data.sphere_render(model, SPHERE_SIZE, 64, lighting="sky")
    np.testing.assert_array_equal(app.sphere_source.data["image"][0], view_data.to_rgba(traced))
    app.set_parameter(0, "ggx.alpha", 0.3, draft=True)
    np.testing.assert_array_equal(app.sphere_source.data["image"][0], view_data.to_rgba(
        view_data.sphere_preview(app.materials[0].model, 64,
                                 lights=view_data.sky_strata(DRAFT_SKY_LIGHTS))))
    app.set_lighting("key")
    assert app.lighting_select.value == "key light + environment"
    app.set_parameter(0, "ggx.alpha", 0.2)
    np.testing.assert_array_equal(app.sphere_source.data["image"][0], key)
    with pytest.raises(InputError, match="lighting 'sun'"):
        app.set_lighting("sun")


def test_the_explorer_lights_its_previews_with_a_users_map(tmp_path):
    from brdf.viz.explorer import DRAFT_SKY_LIGHTS, SKY_LIGHTS, SPHERE_SIZE, Explorer
    path = _write_exr(tmp_path / "lamps.exr", _two_lamps())
    app = Explorer([SPEC], environment=path)
    assert app.lighting == "map" and app.lighting_select.value == "map: lamps.exr"
    lamps = view_data.environment_map(path)
    model = app.materials[0].model
    np.testing.assert_array_equal(app.sphere_source.data["image"][0], view_data.to_rgba(
        view_data.sphere_preview(model, SPHERE_SIZE,
                                 lights=view_data.map_strata(lamps, SKY_LIGHTS))))
    app.refine_thread.join(120)
    assert app.sphere.title.text == "lit sphere (path traced, 64 spp)"
    np.testing.assert_array_equal(app.sphere_source.data["image"][0], view_data.to_rgba(
        view_data.sphere_render(model, SPHERE_SIZE, 64, lighting=lamps)))
    app.set_parameter(0, "ggx.alpha", 0.3, draft=True)
    np.testing.assert_array_equal(app.object_source.data["image"][0], view_data.to_rgba(
        view_data.object_preview(app.materials[0].model, 64,
                                 lights=view_data.map_strata(lamps, DRAFT_SKY_LIGHTS))))
    # a bad upload: the library's line (less the uploads' folder), the map stays
    negative = _two_lamps()
    negative[0, 0, 0] = -1.0
    bad = _write_exr(tmp_path / "bad.exr", negative)
    assert app.upload_environment("bad.exr", bad.read_bytes()) is False
    assert app.error.object == ("bad.exr:row 0, column 0: environment map: radiance -1 is "
                                "negative (expected >= 0)")
    assert app.lighting == "map" and app.environment_label == "lamps.exr"
    assert app.upload_environment("sky.exr", _write_exr(tmp_path / "s.exr", view_data.sky_map())
                                  .read_bytes()) and not app.error.visible
    assert app.lighting_select.options[-1] == "map: sky.exr"
    app.lighting_select.value = "key light + environment"
    assert app.lighting == "key"
    with pytest.raises(InputError, match="lighting 'sun'"):
        Explorer([SPEC]).set_lighting("sun")


def test_the_slice_colours_step_in_quarter_decades():
    from brdf.viz.explorer import SLICE_DECADES, Explorer
    app = Explorer(["ggx(alpha=0.2)"])
    app.refine = False
    peak = np.nanmax(view_data.slice_image(app.materials[0].model, 90.0, 90).mean(-1))
    high = app.slice_mapper.high
    # the top of the colours: the peak rounded up to the next quarter decade
    assert peak <= high < peak * 10 ** 0.25 and abs(4 * math.log10(high) - round(
        4 * math.log10(high))) < 1e-9
    assert app.slice_mapper.low == pytest.approx(high * 10 ** -SLICE_DECADES)
    # a move that keeps the peak within its step leaves the range (and the page's colour
    # bar) alone: over 40 moves, a change only where the step (computed here) changes
    changes = []
    app.slice_mapper.on_change("high", lambda attr, old, new: changes.append(new))
    steps, last = [], math.ceil(4 * math.log10(high) - 1e-9)
    for alpha in np.linspace(0.2, 0.3, 40)[1:]:
        app.set_parameter(0, "ggx.alpha", alpha)
        peak = np.nanmax(view_data.slice_image(app.materials[0].model, 90.0, 90).mean(-1))
        step = math.ceil(4 * math.log10(peak) - 1e-9)
        if step != last:
            steps.append(10 ** (step / 4))
        last = step
    np.testing.assert_allclose(changes, steps, rtol=1e-9)
    assert 0 < len(changes) <= 4


def test_the_slice_shows_the_material_chosen_in_its_list():
    from brdf.viz.explorer import FIRST_SHOWN, Explorer
    app = Explorer(["ggx(alpha=0.1)", SPEC])
    app.refine = False

    def shown_slice(model):
        expected = view_data.slice_image(model, app.phi_d, 90).mean(axis=-1)
        got = app.slice_source.data["image"][0]
        return np.allclose(np.where(expected > 0, expected, np.nan), got, equal_nan=True,
                           rtol=1e-12)

    assert list(app.slice_select.options) == [FIRST_SHOWN, "1: ggx", "2: lambert + ggx"]
    assert shown_slice(app.materials[0].model) and "material 1" in app.slice.title.text
    app.slice_select.value = "2: lambert + ggx"
    assert shown_slice(app.materials[1].model) and "material 2" in app.slice.title.text
    # it follows that material's sliders, and stays when it is hidden
    app.set_parameter(1, "ggx.alpha", 0.5)
    assert shown_slice(app.materials[1].model)
    app._visibility(app.materials[1], visible=False)
    assert shown_slice(app.materials[1].model)
    # a third material joins the list; removing the chosen one falls back to the first shown
    app.add("beckmann(alpha=0.3)")
    assert list(app.slice_select.options)[-1] == "3: beckmann"
    app.remove(1)
    assert app.slice_select.value == FIRST_SHOWN
    assert list(app.slice_select.options) == [FIRST_SHOWN, "1: ggx", "2: beckmann"]
    assert shown_slice(app.materials[0].model) and "material 1" in app.slice.title.text


def test_dragging_the_incident_arrow_sets_both_sliders_and_every_view():
    from brdf.viz.explorer import Explorer
    from brdf.viz.samples import incidence
    app = Explorer([SPEC])
    app.refine = False
    sphere = app.sphere_source.data["image"][0].copy()
    updates = app._refines
    # what the page sends while the arrow moves: a draft, one update for both angles
    app.lobe.drag = [60.2, 44.8, 0, 1]
    assert (app.theta_i, app.phi_i) == (60.0, 45.0) == (app.theta_slider.value,
                                                         app.phi_slider.value)
    assert app._refines == updates + 1
    np.testing.assert_allclose(app.lobe.incident, 1.2 * incidence(60.0, 45.0), atol=1e-12)
    assert app.albedo_marker.location == 60.0
    assert not np.array_equal(app.sphere_source.data["image"][0], sphere)
    # the in-plane curve is the one of the new incidence
    _, f = view_data.polar_curve(app.materials[0].model, incidence(60.0, 45.0), cosine=True)
    r = f.mean(axis=-1) / f.mean(axis=-1).max()
    got = app.materials[0].polar_source.data
    np.testing.assert_allclose(np.hypot(got["x"], got["y"]), r, rtol=1e-9)
    # let go: the full update; the same values sent again still update (a new serial)
    app.refine = True
    app.lobe.drag = [60.2, 44.8, 1, 2]
    assert app._refines == updates + 2 and app.refine_thread is not None
    app.refine_thread.join(120)
    # phi wraps, theta stops above the horizon
    app.lobe.drag = [95.0, 359.7, 1, 3]
    assert (app.theta_i, app.phi_i) == (89.0, 0.0)


def test_a_drafts_albedo_curve_stays_within_a_pixel_of_the_exact_one():
    from brdf.viz.explorer import DRAFT_ALBEDO_THETA, Explorer
    app = Explorer([SPEC])
    app.refine = False
    for alpha in (0.05, 0.2, 0.35):
        app.set_parameter(0, "ggx.alpha", alpha, draft=True)
        exact = view_data.albedo_curve(app.materials[0].model, DRAFT_ALBEDO_THETA, tol=1e-7)
        drawn = app.materials[0].albedo_source.data
        np.testing.assert_array_equal(drawn["theta"], DRAFT_ALBEDO_THETA)
        # the plot is 260 px high for an albedo range of about 1.1: 2e-3 is half a pixel
        np.testing.assert_allclose(drawn["a"], exact.mean(axis=-1), atol=2e-3)


def test_a_tables_previews_are_made_once_per_lighting(monkeypatch):
    # a table has no sliders: its previews (costly lookups: 80-110 ms for an RGL table's
    # draft under the sky) are kept while another material's slider moves
    from brdf.viz.explorer import DRAFT_SKY_LIGHTS, DRAFT_SPHERE_SIZE, Explorer
    table = ROOT / "measurements" / "rgl" / "paper_white_rgb.bsdf"
    app = Explorer([SPEC, str(table)])
    app.refine = False
    made, sphere_preview = [], view_data.sphere_preview
    for name in ("sphere_preview", "object_preview"):
        real = getattr(view_data, name)
        monkeypatch.setattr(view_data, name, lambda model, *a, real=real, name=name, **k: (
            made.append((name, model)), real(model, *a, **k))[1])
    app.set_lighting("sky")  # a full update: the previews at full size
    tables = lambda: [name for name, model in made if model is app.materials[1].model]
    assert tables() == ["sphere_preview", "object_preview"]
    app.set_parameter(0, "ggx.alpha", 0.3, draft=True)  # a draft: at the draft's size
    assert tables() == ["sphere_preview", "object_preview"] * 2
    for alpha in (0.25, 0.15):
        app.set_parameter(0, "ggx.alpha", alpha, draft=True)
    assert tables() == ["sphere_preview", "object_preview"] * 2  # kept
    assert len(made) == 4 + 2 * 4  # the model's at every update
    # the kept image is the table's preview under the sky's strata, its sampler's
    np.testing.assert_array_equal(app.sphere_source.data["image"][1], view_data.to_rgba(
        sphere_preview(app.materials[1].model, DRAFT_SPHERE_SIZE,
                       lights=view_data.sky_strata(DRAFT_SKY_LIGHTS))))
    # under the key light: kept from the first update (at phi_i 0); another phi_i (whose
    # albedo curve the environment's term takes) makes them again
    app.set_lighting("key")
    assert len(tables()) == 4
    app.phi_slider.value = 20.0
    assert tables()[4:] == ["sphere_preview", "object_preview"]


def test_sliders_and_the_lobe_hand_the_page_s_moves_over_at_once():
    # Panel holds a widget's change from the page for its _debounce (50 ms by default) before
    # Python sees it: half the latency budget of a slider's move (benchmarks/bench_explore.py)
    import panel as pn
    from brdf.viz.explorer import Explorer
    app = Explorer([SPEC, "beckmann(alpha=0.3)"])
    sliders = app.layout.select(pn.widgets.FloatSlider)
    names = {s.name for s in sliders}
    assert {"theta_i [deg]", "phi_i [deg]", "slice phi_d [deg]", "ggx.alpha",
            "beckmann.alpha", "lambert.albedo[2]"} <= names, names
    slow = [s.name for s in sliders if s._debounce != 0]
    assert not slow, slow
    assert app.lobe._debounce == 0


# -- in a headless browser --------------------------------------------------------------------

def _browser():
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    if chromium is None or driver is None:
        pytest.skip("no chromium or chromedriver: .ci/run installs Debian's chromium and "
                    "chromium-driver for this test")
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.service import Service
    options = webdriver.ChromeOptions()
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
                 "--enable-unsafe-swiftshader", "--window-size=1400,1000"):
        options.add_argument(flag)
    options.binary_location = chromium
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(driver), options=options)


#: JavaScript: the Bokeh document's model with this name, and elements found through every
#: shadow root (Panel draws each widget in its own).
_MODEL = "return [...Bokeh.documents[0]._all_models.values()].find(m => m.name === arguments[0])"
_DEEP = """
const selector = arguments[0], found = [];
(function walk(root) {
  root.querySelectorAll(selector).forEach(e => found.push(e));
  root.querySelectorAll('*').forEach(e => { if (e.shadowRoot) walk(e.shadowRoot); });
})(document);
return found;"""


def _wait(predicate, timeout=30.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError("timed out waiting for the page")


def _polar(driver):
    return driver.execute_script(
        "const d = window.Bokeh && Bokeh.documents[0]; if (!d) return null; "
        "const s = [...d._all_models.values()].find(m => m.name === "
        "'polar-0'); return s ? Array.from(s.data.y) : null")


def _sphere(driver):
    return driver.execute_script(
        "const s = [...Bokeh.documents[0]._all_models.values()].find(m => m.name === "
        "'spheres'); return s && s.data.image.length ? Array.from(s.data.image[0]) : null")


def _object(driver):
    return driver.execute_script(
        "const s = [...Bokeh.documents[0]._all_models.values()].find(m => m.name === "
        "'objects'); return s && s.data.image.length ? Array.from(s.data.image[0]) : null")


def _canvas(driver, canvas):
    return driver.execute_script("return arguments[0].toDataURL()", canvas)


def _lobe_target(lobe, theta, phi):
    """Canvas pixels where the 3-D lobe draws the incident arrow's tip for (theta, phi)
    degrees, and its depth (negative: in front): the view's turn (yaw about the normal, then pitch about the screen's x axis) and
    its projection, written out here from the view's description."""
    yaw, pitch, zoom = (float(v) for v in lobe.get_attribute("data-view").split(","))
    t, f = math.radians(theta), math.radians(phi)
    p = 1.2 * np.array([math.sin(t) * math.cos(f), math.sin(t) * math.sin(f), math.cos(t)])
    x = math.cos(yaw) * p[0] - math.sin(yaw) * p[1]
    y = math.sin(yaw) * p[0] + math.cos(yaw) * p[1]
    depth, up = math.cos(pitch) * y - math.sin(pitch) * p[2], math.sin(pitch) * y \
        + math.cos(pitch) * p[2]
    scale = 0.42 * 420 * zoom
    return 210 + scale * x, 0.62 * 420 - scale * up, depth


def _text(driver):
    return driver.execute_script("""
const parts = [];
(function walk(root) {
  root.querySelectorAll('*').forEach(e => {
    if (e.shadowRoot) walk(e.shadowRoot);
    if (!e.children.length && e.textContent) parts.push(e.textContent);
  });
})(document);
return parts.join(' ');""")


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_page_in_a_headless_browser(tmp_path):
    from brdf.viz.explorer import explore
    from selenium.webdriver import ActionChains, Keys
    driver = _browser()
    server = explore(SPEC, show=False)
    port = server.port
    try:
        driver.set_page_load_timeout(120)
        driver.get(f"http://localhost:{port}/")
        first = _wait(lambda: driver.execute_script("return window.Bokeh && "
                                                    "Bokeh.documents.length > 0") and
                      _polar(driver))
        sphere = _wait(lambda: _sphere(driver))
        lit_object = _wait(lambda: _object(driver))
        app, = server.explorers
        # the page's websocket sends each message at once (Nagle's algorithm off): a message
        # would otherwise wait up to 40 ms for the page's delayed ACK of the previous one
        import socket
        _wait(lambda: [c for c in app._doc.session_context.session._subscribed_connections
                       if c._socket.ws_connection.stream.socket.getsockopt(
                           socket.IPPROTO_TCP, socket.TCP_NODELAY)])
        lobe = _wait(lambda: driver.execute_script(_DEEP, "canvas.brdf-lobe"))[0]
        # the mesh's triangles, less those the cosine folds to a point at the horizon
        faces = int(_wait(lambda: lobe.get_attribute("data-faces")))
        assert 0.9 * len(app.lobe.triangles) / 3 <= faces <= len(app.lobe.triangles) / 3
        picture = _wait(lambda: _canvas(driver, lobe))
        # the lobe turns in the page when dragged
        ActionChains(driver).drag_and_drop_by_offset(lobe, 80, 20).perform()
        turned = _wait(lambda: (lambda p: p if p != picture else None)(_canvas(driver, lobe)))
        # every script comes from this server: nothing is downloaded at run time
        sources = driver.execute_script("return Array.from(document.scripts).map(s => s.src)"
                                        ".filter(s => s)")
        assert sources and all(s.startswith(f"http://localhost:{port}/") for s in sources), \
            sources
        # drag the ggx.alpha slider's handle: the polar curve and the sphere change
        handles = driver.execute_script(_DEEP, ".noUi-handle")
        labels = driver.execute_script(_DEEP, ".bk-slider-title")
        titles = [e.text for e in labels]
        index = next(k for k, t in enumerate(titles) if t.startswith("ggx.alpha"))
        ActionChains(driver).drag_and_drop_by_offset(handles[index], -60, 0).perform()
        second = _wait(lambda: (lambda y: y if y and not np.allclose(y, first) else None)(
            _polar(driver)))
        assert not np.allclose(second, first)
        _wait(lambda: _sphere(driver) != sphere)
        _wait(lambda: _object(driver) != lit_object)
        _wait(lambda: _canvas(driver, lobe) != turned)
        assert app.materials[0].model.params["ggx.alpha"] < 0.2
        # a wrong spec typed into the page: the library's one line, and the server lives on
        box = driver.execute_script(_DEEP, "input[type=text]")[0]
        box.send_keys("ggx(alpha=-0.1)", Keys.ENTER)
        message = _wait(lambda: "outside its bounds" in _text(driver) and _text(driver))
        assert "ggx: alpha=-0.1 is outside its bounds [0.0001, 4]" in message
        box.clear()
        box.send_keys("beckmann(alpha=0.3)", Keys.ENTER)
        _wait(lambda: driver.execute_script(_MODEL, "polar-1"))
        assert len(app.materials) == 2
        # the slice of the second material, chosen in the page's list
        from selenium.webdriver.support.select import Select
        choice = _wait(lambda: [e for e in driver.execute_script(_DEEP, "select")
                                if "2: beckmann" in e.text])[0]
        Select(choice).select_by_visible_text("2: beckmann")
        _wait(lambda: "material 2" in driver.execute_script(
            _MODEL.replace("return ", "const m = ") + "; return m.title.text", "slice"))
        assert app.slice_material() is app.materials[1]
        # a measured file typed in: its samples drawn in the page
        box.clear()
        box.send_keys(str(ROOT / "measurements" / "rgl" / "paper_white_rgb.bsdf"), Keys.ENTER)
        _wait(lambda: driver.execute_script(
            "const s = [...Bokeh.documents[0]._all_models.values()].find(m => m.name === "
            "'samples-2'); return s && s.data.x.length > 10"))
        _wait(lambda: int(lobe.get_attribute("data-samples") or 0) > 10)  # on the 3-D lobe
        # fit its card's spec (lambert + ggx) in the background: the fit joins the materials
        button = _wait(lambda: [b for b in driver.execute_script(_DEEP, "button")
                                if b.text.strip() == "fit"])[0]
        button.click()
        # the page's progress bar shows the fit's percentage (no value: indeterminate)
        percent = _wait(lambda: [float(e.get_dom_attribute("value"))
                                 for e in driver.execute_script(_DEEP, "progress")
                                 if e.get_dom_attribute("value") not in (None, "", "0")],
                        timeout=60)
        assert 0 < percent[0] <= 100
        _wait(lambda: "fitted in" in _text(driver), timeout=120)
        _wait(lambda: driver.execute_script(_MODEL, "polar-3"))
        assert len(app.materials) == 4 and app.materials[3].fit.converged
        assert str(app.materials[3].model).startswith("lambert(albedo=[")
        # upload files through the page's file input: a truncated one is refused with the
        # library's line naming it, then a good one joins with its samples
        table = ROOT / "measurements" / "rgl" / "paper_white_rgb.bsdf"
        bad = tmp_path / "cut.bsdf"
        bad.write_bytes(table.read_bytes()[:5000])
        upload = driver.execute_script(_DEEP, "input[type=file]")[0]
        upload.send_keys(str(bad))
        _wait(lambda: "cut.bsdf" in _text(driver) and app.error.visible)
        assert app.error.object.startswith("cut.bsdf") and len(app.materials) == 4
        upload.send_keys(str(table))
        _wait(lambda: driver.execute_script(
            "const s = [...Bokeh.documents[0]._all_models.values()].find(m => m.name === "
            "'samples-4'); return s && s.data.x.length > 10"))
        assert app.materials[4].label == "paper_white_rgb.bsdf" and not app.error.visible
        # dragging in the polar plot moves the incident direction (last: the
        # measured samples above were taken at theta_i = 30)
        plot = _wait(lambda: [c for c in driver.execute_script(_DEEP, "canvas")
                              if c.size["width"] > 300 and c.size["height"] > 200
                              and "brdf-lobe" not in (c.get_attribute("class") or "")])[0]
        driver.execute_script("arguments[0].scrollIntoView({block: 'center'})", plot)
        ActionChains(driver).move_to_element_with_offset(plot, -60, -40).click_and_hold() \
            .move_by_offset(-40, 0).release().perform()
        _wait(lambda: app.theta_i != 30.0)
        # drag the incident arrow's tip on the 3-D lobe to where the page draws the direction
        # theta 60 at the phi (of four) nearest the viewer, projected here from the page's
        # view angles independently of its own inverse: both sliders and the views follow
        driver.execute_script("arguments[0].scrollIntoView({block: 'center'})", lobe)
        phi = min((45.0, 135.0, 225.0, 315.0), key=lambda p: _lobe_target(lobe, 60.0, p)[2])
        target = _lobe_target(lobe, 60.0, phi)
        # the arrow drawn where the server's incidence projects (once the page has redrawn)
        tip = _wait(lambda: (lambda t: t if np.allclose(
            t, _lobe_target(lobe, app.theta_i, app.phi_i)[:2], atol=1.0) else None)(
            [float(v) for v in lobe.get_attribute("data-incident-tip").split(",")]))
        size = lobe.size
        ActionChains(driver).move_to_element_with_offset(
            lobe, tip[0] - size["width"] / 2, tip[1] - size["height"] / 2).click_and_hold() \
            .move_by_offset((target[0] - tip[0]) / 2, (target[1] - tip[1]) / 2) \
            .move_by_offset(target[0] - tip[0] - (target[0] - tip[0]) / 2,
                            target[1] - tip[1] - (target[1] - tip[1]) / 2).release().perform()
        _wait(lambda: abs(app.theta_i - 60.0) < 1.5 and abs(app.phi_i - phi) < 2.0)
        assert (app.theta_slider.value, app.phi_slider.value) == (app.theta_i, app.phi_i)
        # the previews under the sky map, chosen in the page
        before = _sphere(driver), _object(driver)
        sky = [b for b in driver.execute_script(_DEEP, "button") if b.text.strip() == "sky map"]
        driver.execute_script("arguments[0].scrollIntoView({block: 'center'})", sky[0])
        sky[0].click()
        _wait(lambda: app.lighting == "sky" and _sphere(driver) != before[0]
              and _object(driver) != before[1])
        # a map uploaded in the page: a bad one refused with its line, then a good one lights
        # the previews
        maps = [e for e in driver.execute_script(_DEEP, "input[type=file]")
                if e.get_attribute("accept") == ".exr"]
        negative = _two_lamps()
        negative[1, 2, 0] = -1.0
        maps[0].send_keys(str(_write_exr(tmp_path / "neg.exr", negative)))
        _wait(lambda: "is negative" in _text(driver) and app.error.visible)
        assert app.error.object.startswith("neg.exr:row 1, column 2") and app.lighting == "sky"
        before = _sphere(driver)
        maps[0].send_keys(str(_write_exr(tmp_path / "lamps.exr", _two_lamps())))
        _wait(lambda: app.lighting == "map" and _sphere(driver) != before
              and "map: lamps.exr" in _text(driver))
        assert not app.error.visible
        severe = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
        assert not severe, severe
    finally:
        driver.quit()
        server.stop()


# -- the command line -------------------------------------------------------------------------

def _brdf_fit(*args):
    """The installed ``brdf-fit`` (beside this Python), started with ``args``, with SIGINT at
    its default: a process inherits an ignored SIGINT, and Python then never turns it into
    KeyboardInterrupt. The suite's own processes have it ignored when the suite was started in
    the background of a script (a non-interactive shell ignores SIGINT in its ``&`` jobs), as
    in the CI runs where this test once hung."""
    import signal
    import subprocess
    import sys
    from pathlib import Path
    script = Path(sys.executable).with_name("brdf-fit")
    return subprocess.Popen([str(script), *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def test_cli_without_the_extra_says_how_to_install_it():
    import subprocess
    import sys
    # panel made unimportable, as in an install without brdf[explore]
    code = ("import sys; sys.modules['panel'] = None; from brdf_cli.main import main; "
            "sys.exit(main(['explore', 'ggx', '--no-browser']))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 2
    assert done.stderr == ('brdf-fit: error: the explorer needs Panel and Bokeh: '
                           'pip install "brdf[explore]"\n')


def test_cli_refuses_a_bad_spec_before_serving():
    done = _brdf_fit("explore", "ggx(alpha=-1)", "--no-browser")
    out, err = done.communicate(timeout=120)
    assert done.returncode == 2 and out == ""
    assert err.startswith("brdf-fit: error: ") and "bounds" in err and err.count("\n") == 1


def test_cli_refuses_a_bad_environment_map_before_serving(tmp_path):
    square = _write_exr(tmp_path / "square.exr", np.ones((8, 8, 3)))
    done = _brdf_fit("explore", "ggx", "--environment", str(square), "--no-browser")
    out, err = done.communicate(timeout=120)
    assert done.returncode == 2 and out == ""
    assert err == (f"brdf-fit: error: {square}: environment map: expected a lat-long map twice "
                   "as wide as high, got 8 x 8 pixels\n")


@pytest.mark.timeout(180)
def test_cli_serves_the_page_until_interrupted():
    import json
    import signal
    import urllib.request
    done = _brdf_fit("explore", SPEC, "--no-browser", "--json")
    try:
        line = done.stdout.readline()
        url = json.loads(line + "".join(iter(lambda: done.stdout.readline(), "}\n")) + "}")["url"]
        with urllib.request.urlopen(url, timeout=60) as page:
            assert page.status == 200 and b"brdf explorer" in page.read()
    finally:
        done.send_signal(signal.SIGINT)
        out, err = done.communicate(timeout=60)
    assert done.returncode == 0, err
