"""The path tracer against closed-form answers, against itself (estimators, threads, seeds)
and against the library's own models (measured tables, albedo)."""

import math

import numpy as np
import pytest

import brdf
from brdf import render
from brdf.errors import InputError
from pixels import pixel_directions as _pixel_directions


def _z(a, b):
    """Per-pixel z-scores of the difference of two independent renders."""
    return (a.image - b.image) / np.sqrt(a.variance + b.variance + 1e-30)


def test_white_furnace_lambert_is_one():
    """A Lambertian sphere of albedo 1 in a uniform environment of radiance 1 is invisible:
    every pixel's expected value is 1."""
    r = render.render(render.builtin("furnace", "lambert(albedo=1)"), spp=64, size=24, seed=3)
    se = np.sqrt(r.variance)
    z = (r.image - 1.0) / np.maximum(se, 1e-12)
    assert np.mean(np.abs(z) < 3.0) > 0.98, np.abs(z).max()
    # the whole image: 576 pixels x 64 paths
    total_se = np.sqrt(r.variance.sum()) / r.variance[..., 0].size
    assert abs(r.image.mean() - 1.0) < 3 * total_se + 1e-12


def test_white_furnace_gives_directional_albedo():
    """Pixels on the sphere equal the model's directional albedo towards the camera."""
    model = brdf.parse("ggx(alpha=0.3)")
    scene = render.builtin("furnace", model)
    w = h = 20
    r = render.render(scene, spp=256, size=(w, h), seed=5, jitter=False)
    d = _pixel_directions(scene.camera, w, h)
    n = r.normal
    on = np.linalg.norm(n, axis=-1) > 0.5
    cos = np.clip(np.sum(-d * n, axis=-1), 0, 1)[on]
    wi = np.stack([np.sqrt(1 - cos ** 2), np.zeros_like(cos), cos], axis=-1)
    expected = model.albedo(wi)[:, 0]
    z = (r.image[on][:, 0] - expected) / np.sqrt(r.variance[on][:, 0] + 1e-30)
    assert on.sum() > 100
    assert np.mean(np.abs(z) < 3.0) > 0.97
    assert abs(np.mean(z)) < 4.0 / math.sqrt(on.sum())
    # GGX with F = 1 loses energy: a visible share of pixels is well below 1
    assert np.mean(expected) < 0.95


def test_materials_with_one_layout_shade_in_one_batch():
    """Materials whose lobes and parameter layout agree share a shading batch (each path
    carries its own parameters); others, and measured tables, keep their own."""
    from brdf.render import _materials as M
    specs = ["lambert(albedo=0.2)", "lambert(albedo=[0.8, 0.5, 0.1])",
             "lambert + ggx(alpha=0.2)", "lambert(albedo=0.3) + ggx(alpha=0.5, ks=0.2)",
             "ggx + lambert", "lambert + beckmann(alpha=0.2)"]
    shapes = [render.Sphere((3.0 * i, 0, 0), 1, s) for i, s in enumerate(specs)]
    mint = render.Scene(shapes=shapes).compile().mats[0]
    assert list(mint[:, M.SHARE]) == [0, 0, 2, 2, 4, 5]


def test_shared_batch_keeps_each_paths_parameters():
    """Two coplanar Lambertian squares (one batch) under a uniform sky of radiance 1: each
    shows its own albedo: they cannot see each other, and a cosine-sampled bounce to the sky
    carries rho exactly, so every path gives L = rho."""
    albedo = (0.2, 0.8)
    shapes = [render.Quad((x, -1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 2.0, 0.0),
                          f"lambert(albedo={a})") for x, a in zip((-1.0, 0.0), albedo)]
    scene = render.Scene(render.Camera(origin=(0, 0, 3), target=(0, 0, 0), fov=30), shapes,
                         environment=render.Environment(1.0))
    r = render.render(scene, spp=16, size=16, seed=2, strategy="bsdf")
    for half, a in zip((r.image[:, :8], r.image[:, 8:]), albedo):
        np.testing.assert_allclose(half, a, rtol=1e-12)


def test_closed_sphere_radiance():
    """Inside a closed sphere with Lambertian albedo rho emitting Le inwards, radiance is
    Le / (1 - rho) everywhere (the sum of the geometric series of bounces)."""
    rho, le = 0.5, 1.0
    scene = render.Scene(render.Camera(origin=(0, 0, 0), target=(0, 0, -1), fov=90),
                         [render.Sphere((0, 0, 0), 1.0, f"lambert(albedo={rho})", emission=le,
                                        sides="back")])
    r = render.render(scene, spp=128, size=16, seed=1, max_depth=-1, rr_depth=3)
    expected = le / (1 - rho)
    mean_se = np.sqrt(r.variance.sum()) / r.variance[..., 0].size
    assert abs(r.image.mean() - expected) < 3 * mean_se + 1e-12
    # per pixel the estimate is a skewed sum of whole bounces, and its sample variance on 128
    # paths is rough: over seeds 1-20, 97.3 % to 100 % of the pixels (98.9 % on average) lie
    # within 4 standard errors, for this tracer as for the one-path-at-a-time one before it
    assert np.mean(np.abs(r.image - expected) < 4 * np.sqrt(r.variance) + 1e-12) > 0.96


@pytest.mark.parametrize("spec, attenuation", [
    ("lambert(albedo=0.7)", (1.0, 0.0, 0.0)),
    ("lambert(albedo=0.7) + ggx(alpha=0.3, fresnel=schlick(f0=0.04))", (0.5, 0.3, 0.2)),
])
def test_plane_under_point_light(spec, attenuation):
    """L = f(wi, wo) I cos(theta_i) / (a r^2 + b r + c) at pixel centres (one light path, no
    noise for a light the BSDF can never hit)."""
    model = brdf.parse(spec)
    intensity = 2.0
    scene = render.builtin("plane-point", model)
    scene.lights[0].intensity = intensity
    scene.lights[0].attenuation = attenuation
    w = h = 16
    r = render.render(scene, spp=4, size=(w, h), seed=0, jitter=False, max_depth=2)
    d = _pixel_directions(scene.camera, w, h)
    o = np.array(scene.camera.origin, float)
    t = -o[1] / d[..., 1]
    p = o + t[..., None] * d
    inside = (np.abs(p[..., 0]) < 1.99) & (np.abs(p[..., 2]) < 1.99)
    to_light = np.array([0, 1.0, 0]) - p
    dist = np.linalg.norm(to_light, axis=-1)
    l = to_light / dist[..., None]
    # the plane's local frame: normal +y, tangent +x (edge1), bitangent n x t = -z
    local = lambda v: np.stack([v[..., 0], -v[..., 2], v[..., 1]], axis=-1)  # noqa: E731
    f = model.eval(local(l), local(-d))
    a, b, c = attenuation
    expected = f * intensity * l[..., 1:2] / (a * dist ** 2 + b * dist + c)[..., None]
    expected = np.broadcast_to(expected, r.image.shape)
    # the shadow ray starts 1e-7 (relative) off the surface, which moves r by as much
    np.testing.assert_allclose(r.image[inside], expected[inside], rtol=1e-6, atol=1e-12)


def _glossy_scene(spec):
    """A sphere under a quad area light and a constant environment."""
    return render.Scene(
        render.Camera(origin=(0, 0, 4), target=(0, 0, 0), fov=35),
        [render.Sphere((0, 0, 0), 1.0, spec),
         render.Quad((-0.5, 2.0, -0.5), (1.0, 0, 0), (0, 0, 1.0), None, emission=4.0)],
        [], render.Environment(0.3))


@pytest.mark.slow
@pytest.mark.parametrize("spec", ["lambert(albedo=0.6) + ggx(alpha=0.2)",
                                  "modified-phong(ks=0.5, n=10) + lambert(albedo=0.3)"])
def test_estimators_agree(spec):
    """BSDF sampling only, light sampling only and MIS converge to the same image. Light
    sampling alone has heavy tails on glossy lobes (a rare path through the lobe's peak carries
    a large weight), so its per-pixel variance estimates are loose at this spp: a few pixels
    beyond 4 sigma are allowed, the image mean is held to 4 standard errors."""
    scene = _glossy_scene(spec)
    runs = {s: render.render(scene, spp=128, size=20, seed=7, strategy=s)
            for s in ("mis", "bsdf", "light")}
    for a, b in (("mis", "bsdf"), ("mis", "light"), ("bsdf", "light")):
        z = _z(runs[a], runs[b])
        assert np.mean(np.abs(z) < 4.0) > 0.97, (a, b, np.abs(z).max())
        da = runs[a].image.mean() - runs[b].image.mean()
        se = np.sqrt((runs[a].variance + runs[b].variance).sum()) / runs[a].variance[..., 0].size
        assert abs(da) < 4 * se, (a, b, da, se)


def test_measured_table_renders_like_its_model():
    """A MERL-grid table made from a model by the virtual gonioreflectometer renders like the
    model, within noise and the grid's interpolation error."""
    model = brdf.parse("lambert(albedo=[0.6,0.5,0.4]) + ggx(alpha=0.35)")
    table = brdf.measure(model, "merl")
    a = render.render(render.builtin("sphere", model), spp=64, size=20, seed=2)
    b = render.render(render.builtin("sphere", table), spp=64, size=20, seed=4)
    diff = a.image.mean(axis=(0, 1)) - b.image.mean(axis=(0, 1))
    assert np.all(np.abs(diff) < 0.02 * a.image.mean(axis=(0, 1)) + 1e-3), diff
    assert np.mean(np.abs(_z(a, b)) < 4.0) > 0.97


@pytest.mark.slow
@pytest.mark.parametrize("theta, phi", [(0.6, 0.0), (0.6, 2.0), (0.0, 0.0)])
def test_measured_sampling_matches_its_pdf(theta, phi):
    """The tabulated sampler of measured tables follows the density it reports (chi-square),
    for a view direction in the x-z plane, one out of it and one at the pole (where the
    density measures azimuths from the x axis, as the sampler does)."""
    from chi2 import histogram, integrate_cells, pearson
    from scipy import stats
    from brdf.render import _materials as M
    table = brdf.measure(brdf.parse("lambert(albedo=[0.2,0.2,0.2]) + ggx(alpha=0.15)"), "merl")
    mats = render.Scene(shapes=[render.Sphere((0, 0, 0), 1, table)]).compile().mats
    v = np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi),
                  math.cos(theta)])

    def sample(u):
        n = len(u)
        l, pdf, w = np.empty((n, 3)), np.empty(n), np.empty((n, 3))
        M.sample_array(mats, 0, np.broadcast_to(v, (n, 3)).copy(), u, l, pdf, w)
        return l, pdf

    def pdf(l):
        out = np.empty(len(l))
        M.pdf_array(mats, 0, np.broadcast_to(v, l.shape).copy(), np.ascontiguousarray(l), out)
        return out

    # the tabulated density is piecewise constant: rectangles across its jumps never meet a
    # tolerance, so the refinement stops at 7 levels (a cell's 1/128th). The expected counts
    # are then within 0.043 % of 10 levels' (the harness's default, 3-5x the time), which
    # moves the statistic by at most 0.01 against its standard deviation of 60 (measured at
    # (0.6, 0) and the pole, 2026-12-07)
    shape = (30, 60)
    u = np.random.default_rng(1).random((300_000, 2))
    l, p = sample(u)
    assert np.all(p > 0) and np.all(l[:, 2] > 0)
    cells, _ = integrate_cells(pdf, shape, atol=1e-6, rtol=1e-3, max_level=7)
    assert abs(cells.sum() - 1.0) < 2e-3
    stat, dof = pearson(histogram(l, shape).ravel(), len(u) * cells.ravel() / cells.sum())
    assert stats.chi2.sf(stat, dof) > 0.01, (stat, dof)


@pytest.mark.parametrize("theta, phi", [(0.6, 2.0), (0.0, 0.0), (1.5, -1.0)])
def test_measured_sample_reports_the_density_of_its_direction(theta, phi):
    """The tabulated sampler reports its cell's density without finding the cell again; it is
    the density the table gives at the sampled direction (a direction within rounding of a
    cell's edge may fall either side)."""
    from brdf.render import _materials as M
    table = brdf.measure(brdf.parse("lambert(albedo=[0.3,0.3,0.3]) + ggx(alpha=0.2)"), "merl")
    mats = render.Scene(shapes=[render.Sphere((0, 0, 0), 1, table)]).compile().mats
    v = np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi),
                  math.cos(theta)])
    n = 100_000
    u = np.random.default_rng(3).random((n, 2))
    vs = np.broadcast_to(v, (n, 3)).copy()
    l, pdf, w = np.empty((n, 3)), np.empty(n), np.empty((n, 3))
    M.sample_array(mats, 0, vs, u, l, pdf, w)
    again = np.empty(n)
    M.pdf_array(mats, 0, vs, l, again)
    tabulated = u[:, 0] >= M.DEFENSIVE
    assert tabulated.sum() > 0.7 * n and np.all(pdf > 0.0)
    same = np.isclose(pdf, again, rtol=1e-12, atol=0.0)
    assert np.mean(same) > 0.9999, np.mean(same)


def test_a_measured_scene_compiles_without_copying_or_tabulating_its_table_again():
    """A scene is compiled at every render: its one MERL table's grids are views, and the
    table's sampling CDFs are computed once while the table lives."""
    from brdf.render import _materials as M
    table = brdf.measure(brdf.parse("lambert(albedo=[0.3,0.3,0.3]) + ggx(alpha=0.2)"), "merl")
    scene = render.Scene(shapes=[render.Sphere((0, 0, 0), 1, table)])
    first, again = scene.compile().mats, scene.compile().mats
    assert np.shares_memory(first.grids, table.grid) and np.shares_memory(first.filled,
                                                                            table.filled)
    assert again.tables.base is first.tables.base is M.tabulated(table)
    np.testing.assert_array_equal(M.tabulated(table), M.tabulate(table))
    other = brdf.measure(brdf.parse("lambert(albedo=[0.6,0.3,0.3])"), "merl")
    two = render.Scene(shapes=[render.Sphere((0, 0, 0), 1, table),
                               render.Sphere((3, 0, 0), 1, other)]).compile().mats
    np.testing.assert_array_equal(two.grids[1], other.grid)
    assert not np.shares_memory(two.grids, table.grid)


def test_same_seed_same_bytes_any_thread_count():
    scene = _glossy_scene("lambert(albedo=0.5) + ggx(alpha=0.3)")
    one = render.render(scene, spp=8, size=16, seed=11, threads=1)
    two = render.render(scene, spp=8, size=16, seed=11, threads=2)
    other = render.render(scene, spp=8, size=16, seed=12, threads=2)
    assert one.image.tobytes() == two.image.tobytes()
    assert one.variance.tobytes() == two.variance.tobytes()
    assert one.image.tobytes() != other.image.tobytes()


def test_cornell_matches_mitsuba_mean():
    """Mean of our Cornell box against Mitsuba 3's at 256 x 256, 64 spp (llvm_ad_rgb, three
    seeds: 0.2401, 0.1411, 0.0600): the same scene, within 1 % plus this render's noise (the
    image mean is an integral over the image plane, whatever the resolution)."""
    r = render.render(render.builtin("cornell"), spp=32, size=64, seed=1)
    mitsuba = np.array([0.24015, 0.14114, 0.05999])
    se = np.sqrt(r.variance.sum(axis=(0, 1))) / (64 * 64)
    assert np.all(np.abs(r.image.mean(axis=(0, 1)) - mitsuba) < 0.01 * mitsuba + 3 * se)


def test_exr_layers_round_trip(tmp_path):
    import OpenEXR
    r = render.render(render.builtin("sphere", "lambert(albedo=0.5)"), spp=2, size=(12, 8), seed=0)
    path = r.save(tmp_path / "out.exr")
    with OpenEXR.File(str(path), separate_channels=True) as f:
        ch = f.channels()
        assert {"R", "G", "B", "albedo.R", "normal.X", "normal.Z", "variance.G"} <= set(ch)
        np.testing.assert_array_equal(ch["G"].pixels, r.image[..., 1].astype(np.float32))
    with pytest.raises(brdf.OutputError):
        r.save(path)
    r.save(path, force=True)
    png = r.preview(tmp_path / "out.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


_POOL = """
import sys
import numpy as np
import OpenEXR
from brdf.render.image import read_image, write_exr
if len(sys.argv) > 2:
    OpenEXR.set_global_thread_count(int(sys.argv[2]))
rgb = np.linspace(0.0, 1.0, 48 * 3).reshape(4, 12, 3)
write_exr(sys.argv[1], rgb)
same = bool(np.array_equal(read_image(sys.argv[1]), rgb.astype(np.float32)))
print(OpenEXR.global_thread_count(), same)
"""


@pytest.mark.parametrize("threads, pool", [("1", "1"), ("2", "2"), ("2 3", "3")])
def test_exr_files_are_compressed_on_the_packages_threads(tmp_path, threads, pool):
    """The first EXR write sizes OpenEXR's pool of threads (empty by default: one thread
    compresses the file) to the package's thread count, unless something set a size first."""
    import os
    import subprocess
    import sys
    count, *preset = threads.split()
    done = subprocess.run([sys.executable, "-c", _POOL, str(tmp_path / "a.exr"), *preset],
                          env={**os.environ, "NUMBA_NUM_THREADS": count}, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == [pool, "True"]


def test_without_layers_the_same_image(tmp_path):
    """layers=False skips the variance, albedo and normal sums, and only them: the image is the
    same to the bit (a glossy sum and a texture-free Cornell box), and the EXR is RGB only."""
    import OpenEXR
    glossy = _glossy_scene("lambert(albedo=0.5) + ggx(alpha=0.3)")
    for scene in (glossy, render.builtin("cornell")):
        full = render.render(scene, spp=4, size=(12, 10), seed=5)
        bare = render.render(scene, spp=4, size=(12, 10), seed=5, layers=False)
        assert bare.image.tobytes() == full.image.tobytes()
        assert bare.variance is None and bare.albedo is None and bare.normal is None
        assert full.variance.max() > 0 and np.abs(full.normal).max() > 0
    path = bare.save(tmp_path / "bare.exr")
    with OpenEXR.File(str(path), separate_channels=True) as f:
        assert set(f.channels()) == {"R", "G", "B"}


@pytest.mark.parametrize("kwargs, message", [
    ({"spp": 0}, "spp"), ({"size": (0, 4)}, "size"), ({"strategy": "nee"}, "strategy"),
    ({"max_depth": 0}, "max_depth"), ({"seed": -1}, "seed"),
])
def test_bad_options(kwargs, message):
    with pytest.raises(InputError, match=message):
        render.render(render.builtin("furnace", "lambert"), **kwargs)


def test_bad_scenes():
    with pytest.raises(InputError, match="built-in scenes"):
        render.builtin("teapot", "lambert")
    with pytest.raises(InputError, match="radius"):
        render.Scene(shapes=[render.Sphere((0, 0, 0), -1, "lambert")]).compile()
    with pytest.raises(InputError, match="parallel"):
        render.Scene(shapes=[render.Quad((0, 0, 0), (1, 0, 0), (2, 0, 0))]).compile()
    with pytest.raises(InputError, match="RGB"):
        render.Scene(shapes=[render.Sphere((0, 0, 0), 1, "lambert(albedo=[0.1,0.2,0.3,0.4])")]
                     ).compile()
