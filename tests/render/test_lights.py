"""Light sources of the path tracer against closed forms: IES files and goniometric lights, spot
and directional lights, environment maps (constant, importance-sampled)."""

import math
from pathlib import Path

import numpy as np
import pytest

import brdf
from brdf import render
from brdf.errors import FormatError
from brdf.render.ies import read_ies
from pixels import ground_local, hits_on_ground

IES = Path(__file__).parent.parent / "data" / "ies"
W = H = 16


def _z(a, b):
    return (a.image - b.image) / np.sqrt(a.variance + b.variance + 1e-30)


# --- IES files --------------------------------------------------------------------------------

def test_ies_one_plane_with_multiplier():
    """cosine.ies: I = 1000 cos(theta) cd at 1-degree steps, candela multiplier 0.5."""
    table, theta, phi = read_ies(IES / "cosine.ies")
    np.testing.assert_array_equal(theta, np.arange(91.0))
    np.testing.assert_array_equal(phi, [0.0, 360.0])
    np.testing.assert_allclose(table[:, 0], 500 * np.cos(np.radians(theta)), atol=5e-4)
    np.testing.assert_array_equal(table[:, 0], table[:, 1])


def test_ies_1995_commas_full_circle():
    table, theta, phi = read_ies(IES / "constant.ies")
    np.testing.assert_array_equal(theta, [0, 45, 90, 135, 180])
    np.testing.assert_array_equal(phi, [0, 90, 180, 270, 360])
    assert table.shape == (5, 5) and np.all(table == 100.0)


def test_ies_quadrant_symmetry_expands_to_four_quadrants():
    """quadrant.ies holds I(theta, phi) = 2 (100 + 10 k) (1 + cos phi) for phi in 0-90; the
    other quadrants mirror it: I(180 - phi) = I(180 + phi) = I(360 - phi) = I(phi)."""
    table, theta, phi = read_ies(IES / "quadrant.ies")
    np.testing.assert_allclose(phi, np.arange(0, 361, 30.0))
    given = 2 * (100 + 10 * np.arange(5))[:, None] * (1 + np.cos(np.radians([0, 30, 60, 90])))
    for j, p in enumerate([0, 30, 60, 90]):
        for image in (p, 180 - p, 180 + p, 360 - p):
            np.testing.assert_allclose(table[:, list(phi).index(image)], given[:, j], rtol=1e-5)


def test_ies_bilateral_symmetry_mirrors_the_0_180_plane():
    """bilateral.ies: I = 100 + theta + phi / 2 for phi in 0-180, values wrapped over lines."""
    table, theta, phi = read_ies(IES / "bilateral.ies")
    np.testing.assert_array_equal(phi, np.arange(0, 361, 45.0))
    folded = np.where(phi <= 180, phi, 360 - phi)
    np.testing.assert_allclose(table, 100 + theta[:, None] + folded[None, :] / 2)


def test_ies_90_270_symmetry(tmp_path):
    p = tmp_path / "side.ies"
    p.write_text("IESNA:LM-63-1995\nTILT=NONE\n1 -1 1 2 3 1 2 0 0 0\n1 1 0\n0 90\n90 180 270\n"
                 "10 11\n20 21\n30 31\n")
    table, _, phi = read_ies(p)
    np.testing.assert_array_equal(phi, [0, 90, 180, 270, 360])
    # the plane 90-270 is the mirror: I(180 - phi) = I(phi), so 0 and 360 see 180
    np.testing.assert_array_equal(table[0], [20, 10, 20, 30, 20])


HEADER = "IESNA:LM-63-2002\nTILT=NONE\n"


@pytest.mark.parametrize("text, line, fragment", [
    ("just some text\n", 1, "LM-63"),
    ("IESNA:LM-63-2002\nTILT=INCLUDE\n", 2, "TILT=NONE"),
    ("IESNA:LM-63-2002\n[TEST] x\n", 2, "TILT"),
    (HEADER + "1 -1 1 2 1 2 2 0 0 0\n1 1 0\n0 90\n0\n1 2\n", 3, "Type C"),
    (HEADER + "1 -1 1 2 1 1 2 0 0 0\n1 1 0\n0 90\n0\n1\n", 7, "ends early"),
    (HEADER + "1 -1 1 2 1 1 2 0 0 0\n1 1 0\n0 90\n0\n1 x\n", 7, "got 'x'"),
    (HEADER + "1 -1 1 2 1 1 2 0 0 0\n1 1 0\n90 0\n0\n1 2\n", 5, "increase"),
    (HEADER + "1 -1 1 2 1 1 2 0 0 0\n1 1 0\n0 200\n0\n1 2\n", 5, "[0, 180]"),
    (HEADER + "1 -1 1 2 2 1 2 0 0 0\n1 1 0\n0 90\n0 45\n1 2 3 4\n", 3, "0-90"),
    (HEADER + "1 -1 1 2 1 1 2 0 0 0\n1 1 0\n0 90\n0\n1 -2\n", 7, "negative"),
    (HEADER + "1 -1 0 2 1 1 2 0 0 0\n1 1 0\n0 90\n0\n1 2\n", 3, "multiplier"),
    (HEADER + "1 -1 1 2.5 1 1 2 0 0 0\n1 1 0\n0 90\n0\n1 2\n", 3, "whole number"),
    (HEADER + "1 -1 1 2 1 1 2 0 0 0\n1 1 0\n0 90\n0\n1 2\n7\n", 8, "unexpected"),
])
def test_ies_bad_files_name_file_and_line(tmp_path, text, line, fragment):
    p = tmp_path / "bad.ies"
    p.write_text(text)
    with pytest.raises(FormatError) as e:
        read_ies(p)
    message = str(e.value)
    assert "\n" not in message
    assert message.startswith(f"{p}:{line}: "), message
    assert fragment in message


# --- goniometric lights -----------------------------------------------------------------------

def _plane_render(light, spec="lambert(albedo=0.7) + ggx(alpha=0.3)"):
    scene = render.builtin("plane-point", spec)
    scene.lights = [light]
    return scene, render.render(scene, spp=2, size=(W, H), seed=0, jitter=False, max_depth=2)


def _plane_geometry(scene, light_position=(0.0, 1.0, 0.0)):
    """Per pixel: inside-plane mask, unit direction to the light, distance, and f(l, v)."""
    d, p = hits_on_ground(scene.camera, W, H)
    inside = (np.abs(p[..., 0]) < 1.99) & (np.abs(p[..., 2]) < 1.99)
    to_light = np.asarray(light_position, float) - p
    dist = np.linalg.norm(to_light, axis=-1)
    l = to_light / dist[..., None]
    f = brdf.parse(scene.shapes[0].material).eval(ground_local(l), ground_local(-d))
    return inside, l, dist, np.broadcast_to(f, (H, W, 3))


def test_constant_goniometric_light_is_a_point_light():
    """A goniometric light whose table is 100 cd everywhere, times 0.02, renders like a point
    light of intensity 2 (the same shadow rays; only the table lookup differs)."""
    gonio = render.GoniometricLight.from_ies(IES / "constant.ies", (0, 1, 0), intensity=0.02)
    _, a = _plane_render(gonio)
    _, b = _plane_render(render.PointLight((0, 1, 0), 2.0))
    assert a.image.max() > 0
    np.testing.assert_allclose(a.image, b.image, rtol=1e-12, atol=0)


def test_cosine_goniometric_light_matches_closed_form():
    """Light 1 above the plane pointing down with I(theta) = 500 cos(theta): L = f I(theta)
    cos(theta) / r^2, theta also the angle of incidence. The table is linear between its
    1-degree nodes: relative error (1 deg)^2 / 8 = 4e-5."""
    scene, r = _plane_render(render.GoniometricLight.from_ies(IES / "cosine.ies", (0, 1, 0)))
    inside, l, dist, f = _plane_geometry(scene)
    cos = l[..., 1]
    expected = f * (500 * cos * cos / dist ** 2)[..., None]
    np.testing.assert_allclose(r.image[inside], expected[inside], rtol=1e-4)


def test_goniometric_phi_turns_right_handed_about_the_axis():
    """A table I = 100 + 50 sin(phi): phi is measured about the axis (down) from phi_axis (+x)
    towards axis x phi_axis (+z), so the half of the plane at z > 0 is the brighter one. The
    kernel's grid is 2 degrees in phi: interpolation error 50 (2 deg)^2 / 8 = 0.008 cd."""
    theta = np.array([0.0, 180.0])
    phi = np.arange(0.0, 360.0, 1.0)
    table = np.broadcast_to(100 + 50 * np.sin(np.radians(phi)), (2, phi.size))
    light = render.GoniometricLight((0, 1, 0), table, theta, phi, intensity=0.01)
    scene, r = _plane_render(light, "lambert(albedo=0.8)")
    inside, l, dist, f = _plane_geometry(scene)
    d = -l  # from the light
    ph = np.arctan2(d[..., 2], d[..., 0])
    expected = f * (0.01 * (100 + 50 * np.sin(ph)) * l[..., 1] / dist ** 2)[..., None]
    np.testing.assert_allclose(r.image[inside], expected[inside], rtol=2e-4)


def test_ies_horizontal_angles_turn_counterclockwise_seen_from_above(tmp_path):
    """LM-63 Type C horizontal angles turn counterclockwise seen from above: with the nadir
    down and C0 along +x, C90 points along -z. A file bright at C90 (300 cd, else 100,
    linear between the planes) lights the plane's -z half: L = f I(C) cos / r^2 with C the
    angle from +x towards -z."""
    p = tmp_path / "c90.ies"
    p.write_text(HEADER + "1 -1 1 2 5 1 2 0 0 0\n1 1 0\n0 90\n0 90 180 270 360\n"
                 "100 100\n300 300\n100 100\n100 100\n100 100\n")
    light = render.GoniometricLight.from_ies(p, (0, 1, 0), intensity=0.01, phi_axis=(1, 0, 0))
    scene, r = _plane_render(light, "lambert(albedo=0.8)")
    inside, l, dist, f = _plane_geometry(scene)
    d = -l
    c = np.degrees(np.arctan2(-d[..., 2], d[..., 0])) % 360
    intensity = 0.01 * np.interp(c, [0, 90, 180, 270, 360], [100, 300, 100, 100, 100])
    # the light's own 90-degree cone ends at the horizon: every plane point is below it
    expected = f * (intensity * l[..., 1] / dist ** 2)[..., None]
    np.testing.assert_allclose(r.image[inside], expected[inside], rtol=1e-6)


# --- spot and directional lights --------------------------------------------------------------

@pytest.mark.parametrize("exponent", [0.0, 2.0, 7.0, 2.5])
def test_spot_light_falloff_and_cutoff(exponent):
    """Spot 1 above the plane, pointing down, cutoff 35 degrees: L = f I cos^n(angle) cos / r^2
    inside the cone (the angle to the axis is the angle of incidence), black outside."""
    cutoff = 35.0
    spot = render.SpotLight((0, 1, 0), (0, -1, 0), 3.0, cutoff=cutoff, exponent=exponent)
    scene, r = _plane_render(spot)
    inside, l, dist, f = _plane_geometry(scene)
    angle = np.degrees(np.arccos(l[..., 1]))
    lit = inside & (angle < cutoff - 0.5)
    dark = inside & (angle > cutoff + 0.5)
    assert lit.sum() > 20 and dark.sum() > 20
    expected = f * (3.0 * l[..., 1] ** exponent * l[..., 1] / dist ** 2)[..., None]
    np.testing.assert_allclose(r.image[lit], expected[lit], rtol=1e-6)
    assert np.all(r.image[dark] == 0.0)


def test_spot_falloff_by_squaring_is_pow_to_rounding():
    """Whole exponents up to 64 are raised to by squaring, within k ulp of pow for c^k (each
    squaring doubles the relative error before it); c^2 is c * c to the bit."""
    from brdf.render._lights import _cos_power
    c = np.random.default_rng(6).uniform(0.0, 1.0, 300)
    for k in range(65):
        got = np.array([_cos_power(x, float(k)) for x in c])
        np.testing.assert_allclose(got, c ** float(k), rtol=max(k, 1) * 2.3e-16, atol=0.0)
    assert all(_cos_power(x, 2.0) == x * x for x in c)
    assert _cos_power(0.3, 2.5) == 0.3 ** 2.5 and _cos_power(0.9, 65.0) == 0.9 ** 65.0


def test_directional_light():
    """L = f(l, v) E cos(theta) everywhere on the plane, l against the light's direction."""
    direction = np.array([0.4, -1.0, 0.3]) / np.linalg.norm([0.4, -1.0, 0.3])
    scene, r = _plane_render(render.DirectionalLight(direction, [1.5, 2.0, 2.5]))
    inside, _, _, _ = _plane_geometry(scene)
    d, _ = hits_on_ground(scene.camera, W, H)
    l = np.broadcast_to(-direction, d.shape)
    f = brdf.parse(scene.shapes[0].material).eval(ground_local(l), ground_local(-d))
    expected = f * np.array([1.5, 2.0, 2.5]) * l[..., 1:2]
    np.testing.assert_allclose(r.image[inside], expected[inside], rtol=1e-6)


# --- environment maps -------------------------------------------------------------------------

def _env_scene(environment, spec="lambert(albedo=0.8)"):
    return render.Scene(render.Camera(origin=(0, 0, 4), target=(0, 0, 0), fov=32),
                        [render.Sphere((0, 0, 0), 1.0, spec)], [], environment)


def _write_map(path, image):
    from brdf.render.image import write_exr
    write_exr(path, np.asarray(image, np.float32))
    return str(path)


def test_env_bilinear_against_numpy_with_wrapping_columns():
    """The map's bilinear lookup (Mitsuba 3's envmap: pixel centres at u = (j + 1/2) / w, rows
    at v = i / (h - 1)) against a numpy twin, over u in [0, 1] and at its ends, where the
    columns wrap."""
    from brdf.render._lights import _env_bilinear
    h, w = 6, 9
    env = np.random.default_rng(7).random((h, w, 3))
    u = np.concatenate([np.random.default_rng(8).random(500),
                        [0.0, 0.5 / w, 1.0 - 0.5 / w, np.nextafter(1.0, 0.0), 1.0]])
    v = np.random.default_rng(9).random(u.size)
    for a, b in zip(u, v):
        x = a * w - 0.5
        x0 = int(np.floor(x))
        y = b * (h - 1)
        i0 = min(int(y), h - 2)
        fx, fy = x - x0, y - i0
        ja, jb = x0 % w, (x0 + 1) % w
        want = ((1 - fx) * (1 - fy) * env[i0, ja] + fx * (1 - fy) * env[i0, jb]
                + (1 - fx) * fy * env[i0 + 1, ja] + fx * fy * env[i0 + 1, jb])
        np.testing.assert_allclose(_env_bilinear(env, a, b), want, rtol=1e-13, atol=1e-15)


def test_constant_map_renders_like_constant_environment(tmp_path):
    """A map of 0.25 everywhere scaled by 2 is the constant environment 0.5 (its importance
    sampling reduces to sin(theta), the uniform density over the sphere)."""
    m = _write_map(tmp_path / "flat.exr", np.full((8, 16, 3), 0.25))
    a = render.render(_env_scene(render.Environment(2.0, m)), spp=64, size=16, seed=1)
    b = render.render(_env_scene(render.Environment(0.5)), spp=64, size=16, seed=2)
    z = _z(a, b)
    assert np.mean(np.abs(z) < 4) > 0.98
    se = np.sqrt((a.variance + b.variance).sum()) / a.variance[..., 0].size
    assert abs(a.image.mean() - b.image.mean()) < 4 * se
    # background pixels see the map itself: exactly 0.5
    background = np.all(a.normal == 0, axis=-1)
    assert background.sum() > 50
    np.testing.assert_allclose(a.image[background], 0.5, rtol=1e-6)


def test_map_up_axis_orients_the_map(tmp_path):
    """Row 0 of the map is the direction of ``up``: a map bright in its top rows lights the
    top of the sphere with up = +y and the bottom with up = -y."""
    img = np.full((8, 16, 3), 0.05)
    img[:2] = 5.0
    m = _write_map(tmp_path / "sky.exr", img)
    for up, sign in (((0, 1, 0), 1), ((0, -1, 0), -1)):
        r = render.render(_env_scene(render.Environment(1.0, m, up=up)), spp=16, size=16, seed=3)
        ny = r.normal[..., 1]
        top = r.image[sign * ny > 0.5].mean()
        bottom = r.image[sign * ny < -0.5].mean()
        assert top > 5 * bottom, (up, top, bottom)


@pytest.mark.slow
def test_bright_region_light_and_bsdf_sampling_agree(tmp_path):
    """A map with one small bright patch: sampling the map, sampling the BSDF and MIS converge
    to the same image, and sampling the map has the (much) smaller variance. BSDF sampling
    rarely finds the patch, so its per-pixel estimates are skewed (mostly low, rarely very
    high) and their variance estimates unreliable: it is held to the image mean only."""
    img = np.full((32, 64, 3), 0.1)
    img[6:9, 40:44] = [40.0, 30.0, 20.0]
    m = _write_map(tmp_path / "sun.exr", img)
    scene = _env_scene(render.Environment(1.0, m), "lambert(albedo=0.7) + ggx(alpha=0.3)")
    runs = {s: render.render(scene, spp=256, size=16, seed=seed, strategy=s)
            for seed, s in enumerate(("light", "bsdf", "mis"))}
    on = np.all(runs["light"].normal != 0, axis=-1)
    for a, b in (("light", "bsdf"), ("mis", "bsdf"), ("mis", "light")):
        da = runs[a].image[on].mean() - runs[b].image[on].mean()
        se = np.sqrt((runs[a].variance[on] + runs[b].variance[on]).sum()) / runs[a].variance[
            on].size
        assert abs(da) < 4 * se, (a, b, da, se)
    assert np.mean(np.abs(_z(runs["mis"], runs["light"]))[on] < 4) > 0.95
    assert runs["light"].variance[on].mean() < 0.1 * runs["bsdf"].variance[on].mean()


def test_map_lookup_finds_libms_pixel(tmp_path):
    """The lookup's polynomial angles, settled against the pixels' edges, give the pixel of
    libm's atan2 and acos (Mitsuba's layout) wherever rounding cannot take either side, and
    sin(theta) to rounding."""
    from brdf.render import _lights as L
    rng = np.random.default_rng(5)
    img = rng.random((16, 32, 3)) * (rng.random((16, 32, 1)) < 0.7)
    img[3] = 0.0
    lights = _env_scene(render.Environment(1.0, _write_map(tmp_path / "m.exr", img))
                        ).compile().lights
    h, w = img.shape[:2]
    d = rng.normal(size=(4000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[:4] = [[0, 1, 0], [0, -1, 0], [1, 0, 0], [0, 0, -1]]     # poles and column edges
    u = (np.arctan2(d[:, 0], -d[:, 2]) / (2 * np.pi)) % 1.0
    v = np.arccos(d[:, 1]) / np.pi
    clear = (np.abs(u * w - np.round(u * w)) > 1e-9) & (np.abs(v * h - np.round(v * h)) > 1e-9)
    assert clear.sum() > 3900
    for k in range(len(d)):
        i, j, s, uu, vv = L._env_pixel(lights, *d[k])
        assert vv == pytest.approx(v[k], abs=1e-7)
        if s > 1e-6:                            # the azimuth is moot at the poles
            assert abs((uu - u[k] + 0.5) % 1.0 - 0.5) < 1e-7
        assert 0 <= i < h and 0 <= j < w
        assert s == pytest.approx(np.sin(v[k] * np.pi), abs=1e-12)
        if clear[k]:
            assert (i, j) == (min(int(v[k] * h), h - 1), min(int(u[k] * w), w - 1)), k


def test_map_lookup_settles_directions_at_pixel_edges(tmp_path):
    """Directions on the edges of a 512 x 1024 map's pixels and within a few rounding steps of
    them, where the polynomial angles may land in the next row or column: the lookup settles
    each into the pixel whose edges hold it by the tables it reads (row i: cos(pi (i + 1) / h) <
    y <= cos(pi i / h); column j: x cos a + z sin a >= 0 at its edge a_j, < 0 at a_j+1, to
    rounding)."""
    from brdf.render import _lights as L
    h, w = 512, 1024
    lights = _env_scene(render.Environment(1.0, _write_map(tmp_path / "m.exr", np.ones((h, w, 3))))
                        ).compile().lights
    ct, edge = lights.env_cos, lights.env_edge
    rng = np.random.default_rng(11)
    nudges = (-3e-9, -1e-15, 0.0, 1e-15, 3e-9)
    rows, cols = rng.integers(1, h, 40), rng.integers(0, w, 40)
    theta = np.concatenate([np.pi * rows / h + e for e in nudges]
                           + [rng.uniform(0.1, np.pi - 0.1, 40 * len(nudges))])
    phi = np.concatenate([rng.uniform(0.0, 2 * np.pi, 40 * len(nudges))]
                         + [2 * np.pi * cols / w + e for e in nudges])
    x, y, z = np.sin(theta) * np.sin(phi), np.cos(theta), -np.sin(theta) * np.cos(phi)
    moved = 0
    for k in range(len(theta)):
        i, j, s, _, _ = L._env_pixel(lights, x[k], y[k], z[k])
        assert 0 <= i < h and 0 <= j < w
        assert (i == h - 1 or ct[i + 1] < y[k]) and (i == 0 or y[k] <= ct[i]), k
        # the cross products to rounding: the kernel's are fused multiply-adds
        assert edge[j, 0] * x[k] + edge[j, 1] * z[k] >= -1e-15, k
        assert edge[j + 1, 0] * x[k] + edge[j + 1, 1] * z[k] < 1e-15, k
        guess_i = min(int(theta[k] / np.pi * h), h - 1)
        moved += i != guess_i
    assert moved > 0  # some directions needed the step past the first guess


def _sampled_map(tmp_path):
    from brdf.render import _lights as L
    rng = np.random.default_rng(5)
    img = rng.random((16, 32, 3)) * (rng.random((16, 32, 1)) < 0.7)
    img[3] = 0.0                                # a row of zeros, and zero pixels elsewhere
    return L, img, _env_scene(render.Environment(1.0, _write_map(tmp_path / "m.exr", img))
                              ).compile().lights


def test_the_alias_table_gives_each_pixel_its_probability(tmp_path):
    """Walker's table of the map's pixels (Vose's construction): a pixel's probability, 1/n
    times its own bin's prob plus 1 - prob of each bin aliased to it, is env_pmf's to
    rounding; a pixel of probability 0 is never kept, nor aliased to."""
    L, img, lights = _sampled_map(tmp_path)
    pmf, prob, alias = lights.env_pmf.ravel(), lights.env_prob, lights.env_alias
    n = len(pmf)
    assert prob.shape == alias.shape == (n,) and np.all((prob >= 0) & (prob <= 1))
    got = prob.copy()
    np.add.at(got, alias, 1.0 - prob)
    np.testing.assert_allclose(got / n, pmf, rtol=1e-12, atol=1e-15)
    assert np.all(prob[pmf == 0] == 0) and np.all(pmf[alias[prob < 1]] > 0)
    assert pmf.sum() == pytest.approx(1.0, abs=1e-12)
    # zero weights among others, not normalised: kept never, aliased to never
    prob, alias = L.alias_table(np.array([0.0, 0.0, 3.0, 1.0, 0.0, 6.0]))
    np.testing.assert_array_equal(prob[[0, 1, 4]], 0.0)
    assert set(alias[prob < 1]) <= {2, 3, 5}
    got = prob.copy()
    np.add.at(got, alias, 1.0 - prob)
    np.testing.assert_allclose(got / 6, [0.0, 0.0, 0.3, 0.1, 0.0, 0.6], rtol=1e-15, atol=0)


@pytest.mark.slow
def test_the_map_sampler_draws_its_pixels_and_densities(tmp_path):
    """Pixels drawn with u1 follow env_pmf (Pearson's chi-square, cells pooled below 5
    expected), the rest of u1 is uniform in [0, 1), and the density each sample reports is
    env_lookup's at the direction drawn (what MIS weighs it with), away from pixel edges."""
    from scipy import stats
    L, img, lights = _sampled_map(tmp_path)
    pmf = lights.env_pmf.ravel()
    rng = np.random.default_rng(7)
    n = 100_000
    picks, rests = np.empty(n, np.int64), np.empty(n)
    for k, u in enumerate(rng.random(n)):
        picks[k], rests[k] = L._alias_pick(lights.env_prob, lights.env_alias, u)
    observed = np.bincount(picks, minlength=len(pmf))
    expected = n * pmf
    assert observed[pmf == 0].sum() == 0
    small = (expected < 5) & (pmf > 0)
    obs = np.append(observed[expected >= 5], observed[small].sum())
    exp = np.append(expected[expected >= 5], expected[small].sum())
    obs, exp = obs[exp > 0], exp[exp > 0]
    chi2 = ((obs - exp) ** 2 / exp).sum()
    assert stats.chi2.sf(chi2, len(obs) - 1) > 1e-3, chi2
    assert 0.0 <= rests.min() and rests.max() < 1.0
    assert stats.kstest(rests, "uniform").pvalue > 1e-3
    e = lights.env_light
    agree = 0
    u = rng.random((2000, 2))
    for u1, u2 in u:
        dx, dy, dz, r, g, b, pdf = L._sample_env(lights, e, u1, u2)
        _, _, _, looked = L.env_lookup(lights, e, dx, dy, dz)
        agree += pdf == pytest.approx(looked, rel=1e-9)
    assert agree >= 0.995 * len(u), agree


def test_map_mean_matches_mitsuba(tmp_path):
    """A Lambertian sphere and the background in a coarse, high-contrast map (8 x 16 random
    pixels, where looking up the nearest pixel instead of interpolating bilinearly moves the
    mean by percents): our mean image is Mitsuba 3's (``envmap``, llvm_ad_rgb, 1024 spp) to
    0.2 % plus three of our standard errors, per channel."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("llvm_ad_rgb")
    img = np.random.default_rng(9).random((8, 16, 3)) ** 3 * 4.0 + 0.05
    size = 32
    ours = render.render(_env_scene(render.Environment(1.0, _write_map(tmp_path / "m.exr", img)),
                                    "lambert(albedo=0.8)"), spp=256, size=size, seed=4)
    theirs = mi.render(mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 8},
        "sensor": {"type": "perspective", "fov": 32.0, "fov_axis": "x",
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0],
                                                              up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": size, "height": size,
                            "rfilter": {"type": "box"}}},
        "sphere": {"type": "sphere", "center": [0, 0, 0], "radius": 1.0,
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.8}}},
        "env": {"type": "envmap", "bitmap": mi.Bitmap(img.astype(np.float32))}}), spp=1024, seed=4)
    a = ours.image.mean(axis=(0, 1))
    b = np.asarray(theirs, float)[..., :3].mean(axis=(0, 1))
    se = np.sqrt(ours.variance.sum(axis=(0, 1))) / (size * size)
    assert np.all(np.abs(a - b) < 0.002 * b + 3 * se), (a, b, se)
