"""brdf.export: Mitsuba 3 files load in Mitsuba and evaluate like our models where exact (and
like the stated equivalent where approximate); glTF materials follow the conversions stated and
our evaluator of glTF's BRDF; models without an equivalent are one-line errors; files are
written atomically and only replaced with force; the CLI."""

import json
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import brdf
from brdf.errors import BRDFError, InputError, OutputError
from brdf.io.export import EXPORTABLE, FORMATS, gltf_eval, relative_deviation
from lobes import upper_directions
from mitsuba_oracle import load_mitsuba, mitsuba_eval
from test_cli import assert_one_error_line, run, without_progress


@pytest.fixture(scope="module")
def mi():
    return load_mitsuba()


@pytest.fixture(scope="module")
def pairs():
    rng = np.random.default_rng(5)
    return upper_directions(rng, 40), upper_directions(rng, 40)


def mitsuba_bsdf(mi, text):
    """The file loads as a scene; its ``<bsdf id="material">`` loads as a BSDF to evaluate."""
    mi.load_string(text)
    element = ET.fromstring(text).find("bsdf")
    assert element.get("id") == "material"
    element.set("version", "3.0.0")
    return mi.load_string(ET.tostring(element, encoding="unicode"))


def mitsuba_f(mi, bsdf, wi, wo):
    """f_r (no cosine) from Mitsuba in our convention: our wo (viewer) is Mitsuba's si.wi, our
    wi (light) its wo, whose cosine its eval includes."""
    return mitsuba_eval(mi, bsdf, wo, wi) / wi[:, 2:]


MITSUBA_EXACT = [
    "lambert(albedo=[0.5,0.4,0.3])",
    "ggx(ks=0.8, alpha=0.2, alpha_y=0.45)",
    "ggx(ks=[0.9,0.8,0.7], alpha=0.3, fresnel=conductor(eta=[0.2,0.5,1.2], k=[3,2.5,2]))",
    "ggx(alpha=0.25, fresnel=dielectric(eta=1.5))",
    "lambert(albedo=[0.5,0.4,0.3]) + ggx(ks=0.3, alpha=0.2)",
    "lambert(albedo=0.2) + ggx(ks=0.3, alpha=0.4, fresnel=dielectric(eta=1.4)) "
    "+ ggx(ks=0.2, alpha=0.1, alpha_y=0.3)",
]


@pytest.mark.parametrize("spec", MITSUBA_EXACT)
def test_exact_mitsuba_exports_evaluate_like_our_model_in_mitsuba(mi, pairs, spec):
    result = brdf.export(spec, "mitsuba")
    assert result.exact and result.deviation <= 1e-9, result.notes
    wi, wo = pairs
    ours = np.broadcast_to(brdf.parse(spec).eval(wi, wo), (len(wi), 3))
    theirs = mitsuba_f(mi, mitsuba_bsdf(mi, result.text), wi, wo)
    # Mitsuba computes in float32
    np.testing.assert_allclose(theirs, ours, rtol=2e-5, atol=1e-6 * ours.max())


MITSUBA_APPROXIMATE = [
    ("ggx(alpha=0.3, fresnel=schlick(f0=[0.9,0.6,0.3]))", "Schlick"),
    ("ggx(alpha=0.3, alpha_y=0.1, masking=height-correlated)", "height-correlated"),
    ("lambert(albedo=0.3) + ggx(ks=0.5, alpha=0.2, fresnel=schlick(f0=0.04))", "Schlick"),
]


@pytest.mark.parametrize("spec,cause", MITSUBA_APPROXIMATE)
def test_approximate_mitsuba_exports_say_so_and_mitsuba_evaluates_the_stated_equivalent(
        mi, pairs, spec, cause):
    result = brdf.export(spec, "mitsuba")
    assert not result.exact
    assert any(cause in n and "approximate" in n for n in result.notes)
    assert "APPROXIMATE" in result.text.split("-->")[0]
    model = brdf.parse(spec)
    assert result.deviation == pytest.approx(relative_deviation(model.eval,
                                                                result.equivalent.eval))
    # no exact Fresnel follows Schlick's curve at low F0 (24 % apart at F0 = 0.04, a few
    # percent for metals); separable and height-correlated masking differ most at grazing
    # (11 % at 80 degrees for the anisotropic lobe)
    assert 1e-3 < result.deviation < 0.3
    wi, wo = pairs
    expected = np.broadcast_to(result.equivalent.eval(wi, wo), (len(wi), 3))
    theirs = mitsuba_f(mi, mitsuba_bsdf(mi, result.text), wi, wo)
    np.testing.assert_allclose(theirs, expected, rtol=2e-5, atol=1e-6 * expected.max())


@pytest.mark.parametrize("spec", [
    "beckmann(ks=[0.9,0.8,0.7], alpha=0.3, fresnel=conductor(eta=[0.2,0.5,1.2], k=[3,2.5,2]))",
    "lambert(albedo=0.2) + beckmann(ks=0.3, alpha=0.15, alpha_y=0.5)",
])
def test_beckmann_in_mitsuba_is_within_the_stated_bound_of_its_rational_g1(mi, pairs, spec):
    result = brdf.export(spec, "mitsuba")
    assert not result.exact and any("Walter" in n for n in result.notes)
    assert result.deviation == pytest.approx(1.00313 ** 2 - 1.0, rel=1e-3)
    wi, wo = pairs
    ours = np.broadcast_to(brdf.parse(spec).eval(wi, wo), (len(wi), 3))
    theirs = mitsuba_f(mi, mitsuba_bsdf(mi, result.text), wi, wo)
    err = np.abs(theirs - ours) - 2e-5 * ours - 1e-6 * ours.max()
    assert np.all(err <= result.deviation * ours)
    assert np.abs(theirs - ours).max() > 1e-4 * ours.max()  # the approximation does show


def test_mirror_exports_as_a_conductor_with_the_same_reflectance(mi):
    spec = "mirror(reflectance=[0.9,0.8,0.7], fresnel=conductor(eta=0.2, k=3))"
    result = brdf.export(spec, "mitsuba")
    assert result.exact
    bsdf = mitsuba_bsdf(mi, result.text)
    ctx, si = mi.BSDFContext(), mi.SurfaceInteraction3f()
    model = brdf.parse(spec)
    for theta in (0.0, 40.0, 75.0):
        wi = brdf.geometry.directions_from_degrees(theta, 30.0)
        si.wi = mi.Vector3f(*wi)
        sample, weight = bsdf.sample(ctx, si, 0.5, mi.Point2f(0.5, 0.5))
        assert np.allclose([sample.wo[0], sample.wo[1], sample.wo[2]], [-wi[0], -wi[1], wi[2]],
                           atol=1e-6)
        np.testing.assert_allclose([weight[0], weight[1], weight[2]], model.albedo(wi),
                                   rtol=1e-5)


def test_blend_weights_keep_each_reflectance_within_mitsuba_bounds():
    result = brdf.export("lambert(albedo=[0.6,0.2,0.1]) + ggx(ks=0.3, alpha=0.2)", "mitsuba")
    values = [float(v) for e in ET.fromstring(result.text).iter()
              if e.get("name") in ("reflectance", "specular_reflectance")
              for v in e.get("value").split(",")]
    assert max(values) == pytest.approx(0.9) and min(values) > 0.0  # 0.6 + 0.3 spread over both


def test_bright_sums_export_exactly_with_unbounded_reflectance_textures(mi, pairs):
    """Scales adding up to more than 1 (an energy-constrained fit of a bright material) are
    held by srgb textures with ``unbounded``, which Mitsuba's RGB variants evaluate as is."""
    spec = "lambert(albedo=[0.8,0.7,0.6]) + ggx(ks=0.5, alpha=0.2)"
    result = brdf.export(spec, "mitsuba")
    assert result.exact and result.error == 0.0
    assert 'name="unbounded" value="true"' in result.text
    assert any("1.3 > 1" in n for n in result.notes)
    wi, wo = pairs
    ours = np.broadcast_to(brdf.parse(spec).eval(wi, wo), (len(wi), 3))
    theirs = mitsuba_f(mi, mitsuba_bsdf(mi, result.text), wi, wo)
    np.testing.assert_allclose(theirs, ours, rtol=2e-5, atol=1e-6 * ours.max())


# --- the closest material -----------------------------------------------------------------------

CLOSEST = [
    ("lambert(albedo=0.3) + phong(ks=0.5, n=20)", "mitsuba"),
    ("ward(rho_s=0.2, alpha=0.1)", "mitsuba"),
    ("oren-nayar(albedo=[0.6,0.5,0.4], sigma=0.4)", "mitsuba"),
    ("lambert + modified-phong", "mitsuba"),
    ("mirror(reflectance=0.5) + blinn-phong(ks=0.3, n=50)", "mitsuba"),
    ("lambert(albedo=0.3) + ggx(ks=0.2, alpha=0.1) + ashikhmin-shirley", "mitsuba"),
    ("ashikhmin-shirley", "gltf"), ("blinn-phong", "gltf"), ("lambert + beckmann", "gltf"),
    ("lambert(albedo=0.9) + ggx(ks=0.5, alpha=0.2)", "gltf"),
]


@pytest.mark.parametrize("spec,format", CLOSEST)
def test_models_without_a_counterpart_export_as_the_closest_material_with_its_figures(
        spec, format):
    from brdf.io.closest_material import MAX_ERROR, relative_rms
    result = brdf.export(spec, format)
    model = brdf.parse(spec)
    assert not result.exact and result.closest
    assert "closest" in result.notes[0] and "approximate" in result.notes[0]
    if format == "mitsuba":
        assert result.equivalent.name in ("sum", "lambert", "ggx")
        theirs = result.equivalent.eval
    else:
        document = json.loads(result.text)
        (material,) = document["materials"]
        pbr = material["pbrMetallicRoughness"]
        assert all(0.0 <= v <= 1.0 for v in [*pbr["baseColorFactor"], pbr["metallicFactor"],
                                            pbr["roughnessFactor"]])
        assert set(document["extensionsUsed"]) == set(material["extensions"])
        assert material["extras"]["brdf"]["error"] == result.error

        def theirs(wi, wo):
            return gltf_eval(material, wi, wo)
    assert 0.0 < result.error <= MAX_ERROR
    assert result.error == pytest.approx(relative_rms(model, theirs))
    assert result.deviation == pytest.approx(relative_deviation(model.eval, theirs))
    # an independent estimate of the same figure, on other pairs
    assert relative_rms(model, theirs, seed=12345) == pytest.approx(result.error, rel=0.05,
                                                                    abs=2e-3)


def test_the_closest_mitsuba_material_evaluates_in_mitsuba_like_the_stated_one(mi, pairs):
    result = brdf.export("lambert(albedo=[0.6,0.5,0.4]) + ward(rho_s=0.4, alpha=0.15)",
                         "mitsuba")
    wi, wo = pairs
    expected = np.broadcast_to(result.equivalent.eval(wi, wo), (len(wi), 3))
    theirs = mitsuba_f(mi, mitsuba_bsdf(mi, result.text), wi, wo)
    np.testing.assert_allclose(theirs, expected, rtol=2e-5, atol=1e-6 * expected.max())


def test_the_closest_fit_beats_the_textbook_mapping_and_is_a_local_optimum():
    """Blinn-Phong's exponent maps to a microfacet roughness alpha = sqrt(2 / (n + 2))
    (Walter et al. 2007, section 5.2): the fitted closest lobe must be at least as close, and
    moving its roughness or scales either way must not bring it closer."""
    from brdf.io.closest_material import fit_lambert_ggx, relative_rms
    from brdf.models.base import Sum
    model = brdf.parse("lambert(albedo=0.4) + blinn-phong(ks=0.3, n=60)")
    fitted = fit_lambert_ggx(model)

    def error(albedo, ks, alpha):
        candidate = Sum([brdf.parse(f"lambert(albedo={albedo})"),
                         brdf.parse(f"ggx(ks={ks}, alpha={alpha}, masking=separable)")])
        return relative_rms(model, candidate.eval, seed=0)  # the fit's own pairs

    albedo, ks = float(fitted.lobes[0]["albedo"]), float(fitted.lobes[1]["ks"])
    alpha = float(fitted.lobes[1]["alpha"])
    best = error(albedo, ks, alpha)
    assert best < error(0.4, 0.3, math.sqrt(2.0 / 62.0))
    for change in (0.95, 1.05):
        assert best <= error(albedo * change, ks, alpha)
        assert best <= error(albedo, ks * change, alpha)
        assert best <= error(albedo, ks, alpha * change)


def test_the_closest_material_is_the_same_bytes_every_time():
    spec = "lambert(albedo=0.3) + phong(ks=0.5, n=20)"
    assert brdf.export(spec, "gltf").text == brdf.export(spec, "gltf").text


@pytest.mark.parametrize("spec,format,fragments", [
    ("lafortune(cx=0.8, cy=0.8, cz=0.5, n=10)", "mitsuba",
     ["no reasonable mitsuba counterpart", "relative RMS", "RGL tensor"]),
    ("mirror", "gltf", ["delta lobe", "mirror", "mitsuba"]),
])
def test_models_with_no_reasonable_counterpart_are_one_line_errors_naming_what_holds_them(
        spec, format, fragments):
    with pytest.raises(InputError) as info:
        brdf.export(spec, format)
    message = str(info.value)
    assert "\n" not in message and all(f in message for f in fragments), message


def test_max_error_sets_how_far_a_closest_material_may_be():
    spec = "lambert(albedo=0.3) + phong(ks=0.5, n=20)"
    error = brdf.export(spec, "mitsuba").error
    with pytest.raises(InputError, match="max_error"):
        brdf.export(spec, "mitsuba", max_error=error / 2)
    with pytest.raises(InputError, match="positive number"):
        brdf.export(spec, "mitsuba", max_error=-1)


# --- glTF ---------------------------------------------------------------------------------------

GLTF_EXACT = [
    "lambert(albedo=[0.5,0.4,0.3])",
    "ggx(alpha=0.16, masking=height-correlated, fresnel=schlick(f0=[0.9,0.7,0.4]))",
    "ggx(alpha=0.09, alpha_y=0.36, masking=height-correlated, fresnel=schlick(f0=0.5))",
    "lambert(albedo=[0.5,0.4,0.3]) + ggx(ks=0.3, alpha=0.2, masking=height-correlated)",
    "ggx(ks=0.3, alpha=0.2, masking=height-correlated) + lambert(albedo=[0.5,0.4,0.3])",
]


@pytest.mark.parametrize("spec", GLTF_EXACT)
def test_exact_gltf_exports_follow_gltfs_brdf(pairs, spec):
    result = brdf.export(spec, "gltf")
    assert result.exact, result.notes
    wi, wo = pairs
    material = json.loads(result.text)["materials"][0]
    ours = np.broadcast_to(brdf.parse(spec).eval(wi, wo), (len(wi), 3))
    np.testing.assert_allclose(gltf_eval(material, wi, wo), ours, rtol=1e-12, atol=1e-14)


def test_gltf_file_is_minimal_valid_gltf_with_the_stated_conversion():
    spec = "lambert(albedo=[0.5,0.4,0.3]) + ggx(ks=0.3, alpha=0.2, fresnel=schlick(f0=0.04))"
    document = json.loads(brdf.export(spec, "gltf").text)
    assert document["asset"]["version"] == "2.0"
    (material,) = document["materials"]
    pbr = material["pbrMetallicRoughness"]
    assert pbr["roughnessFactor"] == pytest.approx(math.sqrt(0.2))  # glTF alpha = roughness^2
    assert pbr["metallicFactor"] == 0.0 and len(pbr["baseColorFactor"]) == 4
    assert all(0.0 <= v <= 1.0 for v in pbr["baseColorFactor"])
    assert set(document["extensionsUsed"]) == set(material["extensions"])
    specular = material["extensions"]["KHR_materials_specular"]
    assert specular["specularFactor"] == 0.3
    assert np.allclose(np.multiply(specular["specularColorFactor"], 0.3), 0.3 * 0.04)
    stated = material["extras"]["brdf"]
    assert stated["exact"] is False and stated["spec"] == str(brdf.parse(spec))
    assert any("approximate" in n and "diffuse" in n for n in stated["notes"])
    assert 0.0 < stated["deviation"] < 0.2


def test_a_metal_is_metallic_with_its_normal_reflectance_as_base_colour():
    material = brdf.export("ggx(alpha=0.3, fresnel=conductor(eta=0.2, k=3))", "gltf").equivalent
    f0 = ((0.2 - 1.0) ** 2 + 9.0) / ((0.2 + 1.0) ** 2 + 9.0)  # conductor F0 at normal incidence
    pbr = material["pbrMetallicRoughness"]
    assert pbr["metallicFactor"] == 1.0
    assert pbr["baseColorFactor"][:3] == pytest.approx([f0] * 3)


# --- refusals, files, CLI -----------------------------------------------------------------------

def test_unknown_format_and_spectral_models_are_refused():
    with pytest.raises(InputError, match="mitsuba, gltf"):
        brdf.export("lambert", "usd")
    with pytest.raises(InputError, match="4 channels"):
        brdf.export("lambert(albedo=[0.1,0.2,0.3,0.4])", "mitsuba")


def test_writes_atomically_and_replaces_only_with_force(tmp_path):
    path = tmp_path / "paint.xml"
    result = brdf.export("lambert(albedo=0.3)", "mitsuba", path)
    assert result.path == str(path) and path.read_text(encoding="utf-8") == result.text
    with pytest.raises(OutputError, match="exists"):
        brdf.export("lambert(albedo=0.4)", "mitsuba", path)
    brdf.export("lambert(albedo=0.4)", "mitsuba", path, force=True)
    assert "0.4" in path.read_text() and sorted(p.name for p in tmp_path.iterdir()) == [
        "paint.xml"]


def test_cli_format_list_matches_the_library():
    from brdf_cli.export import FORMATS as CLI_FORMATS
    assert CLI_FORMATS == FORMATS


@pytest.fixture()
def report(tmp_path):
    table = tmp_path / "plastic.csv"
    brdf.write(brdf.measure("lambert(albedo=[0.5,0.4,0.3]) + ggx(ks=0.3, alpha=0.2)",
                            "grid:15,30"), table)
    return table


def test_cli_fit_export_writes_beside_the_report_and_export_reads_the_report(capsys, report):
    out_json = report.parent / "fit.json"
    status, out, err = run(capsys, "fit", str(report), "lambert + ggx(alpha=0.4)", "--shared",
                           "ks", "-o", str(out_json), "--export", "mitsuba")
    assert status == 0 and without_progress(err) == "", err
    xml = report.parent / "fit.xml"
    assert "mitsuba export" in out and xml.exists()
    assert brdf.load_report(out_json).spec in xml.read_text()
    status, out, err = run(capsys, "export", str(out_json), "--format", "gltf", "-o",
                           str(report.parent / "fit.gltf"), "--json")
    assert status == 0 and without_progress(err) == ""  # approximate, and written
    d = json.loads(out)
    assert d["exact"] is False and d["path"].endswith("fit.gltf") and d["error"] > 0.0
    status, _, err = run(capsys, "export", str(out_json), "--format", "gltf", "-o",
                         str(report.parent / "fit.gltf"))
    assert status == 2
    assert_one_error_line(err, "fit.gltf", "exists", "--force")


@pytest.mark.parametrize("argv,fragments", [
    (["fit", "{table}", "lambert + mirror", "-o", "{dir}/r.json", "--export", "gltf"],
     ["no gltf equivalent", "delta lobe", "mirror"]),
    (["fit", "{table}", "lambert + ggx", "--export", "gltf"], ["--export needs -o"]),
    (["export", "{table}", "--format", "gltf", "-o", "{dir}/x.gltf"], ["measured table"]),
])
def test_cli_export_errors_exit_2_before_any_work(capsys, report, argv, fragments):
    argv = [a.format(table=report, dir=report.parent) for a in argv]
    status, _, err = run(capsys, *argv)
    assert status == 2
    assert_one_error_line(err, *fragments)
    assert sorted(p.name for p in report.parent.iterdir()) == ["plastic.csv"]


def test_cli_fit_of_a_bright_material_exports_and_prints_the_fit_first(capsys, tmp_path):
    """A fit whose lobes' scales add up to more than 1 exports (exactly,
    for Mitsuba); the fit's table comes before the export's lines."""
    table = tmp_path / "bright.csv"
    brdf.write(brdf.measure("lambert(albedo=0.9) + ggx(ks=0.4, alpha=0.3)", "grid:15,30"),
               table)
    out_json = tmp_path / "fit.json"
    status, out, err = run(capsys, "fit", str(table), "lambert + ggx", "-o", str(out_json),
                           "--export", "mitsuba")
    assert status == 0, err
    assert out.index("verdict:") < out.index("mitsuba export")
    assert "unbounded" in (tmp_path / "fit.xml").read_text()


def test_cli_fit_prints_the_fit_before_an_export_that_is_refused(capsys, tmp_path):
    """A retro-reflective Lafortune fit has no reasonable glTF counterpart: the fit's table
    and its saved report come first, then the export's one error line."""
    spec = "lafortune(cx=0.8, cy=0.8, cz=0.5, n=10)"
    table = tmp_path / "retro.csv"
    brdf.write(brdf.measure(spec, "grid:10,30"), table)
    out_json = tmp_path / "fit.json"
    status, out, err = run(capsys, "fit", str(table), spec, "-o", str(out_json),
                           "--export", "gltf")
    assert status == 2
    assert_one_error_line(without_progress(err), "no reasonable gltf counterpart")
    assert "fitted: " in out and "verdict:" in out
    assert brdf.load_report(out_json).spec in out
    assert not (tmp_path / "fit.gltf").exists()


def test_cli_export_exact_writes_nothing_approximate(capsys, tmp_path):
    target = tmp_path / "x.gltf"
    status, out, _ = run(capsys, "export", "lambert + beckmann", "--format", "gltf", "-o",
                         str(target), "--exact")
    assert status == 1 and "not written" in out and not target.exists()
    status, _, _ = run(capsys, "export", "lambert(albedo=0.3)", "--format", "gltf", "-o",
                       str(target), "--exact")
    assert status == 0 and target.exists()


def test_cli_fit_export_to_a_path_reports_it_under_export_in_json(capsys, report):
    target = report.parent / "material.gltf"
    status, out, err = run(capsys, "fit", str(report), "lambert + ggx(alpha=0.4)", "--json",
                           "--export", "gltf", "--export-to", str(target))
    assert status == 0 and without_progress(err) == "", err
    d = json.loads(out)
    assert d["export"]["path"] == str(target) and d["export"]["format"] == "gltf"
    assert json.loads(target.read_text())["materials"][0]["extras"]["brdf"]["spec"] == d["spec"]


# --- Mitsuba's measured plugin ------------------------------------------------------------------

def test_measured_export_writes_a_tensor_that_mitsuba_reads_like_the_model(mi, tmp_path):
    """A retro-reflective Lafortune lobe has no reasonable roughconductor: as an RGL tensor
    read by Mitsuba's measured plugin it does, within the tensor's stated figures."""
    spec = "lambert(albedo=0.3) + lafortune(cx=0.8, cy=0.8, cz=0.5, n=10)"
    path = tmp_path / "retro.xml"
    result = brdf.export(spec, "mitsuba", path, measured=True)
    tensor = tmp_path / "retro.bsdf"
    assert tensor.exists() and result.closest == "RGL tensor" and not result.exact
    assert 'type="measured"' in result.text and 'value="retro.bsdf"' in result.text
    mi.set_variant("scalar_rgb")
    scene = mi.load_file(str(path))  # the file name resolves beside the scene
    assert scene is not None
    rng = np.random.default_rng(3)
    wi, wo = upper_directions(rng, 200), upper_directions(rng, 200)
    keep = (wi[:, 2] > 0.2) & (wo[:, 2] > 0.2)
    wi, wo = wi[keep], wo[keep]
    element = ET.fromstring(result.text).find("bsdf")
    element.set("version", "3.0.0")
    element.find("string").set("value", str(tensor))
    bsdf = mi.load_string(ET.tostring(element, encoding="unicode"))
    theirs = mitsuba_f(mi, bsdf, wi, wo)
    ours = np.broadcast_to(brdf.parse(spec).eval(wi, wo), theirs.shape)
    relative = np.abs(theirs - ours) / ours
    # the tensor's resolution (tests/io/test_rgl_bsdf_write.py states its figures); our reader
    # averages both orders of a pair, Mitsuba's plugin reads one, so each is held to the model
    assert np.median(relative) < 0.02 and np.percentile(relative, 99) < 0.2
    assert 0.0 < result.error < 0.1


def test_measured_export_refuses_what_a_tensor_cannot_hold_and_keeps_files(tmp_path):
    with pytest.raises(InputError, match="anisotropic"):
        brdf.export("ggx(alpha=0.1, alpha_y=0.3)", "mitsuba", tmp_path / "a.xml", measured=True)
    with pytest.raises(InputError, match="give the path"):
        brdf.export("lambert", "mitsuba", measured=True)
    with pytest.raises(InputError, match="Mitsuba"):
        brdf.export("lambert", "gltf", tmp_path / "a.gltf", measured=True)
    (tmp_path / "b.bsdf").write_text("mine")
    with pytest.raises(OutputError, match="exists"):
        brdf.export("lambert", "mitsuba", tmp_path / "b.xml", measured=True)
    assert (tmp_path / "b.bsdf").read_text() == "mine" and not (tmp_path / "b.xml").exists()


def test_cli_export_measured_and_the_refusal_that_points_to_it(capsys, tmp_path):
    spec = "lafortune(cx=0.8, cy=0.8, cz=0.5, n=10)"
    status, _, err = run(capsys, "export", spec, "--format", "mitsuba", "-o",
                         str(tmp_path / "r.xml"))
    assert status == 2
    assert_one_error_line(without_progress(err), "no reasonable mitsuba counterpart",
                          "--measured")
    status, out, err = run(capsys, "export", spec, "--format", "mitsuba", "-o",
                           str(tmp_path / "r.xml"), "--measured")
    assert status == 0 and "RGL tensor" in out
    assert (tmp_path / "r.xml").exists() and (tmp_path / "r.bsdf").exists()
