"""RGL .bsdf writer: the adaptive parameterisation against closed forms and the RGL files, the
round trip through our reader, Mitsuba 3's ``measured`` plugin as the independent oracle of
what we write (evaluation and a render), and every refusal.

Measured (Mitsuba 3.9.1 ``scalar_rgb``, the default resolution of the RGL files: 8 incident
angles, 32 x 32 samples, 128 x 128 VNDF, 128 NDF nodes), over 1,949 direction pairs with both
polar angles up to 80 degrees, half of them within ~10 degrees of the mirror direction:
Mitsuba's f_r cos(theta_o) of our tensor against our eval of the source times cos(theta_o),
relative difference |a - b| / max(|b|, 1e-3 max |b|):

======================================================  ========  ==========
source                                                  median    99th pct.
======================================================  ========  ==========
lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.3, ks=0.2)  0.58 %    7.2 %
beckmann(alpha=0.2)                                     0.007 %   1.35 %
paper_white_rgb.bsdf (our reader's eval)                0.90 %    9.6 %
======================================================  ========  ==========

The largest differences sit near the mirror direction at grazing incidence, where the VNDF
warp squeezes the half vectors near the normal into the first cell of the sample grid (its
density vanishes like u^3 there); they shrink with ``samples``. A render of a plane under a
point light (64 x 64, 16 spp) in Mitsuba with the tensor and in ``brdf.render`` with the
source agrees in mean within 0.4 % (lambert + ggx 0.997, Beckmann 1.0005, paper 0.9965), a
sphere under a directional light within 0.5 % (0.9955, 0.9999, 0.9969).
"""

import math
from pathlib import Path

import numpy as np
import pytest

import brdf
from brdf.errors import InputError
from brdf.geometry import reflect, spherical_to_cartesian
from brdf.io import adaptive_parameterization as ap
from brdf.io import rgl_bsdf
from mitsuba_oracle import load_mitsuba, mitsuba_eval
from test_cli import assert_one_error_line, run

RGL = Path(__file__).resolve().parents[2] / "measurements" / "rgl"
LAMBERT_GGX = "lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.3, ks=0.2)"
BECKMANN = "beckmann(alpha=0.2)"


def _write(tmp_path, source, name="x.bsdf", **options):
    path = tmp_path / name
    brdf.write(source, path, **options)
    return path


def _pairs(seed, n, max_deg=80.0):
    """Pairs with both polar angles up to ``max_deg``: uniform in cos(theta), and as many with
    wo within ~10 degrees of the mirror direction."""
    rng = np.random.default_rng(seed)
    z_min = math.cos(math.radians(max_deg))

    def hemisphere(k):
        return spherical_to_cartesian(np.arccos(rng.uniform(z_min, 1.0, k)),
                                      rng.uniform(0.0, 2.0 * math.pi, k))
    wi, wo = hemisphere(2 * n), hemisphere(2 * n)
    near = reflect(wi[n:]) + rng.normal(0.0, 0.1, (n, 3))
    wo[n:] = near / np.linalg.norm(near, axis=-1, keepdims=True)
    keep = wo[:, 2] > z_min
    return wi[keep], wo[keep]


def _relative(a, b):
    """|a - b| / max(|b|, 1e-3 max |b|): relative, except where b is 1000 times below its
    peak (the tails of a lobe, where a relative difference says nothing)."""
    return np.abs(a - b) / np.maximum(np.abs(b), 1e-3 * np.abs(b).max())


# --- the parameterisation against closed forms ----------------------------------------------

@pytest.mark.parametrize("family, up_to, d_tol, sigma_tol", [("beckmann", 80.0, 1e-5, 2e-5),
                                                             ("ggx", 40.0, 6e-3, 2e-3)])
def test_power_iteration_recovers_the_ndf_and_projected_area(family, up_to, d_tol, sigma_tol):
    """The eigenvector of the backscattering operator is the lobe's D (Walter et al. 2007 eqs.
    28 and 33) and sigma(theta) = cos(theta) (1 + Lambda) (Heitz 2014, eq. 72 with eqs. 83
    and 86 for Lambda). The extraction assumes f_r(k, k) = F D / (4 cos sigma), i.e. G1 at
    retro-reflection; our lobes' separable G1(wi) G1(wo) gives G1^2 there, which differs
    where Lambda does: nowhere that matters for Beckmann at alpha 0.2 (exact to 1.5e-6), beyond
    ~40 degrees for GGX's long tail (Lambda(40 deg) = 0.007; 2.8 % at 60 degrees)."""
    alpha = 0.2
    model = brdf.parse(f"{family}(alpha={alpha})")
    u = np.linspace(0.0, 1.0, 128)
    theta = u * u * 0.5 * math.pi
    d = ap.backscatter_ndf(model.eval, u)
    t2 = np.tan(theta[1:-1]) ** 2
    c4 = np.cos(theta[1:-1]) ** 4
    if family == "beckmann":
        exact = np.exp(-t2 / alpha ** 2) / (math.pi * alpha ** 2 * c4)
        a = 1.0 / (alpha * np.sqrt(t2))
        lam = np.exp(-a * a) / (2.0 * math.sqrt(math.pi) * a) - 0.5 * np.vectorize(math.erfc)(a)
    else:
        exact = alpha ** 2 / (math.pi * c4 * (alpha ** 2 + t2) ** 2)
        lam = 0.5 * (np.sqrt(1.0 + alpha ** 2 * t2) - 1.0)
    within = np.degrees(theta[1:-1]) <= up_to
    resolved = within & (exact > 1e-3 * exact.max())
    np.testing.assert_allclose(d[1:-1][resolved], exact[resolved], rtol=d_tol)
    sigma = ap.projected_area(d, u)
    assert sigma[0] == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(sigma[1:-1][within], (np.cos(theta[1:-1]) * (1.0 + lam))[within],
                               rtol=sigma_tol)


@pytest.mark.parametrize("name", ["paper_white_rgb.bsdf", "colodur_napoli_4f_rgb.bsdf",
                                  "cc_ibiza_sunset_rgb.bsdf"])
def test_incident_angles_and_vndf_as_the_rgl_files_place_them(name):
    """From a file's own NDF and sigma, incident angles equally spaced in sigma and the VNDF
    <wi.h> D u sin(theta_h) give that file's theta_i and vndf fields."""
    fields = rgl_bsdf.parse_tensor_file(RGL / name, (RGL / name).read_bytes())
    u = np.linspace(0.0, 1.0, 128)
    sigma = fields["sigma"].array[0].astype(float)
    ndf = fields["ndf"].array[0].astype(float)
    theta = fields["theta_i"].array.astype(float)
    np.testing.assert_allclose(ap.incident_angles_for(sigma, u, 8), theta, atol=2e-4)
    vndf = fields["vndf"].array[0].astype(float)
    for k in (1, 4, 7):
        mine = ap.visible_ndf(theta[k], ndf, u, 128)
        np.testing.assert_allclose(mine, vndf[k], rtol=2e-3, atol=1e-6 * vndf[k].max())


# --- the file -----------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def written(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bsdf")
    model = brdf.parse(LAMBERT_GGX)
    return model, _write(folder, model)


def test_layout_matches_the_rgl_files(written):
    _, path = written
    ours = rgl_bsdf.parse_tensor_file(path, path.read_bytes())
    paper = rgl_bsdf.parse_tensor_file(RGL / "paper_white_rgb.bsdf",
                                       (RGL / "paper_white_rgb.bsdf").read_bytes())
    assert list(ours) == list(paper)
    for name, field in paper.items():
        if name != "description":
            assert (ours[name].dtype, ours[name].shape) == (field.dtype, field.shape), name
        assert ours[name].offset % 8 == 0
    assert bytes(ours["description"].array).decode() == str(brdf.parse(LAMBERT_GGX))
    np.testing.assert_array_equal(ours["version"].array, [1, 0])
    assert ours["jacobian"].array[0] == 1 and ours["phi_i"].array[0] == 0.0
    assert ours["sigma"].array[0, 0] == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose(ours["vndf"].array.sum(axis=(2, 3)), 1.0, rtol=1e-4)
    # luminance: Rec. 709 of the rgb samples, clipped at 0
    rgb = ours["rgb"].array.astype(float)
    lum = np.maximum(np.einsum("ptcyx,c->ptyx", rgb, [0.2126, 0.7152, 0.0722]), 0.0)
    np.testing.assert_allclose(ours["luminance"].array, lum, rtol=1e-6, atol=1e-7)


def test_round_trip_through_our_reader(written):
    """At every stored node our reader gives back the source (float32 rounding), and the valid
    bits mark the nodes above the horizon."""
    model, path = written
    t = rgl_bsdf.read(path)
    assert t.metadata["resolution"] == [32, 32] and t.metadata["vndf_resolution"] == [128, 128]
    assert len(t.metadata["theta_i_deg"]) == 8
    np.testing.assert_allclose(t.eval_one_sided(t.wi, t.wo)[0], model.eval(t.wi, t.wo),
                               rtol=1e-5)
    fields = rgl_bsdf.parse_tensor_file(path, path.read_bytes())
    bits = np.unpackbits(fields["valid"].array)[:8 * 32 * 32]
    assert bits.sum() == len(t)  # the reader keeps exactly the nodes above the horizon


def test_same_input_same_bytes_and_options(tmp_path, written):
    model, path = written
    assert _write(tmp_path, model).read_bytes() == path.read_bytes()
    small = _write(tmp_path, model, "small.bsdf", incident_angles=5, samples=16,
                   vndf_resolution=64, ndf_resolution=65, description="small")
    t = rgl_bsdf.read(small)
    assert len(t.metadata["theta_i_deg"]) == 5 and t.metadata["resolution"] == [16, 16]
    assert t.metadata["vndf_resolution"] == [64, 64] and t.metadata["description"] == "small"


def test_grey_and_spectral_sources(tmp_path):
    grey = brdf.parse("lambert(albedo=0.6) + ggx(alpha=0.25, ks=0.3)")
    t = rgl_bsdf.read(_write(tmp_path, grey, "grey.bsdf"))
    assert t.channels == 3
    v = t.eval_one_sided(t.wi, t.wo)[0]
    np.testing.assert_allclose(v, np.repeat(grey.eval(t.wi, t.wo), 3, axis=1), rtol=1e-5)
    # a spectral table: spectra and wavelengths
    wl = [450.0, 550.0, 650.0, 750.0]
    spectral = brdf.parse("lambert(albedo=[0.2,0.4,0.6,0.8]) + ggx(alpha=0.3, ks=0.1)")
    wi = spherical_to_cartesian(np.repeat(np.radians([0.0, 20, 40, 60, 75, 85]), 400),
                                0.0)
    rng = np.random.default_rng(1)
    wo = spherical_to_cartesian(np.arccos(rng.uniform(0.0, 1.0, len(wi))),
                                rng.uniform(0.0, 2.0 * math.pi, len(wi)))
    table = brdf.Table(wi, wo, spectral.eval(wi, wo), wavelengths=wl)
    path = _write(tmp_path, table, "spectral.bsdf")
    fields = rgl_bsdf.parse_tensor_file(path, path.read_bytes())
    assert "spectra" in fields and "rgb" not in fields
    np.testing.assert_array_equal(fields["wavelengths"].array, wl)
    back = rgl_bsdf.read(path)
    assert back.wavelengths.tolist() == wl and back.channels == 4


# --- Mitsuba 3 as the oracle --------------------------------------------------------------------

@pytest.fixture(scope="module")
def mitsuba():
    return load_mitsuba()


def _source(name):
    return brdf.read(RGL / name) if name.endswith(".bsdf") else brdf.parse(name)


# median and 99th-percentile tolerances: about 1.5 x the measured figures (module notes)
@pytest.mark.parametrize("name, median, p99", [(LAMBERT_GGX, 0.01, 0.11),
                                               (BECKMANN, 2e-4, 0.025),
                                               ("paper_white_rgb.bsdf", 0.014, 0.15)])
def test_mitsuba_measured_plugin_agrees_with_the_source(mitsuba, tmp_path, name, median, p99):
    source = _source(name)
    path = _write(tmp_path, source)
    bsdf = mitsuba.load_dict({"type": "measured", "filename": str(path)})
    wi, wo = _pairs(3, 1000)
    theirs = mitsuba_eval(mitsuba, bsdf, wi, wo)  # f_r cos(theta_o)
    ours = source.eval(wi, wo) * wo[:, 2:]
    rel = _relative(theirs, ours)
    assert np.median(rel) < median and np.percentile(rel, 99) < p99, (
        np.median(rel), np.percentile(rel, 99))
    # and our reader reads what Mitsuba reads: the same numbers to float32 rounding
    np.testing.assert_allclose(rgl_bsdf.read(path).eval_one_sided(wi, wo)[0] * wo[:, 2:],
                               theirs, rtol=1e-4, atol=1e-5 * np.abs(theirs).max())


def test_mitsuba_spectral_variant_reads_our_spectra(mitsuba, tmp_path):
    """A spectral table is written as ``spectra`` + ``wavelengths``; Mitsuba's spectral variant
    interpolates it linearly in wavelength, as our reader's values at the four wavelengths
    predict (float32), and close to the model the table samples."""
    wl = [400.0, 500.0, 600.0, 700.0]
    model = brdf.parse("lambert(albedo=[0.2,0.4,0.6,0.8]) + ggx(alpha=0.3, ks=0.1)")
    rng = np.random.default_rng(1)
    wi = spherical_to_cartesian(np.repeat(np.radians([0.0, 20, 40, 60, 75, 85]), 400), 0.0)
    wo = spherical_to_cartesian(np.arccos(rng.uniform(0.0, 1.0, len(wi))),
                                rng.uniform(0.0, 2.0 * math.pi, len(wi)))
    path = _write(tmp_path, brdf.Table(wi, wo, model.eval(wi, wo), wavelengths=wl))
    ours = rgl_bsdf.read(path)
    query = [450.0, 500.0, 550.0, 650.0]
    wi, wo = _pairs(5, 20, max_deg=60.0)
    try:
        mitsuba.set_variant("scalar_spectral")
        bsdf = mitsuba.load_dict({"type": "measured", "filename": str(path)})
        ctx, si = mitsuba.BSDFContext(), mitsuba.SurfaceInteraction3f()
        si.wavelengths = mitsuba.Spectrum(query)
        theirs = np.empty((len(wi), 4))
        for k in range(len(wi)):
            si.wi = mitsuba.Vector3f(*wi[k])
            theirs[k] = list(bsdf.eval(ctx, si, mitsuba.Vector3f(*wo[k])))
    finally:
        mitsuba.set_variant("scalar_rgb")
    g = ours.eval_one_sided(wi, wo)[0] * wo[:, 2:]
    expected = np.stack([np.interp(query, wl, row) for row in g])
    np.testing.assert_allclose(theirs, expected, rtol=1e-4, atol=1e-5 * expected.max())
    truth = np.stack([np.interp(query, wl, row) for row in model.eval(wi, wo) * wo[:, 2:]])
    # measured 1.3 %, mostly the interpolation of the table's 2,400 scattered samples
    assert np.median(_relative(theirs, truth)) < 0.02


SUN = tuple(np.array([1.0, -1.0, -1.0]) / math.sqrt(3.0))


def _scenes(mi, path, source):
    """``{name: (Mitsuba scene dict, our scene)}``, direct light only: ``plane``, a 4 x 4
    plane at y = 0 under a point light of intensity 1 at (0, 1, 0) seen from (0, 3, 3) (our
    ``builtin("plane-point")``); ``sphere``, a unit sphere under a directional light of
    irradiance 3 seen from (0, 0, 4) (pairs up to grazing on both sides)."""
    from brdf import render
    t = mi.ScalarTransform4f
    measured = {"type": "measured", "filename": str(path)}

    def scene(origin, fov, shape, light):
        return {"type": "scene", "integrator": {"type": "path", "max_depth": 2},
                "sensor": {"type": "perspective", "fov": fov, "fov_axis": "x",
                           "to_world": t().look_at(origin=origin, target=[0, 0, 0],
                                                   up=[0, 1, 0]),
                           "film": {"type": "hdrfilm", "width": 64, "height": 64,
                                    "rfilter": {"type": "box"}, "pixel_format": "rgb"},
                           "sampler": {"type": "independent", "sample_count": 16}},
                "shape": shape, "light": light}
    plane = scene([0, 3, 3], 40.0, {"type": "rectangle", "bsdf": measured,
                                    "to_world": t().rotate([1, 0, 0], -90).scale([2, 2, 2])},
                  {"type": "point", "position": [0, 1, 0],
                   "intensity": {"type": "rgb", "value": [1.0, 1.0, 1.0]}})
    sphere = scene([0, 0, 4], 32.0, {"type": "sphere", "radius": 1.0, "bsdf": measured},
                   {"type": "directional", "direction": list(SUN),
                    "irradiance": {"type": "rgb", "value": [3.0, 3.0, 3.0]}})
    ours_sphere = render.Scene(render.Camera(origin=(0, 0, 4), target=(0, 0, 0), fov=32.0),
                               [render.Sphere((0, 0, 0), 1.0, source)],
                               [render.DirectionalLight(direction=SUN, irradiance=3.0)])
    return {"plane": (plane, render.builtin("plane-point", source)),
            "sphere": (sphere, ours_sphere)}


@pytest.mark.slow
@pytest.mark.parametrize("name", [LAMBERT_GGX, BECKMANN, "paper_white_rgb.bsdf"])
def test_mitsuba_render_of_the_tensor_matches_ours_of_the_source(mitsuba, tmp_path, name):
    """Mean image, Mitsuba rendering the tensor over ours rendering the source (64 x 64,
    16 spp, box filter), measured: plane 0.997, 1.0005, 0.9965; sphere 0.9955, 0.9999,
    0.9969 (Mitsuba's diffuse plugin against our lambert on the sphere: 0.9992)."""
    from brdf import render
    source = _source(name)
    path = _write(tmp_path, source)
    for what, (theirs, ours) in _scenes(mitsuba, path, source).items():
        a = np.array(mitsuba.render(mitsuba.load_dict(theirs), spp=16, seed=1))[..., :3]
        b = render.render(ours, spp=16, size=64, seed=1, max_depth=2).image
        np.testing.assert_allclose(a.mean(axis=(0, 1)) / b.mean(axis=(0, 1)), 1.0, atol=0.01,
                                   err_msg=what)


# --- refusals -------------------------------------------------------------------------------

@pytest.mark.parametrize("spec, fragments", [
    ("ggx(alpha=0.3, alpha_y=0.1)", ("anisotropic", "isotropic")),
    ("lambert(albedo=0.5) + mirror", ("delta lobes (mirror)", "without them")),
    ("lambert(albedo=[0.1,0.2])", ("2 channels without wavelengths", "rgb (3 channels)")),
])
def test_refuses_models_the_format_cannot_hold(capsys, tmp_path, spec, fragments):
    with pytest.raises(InputError) as e:
        brdf.write(brdf.parse(spec), tmp_path / "x.bsdf")
    assert "\n" not in str(e.value) and all(f in str(e.value) for f in fragments)
    status, _, err = run(capsys, "convert", spec, str(tmp_path / "y.bsdf"))
    assert status == 2
    assert_one_error_line(err, *fragments)
    assert not list(tmp_path.iterdir())


def test_refuses_tables_the_format_cannot_hold(tmp_path):
    rng = np.random.default_rng(0)
    wi = spherical_to_cartesian(np.arccos(rng.uniform(0.2, 1.0, 500)),
                                rng.uniform(0.0, 2.0 * math.pi, 500))
    wo = spherical_to_cartesian(np.arccos(rng.uniform(0.2, 1.0, 500)),
                                rng.uniform(0.0, 2.0 * math.pi, 500))
    cases = [(brdf.Table(wi, wo, np.full((500, 3), 0.2), isotropic=False, name="aniso"),
              "table aniso is anisotropic"),
             (brdf.Table(wi, wo, np.full((500, 2), 0.2), name="two"),
              "table two has 2 channels without wavelengths"),
             (brdf.measure(brdf.parse("lambert(albedo=0.5)"), "inplane:5", name="scan"),
              "table scan: only 48% of the direction pairs"),
             (brdf.Table(wi[:20], wo[:20], np.full((20, 3), 0.2), name="sparse"),
              "table sparse: only 32% of the direction pairs")]
    for table, fragment in cases:
        with pytest.raises(InputError, match=fragment) as e:
            brdf.write(table, tmp_path / "x.bsdf")
        assert "\n" not in str(e.value)
    assert "fit a model" in str(e.value)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("option, value", [("samples", 1), ("incident_angles", 2.5),
                                           ("vndf_resolution", True), ("ndf_resolution", 10**6)])
def test_refuses_bad_resolutions(tmp_path, option, value):
    with pytest.raises(InputError, match=f"{option} must be an integer"):
        brdf.write(brdf.parse("lambert"), tmp_path / "x.bsdf", **{option: value})
    with pytest.raises(InputError, match="takes no option 'bogus'"):
        brdf.write(brdf.parse("lambert"), tmp_path / "x.bsdf", bogus=1)


def test_convert_tables_specs_and_reports(capsys, tmp_path):
    out = tmp_path / "paper.bsdf"
    status, text, _ = run(capsys, "convert", str(RGL / "paper_white_rgb.bsdf"), str(out))
    assert status == 0 and "wrote" in text and rgl_bsdf.read(out).channels == 3
    status, _, err = run(capsys, "convert", str(RGL / "paper_white_rgb.bsdf"), str(out))
    assert status == 2
    assert_one_error_line(err, "exists", "--force")
    before = out.read_bytes()
    assert run(capsys, "convert", LAMBERT_GGX, str(out), "--force")[0] == 0
    assert out.read_bytes() != before
    report = tmp_path / "fit.json"
    brdf.fit(brdf.measure(brdf.parse("lambert(albedo=0.4) + ggx(alpha=0.3, ks=0.3)"),
                          "grid:15,30"),
             "lambert + ggx", seed=0).save(report)
    status, text, _ = run(capsys, "convert", str(report), str(tmp_path / "fit.bsdf"))
    assert status == 0 and "model lambert" in text
