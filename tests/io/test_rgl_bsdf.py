"""RGL .bsdf reader (Dupuy & Jakob 2018): the four RGL materials, the VNDF warp against
analytic densities, Mitsuba 3's ``measured`` plugin as an independent oracle, bad input."""

import math
import shutil
import struct

import numpy as np
import pytest

import brdf
from brdf.errors import FormatError, InputError
from brdf.geometry import reflect, spherical_to_cartesian
from brdf.io import rgl_bsdf
from brdf.io.rgl_bsdf import RglTable
from measured_data import measured, published_sha256
from mitsuba_oracle import load_mitsuba, mitsuba_eval
from tensor_files import small_material, tensor_file

# descriptions as the README of ../shared/measured lists them
MATERIALS = {
    "paper_white_rgb.bsdf": "White A4 paper (160 gsm)",
    "colodur_napoli_4f_rgb.bsdf": "Coop Colodur wall paint sample swatch (Napoli 4F)",
    "cc_ibiza_sunset_rgb.bsdf": "TeckWrap vinyl wrapping film (Ibiza Sunset RD02)",
    "vch_golden_yellow_rgb.bsdf": "TeckWrap vinyl wrapping film (Golden Yellow VCH508N)",
}


def _path(name):
    return measured(f"rgl/{name}")


@pytest.fixture(scope="module", params=sorted(MATERIALS))
def material(request):
    return request.param, rgl_bsdf.read(_path(request.param))


def _hemisphere(rng, n):
    """Directions uniform on the upper hemisphere (z uniform in [0, 1))."""
    z = rng.uniform(0.0, 1.0, n)
    return spherical_to_cartesian(np.arccos(z), rng.uniform(0.0, 2.0 * math.pi, n))


def _pairs(seed, n):
    """Uniform pairs, and as many with wo within ~10 degrees of the mirror direction (where
    glossy materials have their peak)."""
    rng = np.random.default_rng(seed)
    wi = _hemisphere(rng, 2 * n)
    wo = _hemisphere(rng, 2 * n)
    near = reflect(wi[n:]) + rng.normal(0.0, 0.1, (n, 3))
    wo[n:] = near / np.linalg.norm(near, axis=-1, keepdims=True)
    keep = wo[:, 2] > 0.02
    return wi[keep], wo[keep]


# --- the real files -----------------------------------------------------------------------------

def test_reads_description_provenance_and_layout(material):
    name, t = material
    assert isinstance(t, RglTable) and t.format == rgl_bsdf.FORMAT == "rgl-bsdf"
    assert t.metadata["description"] == MATERIALS[name]
    assert t.source.sha256 == published_sha256(f"rgl/{name}")
    assert t.channels == 3 and t.channel_names == ("r", "g", "b") and t.wavelengths is None
    assert t.isotropic and t.metadata["color_space"] == "linear sRGB"
    assert t.metadata["version"] == "1.0" and t.metadata["jacobian"] is True
    assert t.metadata["resolution"] == [32, 32] and t.metadata["vndf_resolution"] == [128, 128]
    # 8 incident angles x 32 x 32 points, less those the warp sends below the horizon
    assert len(t) + t.metadata["horizon_samples_left_out"] == 8 * 32 * 32
    assert np.all(t.wo[:, 2] > 0.0) and np.all(np.isfinite(t.values))
    theta = t.metadata["theta_i_deg"]
    assert len(theta) == 8 and theta[0] == 0.0 and theta[-1] == pytest.approx(90.0, abs=1e-5)


def test_incident_angles_of_paper_white():
    t = rgl_bsdf.read(_path("paper_white_rgb.bsdf"))
    # README: 0, 0.483, 0.696, 0.872, 1.035, 1.197, 1.369, 1.571 radians
    readme = [0.0, 0.483, 0.696, 0.872, 1.035, 1.197, 1.369, 1.571]
    np.testing.assert_allclose(np.radians(t.metadata["theta_i_deg"]), readme, atol=5e-4)
    np.testing.assert_allclose(np.unique(np.round(t.angles[:, 0], 9)),
                               t.metadata["theta_i_deg"], atol=1e-6)
    assert np.all(t.angles[:, 1] == 0.0)  # phi_i = 0 in the file


def test_registry_by_extension_and_by_content(tmp_path):
    src = _path("vch_golden_yellow_rgb.bsdf")
    assert isinstance(brdf.read(src), RglTable)
    renamed = tmp_path / "material.tensor"  # an extension no format claims
    shutil.copyfile(src, renamed)
    t = brdf.read(renamed)
    assert isinstance(t, RglTable) and t.source.format == "rgl-bsdf"
    assert rgl_bsdf.sniff(src.read_bytes()[:4096]) and not rgl_bsdf.sniff(b"tensor_fil")
    # the extension also picks the writer (tests/io/test_rgl_bsdf_write.py)
    assert isinstance(brdf.read(brdf.write(t, tmp_path / "out.bsdf")), RglTable)


def test_samples_sit_on_the_unit_square_nodes(material):
    # the inverse warp takes each sample's (wi, wo) back to its node (j, i) / 31; the stored
    # value there, converted by eval, is the sample's value
    _, t = material
    s = t.unit_square(t.wi, t.wo)
    # theta_h = 0 (column 0) has no azimuth: its 32 nodes are one direction
    pole = s[:, 0] < 1e-9
    assert np.abs(s * 31 - np.round(s * 31))[~pole].max() < 1e-6
    # v = 0 and v = 1 are one azimuth: the inverse returns either row
    seam = np.abs(s[:, 1] - 0.5) > 0.5 - 1e-9
    ok = ~pole & ~seam
    assert ok.sum() > 6500
    np.testing.assert_allclose(t.eval_one_sided(t.wi[ok], t.wo[ok])[0], t.values[ok],
                               rtol=1e-9, atol=1e-12)


def test_eval_is_finite_non_negative_and_zero_below_horizon(material):
    _, t = material
    wi, wo = _pairs(3, 2000)
    f = t.eval(wi, wo)
    assert f.shape == (len(wi), 3) and np.all(np.isfinite(f)) and np.all(f >= 0.0)
    below = wo * [1.0, 1.0, -1.0]
    np.testing.assert_array_equal(t.eval(wi, below), 0.0)
    np.testing.assert_array_equal(t.eval(below, wo), 0.0)
    # isotropic: rotating both directions about the normal changes nothing
    c, s = math.cos(1.1), math.sin(1.1)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(t.eval(wi @ rot.T, wo @ rot.T), f, rtol=1e-9, atol=1e-12)


def test_clip_option_and_negative_samples():
    # vch_golden_yellow stores out-of-gamut (negative) rgb samples (1,118 in the file)
    t = rgl_bsdf.read(_path("vch_golden_yellow_rgb.bsdf"))
    assert np.count_nonzero(t.values < 0.0) > 0  # kept for the non-negativity check
    neg = np.flatnonzero((t.values < 0.0).any(axis=1))
    raw = t.eval_one_sided(t.wi[neg], t.wo[neg])[0]  # as measured: unclipped
    clipped = t.eval_one_sided(t.wi[neg], t.wo[neg], clip=True)[0]
    assert raw.min() < 0.0
    np.testing.assert_allclose(clipped, np.maximum(raw, 0.0), rtol=1e-12, atol=0)
    # eval clips both orders' samples by default (the table's clip), not when asked not to
    assert t.eval(t.wi[neg], t.wo[neg]).min() >= 0.0
    unclipped = rgl_bsdf.read(_path("vch_golden_yellow_rgb.bsdf"), clip=False)
    np.testing.assert_array_equal(unclipped.eval(t.wi[neg], t.wo[neg]),
                                  t.eval(t.wi[neg], t.wo[neg], clip=False))


def test_measurement_is_approximately_reciprocal_and_eval_exactly():
    # the measurement is one-sided: f(wi, wo) and f(wo, wi) come from different slices and
    # points of the warp. For diffuse paper below 60 degrees they agree to a few percent.
    t = rgl_bsdf.read(_path("paper_white_rgb.bsdf"))
    rng = np.random.default_rng(5)
    wi, wo = _hemisphere(rng, 20000), _hemisphere(rng, 20000)
    keep = (wi[:, 2] > 0.5) & (wo[:, 2] > 0.5)
    (a, _), (b, _) = t.eval_one_sided(wi[keep], wo[keep]), t.eval_one_sided(wo[keep], wi[keep])
    rel = np.abs(a - b).sum(axis=1) / (0.5 * (a + b).sum(axis=1))
    assert np.median(rel) < 0.05 and rel.max() > 1e-3
    # eval combines both orders, (g(wi, wo) + g(wo, wi)) / (cos_i + cos_o) with g = f cos_o
    f = t.eval(wi[keep], wo[keep])
    np.testing.assert_allclose(f, t.eval(wo[keep], wi[keep]), rtol=1e-14)  # to rounding
    ci, co = wi[keep][:, 2:], wo[keep][:, 2:]
    np.testing.assert_allclose(f, (a * co + b * ci) / (ci + co), rtol=1e-12)
    # ... which moves f off the measurement by half the asymmetry at most
    assert np.all(np.abs(f - a) <= np.abs(b - a) + 1e-15)


def test_paper_stays_finite_and_reciprocal_at_the_horizon():
    # the one-sided measurement at 30 degrees in, theta_o -> 90 (specular plane) divides a
    # non-vanishing f cos(theta_o) by cos(theta_o): 27.7 1/sr at 89.99 degrees, 2.7e5 at
    # 89.999999; eval tends to the swapped measurement, ~0.39 1/sr there
    t = rgl_bsdf.read(_path("paper_white_rgb.bsdf"))
    wi = spherical_to_cartesian(math.radians(30.0), 0.0)
    for theta_o, one_sided in ((89.99, 27.7), (89.999999, 2.74e5)):
        wo = spherical_to_cartesian(math.radians(theta_o), math.pi)
        assert t.eval_one_sided(wi, wo)[0][0] == pytest.approx(one_sided, rel=0.01)
        f = t.eval(wi, wo)
        swapped = t.eval_one_sided(wo, wi)[0]
        assert np.all(np.isfinite(f)) and swapped[0] == pytest.approx(0.394, abs=0.001)
        np.testing.assert_allclose(f, swapped, rtol=0.02)
        np.testing.assert_allclose(f, t.eval(wo, wi), rtol=1e-14)
    assert t.valid_theta == pytest.approx(math.radians(78.46392910954252))
    assert t.metadata["valid_theta_deg"] == pytest.approx(78.46392910954252)


def test_eval_is_finite_on_a_dense_grid_to_the_horizon(material):
    # polar angles to within 1e-9 degrees of the horizon in both directions, all azimuths:
    # within a few times the largest measured value (2.1x for colodur, both directions within
    # 1e-6 degrees of the horizon; the one-sided lookup reaches 4e10 1/sr on this grid)
    _, t = material
    theta = np.radians(np.concatenate([np.linspace(0.0, 89.0, 46),
                                       90.0 - np.logspace(-9.0, 0.0, 19)]))
    ti, to, po = np.meshgrid(theta, theta, np.radians(np.arange(0.0, 360.0, 10.0)),
                             indexing="ij")
    wi = spherical_to_cartesian(ti.ravel(), 0.0)
    wo = spherical_to_cartesian(to.ravel(), po.ravel())
    f = t.eval(wi, wo)
    assert np.all(np.isfinite(f)) and np.all(f >= 0.0)
    assert f.max() <= 3.0 * t.values.max()


def test_albedo_of_paper_white_is_plausible():
    t = rgl_bsdf.read(_path("paper_white_rgb.bsdf"))
    theta = np.radians([0.0, 30.0, 60.0])
    wi = spherical_to_cartesian(theta, 0.0)
    albedo = t.albedo(wi)
    assert np.all(albedo > 0.5) and np.all(albedo < 1.0)
    assert np.all(albedo[:, 2] > albedo[:, 0])  # white paper is bluish (optical brighteners)


# --- Mitsuba 3 as the oracle --------------------------------------------------------------------

@pytest.fixture(scope="module")
def mitsuba():
    return load_mitsuba()


@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_agrees_with_mitsuba_measured_plugin(mitsuba, name):
    path = _path(name)
    t = rgl_bsdf.read(path)
    bsdf = mitsuba.load_dict({"type": "measured", "filename": str(path)})
    wi, wo = _pairs(11, 150)
    ref = mitsuba_eval(mitsuba, bsdf, wi, wo)  # Mitsuba's eval includes cos(theta_o)
    ours = t.eval_one_sided(wi, wo)[0] * wo[:, 2:]
    # Mitsuba computes in float32: relative 1e-3, and values 1e-4 of the largest as absolute
    np.testing.assert_allclose(ours, ref, rtol=1e-3, atol=1e-4 * np.abs(ref).max())
    # Mitsuba does not clip; the reference reader's clipping is max(0, .) of the sample
    np.testing.assert_allclose(t.eval_one_sided(wi, wo, clip=True)[0] * wo[:, 2:],
                               np.maximum(ref, 0.0), rtol=1e-3, atol=1e-4 * np.abs(ref).max())


def test_albedo_agrees_with_mitsuba_importance_sampling(mitsuba):
    # Monte Carlo with Mitsuba's own sampling routine (weights f cos / pdf) against the
    # table's quadrature over our eval, at 30 degrees incidence
    path = _path("paper_white_rgb.bsdf")
    bsdf = mitsuba.load_dict({"type": "measured", "filename": str(path)})
    ctx, si = mitsuba.BSDFContext(), mitsuba.SurfaceInteraction3f()
    wi = spherical_to_cartesian(math.radians(30.0), 0.0)
    si.wi = mitsuba.Vector3f(*wi)
    u = np.random.default_rng(2).random((20000, 3))
    weights = np.empty((len(u), 3))
    for k, (a, b, c) in enumerate(u):
        _, w = bsdf.sample(ctx, si, float(a), mitsuba.Point2f(float(b), float(c)))
        weights[k] = [w[0], w[1], w[2]]
    mc = weights.mean(axis=0)
    stderr = weights.std(axis=0) / math.sqrt(len(u))
    ours = rgl_bsdf.read(path).albedo(wi)
    assert np.all(np.abs(ours - mc) < 4.0 * stderr + 2e-3)


# --- the warp against analytic densities ----------------------------------------------------

def _synthetic(vndf, theta=(0.0, 0.5 * math.pi), ndf=0.3, sigma=0.6):
    """An RglTable with constant NDF and sigma, the given VNDF slices (T, H, W) and stored
    samples 1 + sx + 2 sy (bilinear, so interpolated exactly) on a 5 x 5 grid."""
    g = np.linspace(0.0, 1.0, 5)
    sy, sx = np.meshgrid(g, g, indexing="ij")
    samples = np.broadcast_to(1.0 + sx + 2.0 * sy, (len(theta), 1, 5, 5))
    return RglTable(np.array(theta), 0.0, np.full((2, 2), ndf), np.full((2, 2), sigma), vndf,
                    samples)


def _pair(theta_i, theta_h, phi_h, phi_i=0.0):
    wi = spherical_to_cartesian(theta_i, phi_i)
    h = spherical_to_cartesian(theta_h, phi_h + phi_i)
    return wi, reflect(wi, h)


def test_uniform_vndf_is_the_identity_warp():
    # u = sqrt(theta_h / (pi/2)), v = (phi_h - phi_i + pi) / (2 pi); with a uniform VNDF the
    # stored sample is read at (u, v) and f = sample D / (4 sigma) / cos(theta_o)
    t = _synthetic(np.ones((2, 5, 5)))
    for phi_i in (0.0, 2.0):
        wi, wo = _pair(math.radians(40.0), math.radians(20.0), math.radians(60.0), phi_i)
        u, v = math.sqrt(20.0 / 90.0), (60.0 + 180.0) / 360.0
        np.testing.assert_allclose(t.unit_square(wi, wo), [u, v], atol=1e-12)
        expected = (1.0 + u + 2.0 * v) * 0.3 / (4.0 * 0.6) / wo[2]
        np.testing.assert_allclose(t.eval_one_sided(wi, wo)[0], [expected], rtol=1e-12)


def test_linear_vndf_inverts_its_cdf():
    # density 2x (1 + y) / 1.5 on the unit square (bilinear, so tabulated exactly): its
    # marginal-conditional CDFs are x^2 and (y + y^2/2) / 1.5
    h, w = 6, 9
    y, x = np.meshgrid(np.linspace(0, 1, h), np.linspace(0, 1, w), indexing="ij")
    vndf = np.broadcast_to(x * (1.0 + y), (2, h, w))
    t = _synthetic(vndf)
    u, v = 0.37, 0.81
    wi, wo = _pair(0.3, u * u * 0.5 * math.pi, (2.0 * v - 1.0) * math.pi)
    np.testing.assert_allclose(t.unit_square(wi, wo), [u * u, (v + v * v / 2.0) / 1.5],
                               atol=1e-12)
    # forward warp of the same point gives (u, v) back
    pdf, cond, marg = rgl_bsdf.warp_tables(vndf[:1])
    fx, fy = rgl_bsdf.warp_forward(pdf[0], cond[0], marg[0], np.array([u * u]),
                                   np.array([(v + v * v / 2.0) / 1.5]))
    np.testing.assert_allclose([fx[0], fy[0]], [u, v], atol=1e-12)


def test_incident_angle_interpolates_the_cdfs():
    # slice 0 uniform (CDF u), slice 1 linear in x (CDF u^2), same row totals: halfway in
    # theta_i the conditional CDF is their mean
    h, w = 4, 7
    x = np.broadcast_to(np.linspace(0, 1, w), (h, w))
    t = _synthetic(np.stack([np.ones((h, w)), x]))
    u = 0.6
    wi, wo = _pair(0.25 * math.pi, u * u * 0.5 * math.pi, 0.4)
    np.testing.assert_allclose(t.unit_square(wi, wo)[0], 0.5 * (u + u * u), atol=1e-12)


def test_spectral_file_reads_with_wavelengths(tmp_path):
    # a spectral file has 'spectra' and 'wavelengths' instead of 'rgb': the paper's rgb
    # samples relabelled as three wavelengths give the same f_r
    path = _path("paper_white_rgb.bsdf")
    fields = {name: f.array for name, f in
              rgl_bsdf.parse_tensor_file(path, path.read_bytes()).items()}
    fields["spectra"] = fields.pop("rgb")
    fields["wavelengths"] = np.array([450.0, 550.0, 650.0], dtype=np.float32)
    spectral = tmp_path / "spectral.bsdf"
    spectral.write_bytes(tensor_file(fields)[0])
    s, t = rgl_bsdf.read(spectral), rgl_bsdf.read(path)
    np.testing.assert_array_equal(s.wavelengths, [450.0, 550.0, 650.0])
    assert s.channel_names == ("450nm", "550nm", "650nm") and "color_space" not in s.metadata
    np.testing.assert_array_equal(s.values, t.values)


# --- bad input ----------------------------------------------------------------------------------

def test_small_material_reads(tmp_path):
    data, _ = tensor_file(small_material())
    path = tmp_path / "ok.bsdf"
    path.write_bytes(data)
    t = rgl_bsdf.read(path)
    assert t.metadata["description"] == "Test swatch (µ)"
    wi, wo = _pair(0.3, 0.2, 0.1)
    # uniform VNDF, constant samples: f = 0.5 * 0.3 / (4 * 0.8) / cos(theta_o)
    np.testing.assert_allclose(t.eval_one_sided(wi, wo)[0], [0.5 * 0.3 / 3.2 / wo[2]] * 3,
                               rtol=1e-6)


def _patched(data, at, new):
    return data[:at] + new + data[at + len(new):]


def _bad_cases():
    data, where = tensor_file(small_material())
    fields = small_material()
    nan = fields["vndf"].copy()
    nan[0, 1, 2, 3] = np.nan
    nan_data, nan_where = tensor_file({**fields, "vndf": nan})
    nan_byte = nan_where["vndf"][3] + 4 * np.ravel_multi_index((0, 1, 2, 3), nan.shape)
    bad_text = {**fields, "description": np.frombuffer(b"Paper \xff", np.uint8)}
    text_data, text_where = tensor_file(bad_text)
    no_rgb = {k: v for k, v in fields.items() if k != "rgb"}
    two = {**fields, "rgb": fields["rgb"][:, :, :2]}
    two_data, two_where = tensor_file(two)
    aniso = {**fields, "phi_i": np.zeros(4, np.float32)}
    aniso_data, aniso_where = tensor_file(aniso)
    zero_sigma = {**fields, "sigma": np.zeros((2, 8), np.float32)}
    zs_data, zs_where = tensor_file(zero_sigma)
    rgb = where["rgb"]
    overlap = _patched(data, rgb[2], struct.pack("<Q", where["ndf"][3]))
    return [
        ("truncated header", data[:10], "byte 10", "truncated header"),
        ("truncated field entry", data[:30], "byte 27", "field entry 1 of 10"),
        ("wrong magic", b"tensor_filX" + data[11:], "byte 0", "magic"),
        ("version 2.0", _patched(data, 12, b"\x02"), "byte 12", "version 2.0"),
        ("offset past end", _patched(data, rgb[2], struct.pack("<Q", len(data))),
         f"byte {rgb[2]}", "'rgb' data"),
        ("unknown data type", _patched(data, rgb[1], b"\x2a"), f"byte {rgb[1]}",
         "'rgb' has unknown data type 42"),
        ("NaN in a field", nan_data, f"byte {nan_byte}", "'vndf' holds nan"),
        ("non-UTF-8 description", text_data, f"byte {text_where['description'][3] + 6}",
         "not UTF-8"),
        ("missing field", tensor_file(no_rgb)[0], "byte 18", "missing field(s) 'rgb'"),
        ("trailing bytes", data + b"\0" * 5, f"byte {len(data)}", "oversized: 5 bytes"),
        ("overlapping fields", overlap, f"byte {where['ndf'][3]}", "overlaps"),
        ("wrong channel count", two_data, f"byte {two_where['rgb'][0]}", "'rgb' has shape"),
        ("anisotropic", aniso_data, f"byte {aniso_where['phi_i'][0]}", "isotropic"),
        ("zero sigma", zs_data, f"byte {zs_where['sigma'][3]}", "positive"),
    ]


@pytest.mark.parametrize("case", _bad_cases(), ids=lambda c: c[0])
def test_bad_input_names_file_and_byte(tmp_path, case):
    _, data, where, what = case
    path = tmp_path / "bad.bsdf"
    path.write_bytes(data)
    with pytest.raises(FormatError) as e:
        brdf.read(path)
    message = str(e.value)
    assert message.startswith(f"{path}:{where}: ") and what in message
    assert "\n" not in message


def test_missing_fields_lists_the_required_ones(tmp_path):
    fields = {k: v for k, v in small_material().items() if k not in ("rgb", "ndf")}
    path = tmp_path / "bad.bsdf"
    path.write_bytes(tensor_file(fields)[0])
    with pytest.raises(FormatError, match=r"'ndf', 'rgb'; an RGB \.bsdf material needs "
                                          r"description, phi_i, theta_i, sigma, ndf, vndf, "
                                          r"luminance, jacobian, rgb"):
        rgl_bsdf.read(path)
