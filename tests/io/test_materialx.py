"""brdf.export(..., "materialx"): documents load and validate with MaterialX's own Python API
against its standard library's open_pbr_surface; the stated deviation is the one of the written
inputs under openpbr_eval; openpbr_eval itself follows the OpenPBR 1.1 specification (checked
against our compiled models where the two are the same BRDF, furnace tests, closed forms
against quadrature); models without a counterpart are one-line errors; the CLI."""

import math

import numpy as np
import pytest

import brdf
from brdf.errors import InputError, OutputError
from brdf.io import materialx as mtlx
from brdf.io.export import EXPORTABLE, FORMATS, check_families, relative_deviation
from lobes import hemisphere_integral, upper_directions
from test_cli import assert_one_error_line, run

NODEDEFS = {"materialx": "ND_open_pbr_surface_surfaceshader",
            "materialx-standard-surface": "ND_standard_surface_surfaceshader"}
EVALUATORS = {"materialx": mtlx.openpbr_eval,
              "materialx-standard-surface": mtlx.standard_surface_eval}


@pytest.fixture(scope="module")
def mx():
    return pytest.importorskip("MaterialX")


@pytest.fixture(scope="module")
def stdlib(mx):
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    assert all(lib.getNodeDef(name) is not None for name in NODEDEFS.values())
    return lib


@pytest.fixture(scope="module")
def pairs():
    rng = np.random.default_rng(11)
    return upper_directions(rng, 60), upper_directions(rng, 60)


def load(mx, stdlib, path, format="materialx"):
    """The document at ``path`` read by MaterialX, validated with the standard library, and
    the shader's inputs as openpbr_eval (standard_surface_eval) takes them, read back through
    MaterialX."""
    doc = mx.createDocument()
    mx.readFromXmlFile(doc, str(path))
    doc.importLibrary(stdlib)
    valid, message = doc.validate()
    assert valid, message
    (material,) = doc.getMaterialNodes()
    assert material.getCategory() == "surfacematerial"
    (shader,) = mx.getShaderNodes(material)
    nodedef = shader.getNodeDef()
    assert nodedef.getName() == NODEDEFS[format]
    params = {}
    for given in shader.getInputs():
        declared = nodedef.getActiveInput(given.getName())
        assert declared is not None, given.getName()
        assert given.getType() == declared.getType(), given.getName()
        if given.getNodeName():
            node = doc.getNode(given.getNodeName())
            assert node.getCategory() == "bitangent" and given.getName() == "geometry_tangent"
            params[given.getName()] = "bitangent"
        else:
            value = given.getValue()
            params[given.getName()] = tuple(value.asTuple()) if hasattr(
                value, "asTuple") else float(value)
    return params


SPECS = [
    "lambert(albedo=[0.5,0.4,0.3])",
    "oren-nayar(albedo=[0.6,0.5,0.4], sigma=0.3)",
    "ggx(alpha=0.2, masking=height-correlated, fresnel=schlick(f0=[0.9,0.7,0.4]))",
    "ggx(alpha=0.1, alpha_y=0.3, masking=height-correlated, fresnel=schlick(f0=0.5))",
    "ggx(ks=0.9, alpha=0.3, fresnel=conductor(eta=[0.2,0.5,1.2], k=[3,2.5,2]))",
    "ggx(alpha=0.3, alpha_y=0.1, masking=height-correlated, fresnel=dielectric(eta=1.5))",
    "lambert(albedo=[0.5,0.4,0.3]) + ggx(ks=0.3, alpha=0.2)",
    "ggx(alpha=0.15, fresnel=schlick(f0=0.04)) + lambert(albedo=0.6)",
    "lambert(albedo=0.4) + ggx(alpha=0.2, alpha_y=0.05, fresnel=dielectric(eta=1.45))",
    "oren-nayar(albedo=0.5, sigma=0.5) + beckmann(ks=0.2, alpha=0.2)",
]


@pytest.mark.parametrize("format", NODEDEFS)
@pytest.mark.parametrize("spec", SPECS)
def test_documents_validate_and_the_stated_deviation_is_that_of_the_written_inputs(
        mx, stdlib, tmp_path, spec, format):
    path = tmp_path / "m.mtlx"
    result = brdf.export(spec, format, path)
    assert result.format == format
    params = load(mx, stdlib, path, format)
    evaluate = EVALUATORS[format]
    assert params.keys() == result.equivalent.keys()
    for key, value in result.equivalent.items():  # MaterialX holds float32 values
        assert params[key] == (value if isinstance(value, str) else pytest.approx(value, rel=1e-7))
    model = brdf.parse(spec)
    assert result.deviation == pytest.approx(relative_deviation(
        model.eval, lambda wi, wo: evaluate(result.equivalent, wi, wo)), rel=1e-12, abs=1e-15)
    assert result.deviation == pytest.approx(relative_deviation(
        model.eval, lambda wi, wo: evaluate(params, wi, wo)), rel=1e-4, abs=1e-5)
    text = path.read_text(encoding="utf-8")
    assert f"{result.deviation:.3g}" in text.split("-->")[0]
    assert ("APPROXIMATE" in text) == (not result.exact)
    assert all(0.0 <= c <= 1.0 for key in ("base_color", "specular_color") if key in params
               for c in params[key])


SS_EXACT = [
    "lambert(albedo=[0.5,0.4,0.3])",
    "oren-nayar(albedo=[0.6,0.5,0.4], sigma=0.3)",
    "oren-nayar(albedo=0.5, sigma=1.0)",
    "ggx(alpha=0.2, masking=height-correlated, fresnel=conductor(eta=[0.2,0.5,1.2], k=[3,2.5,2]))",
    "ggx(alpha=0.1, alpha_y=0.3, masking=height-correlated, fresnel=conductor(eta=0.2, k=3))",
    "ggx(ks=0.8, alpha=0.3, alpha_y=0.1, masking=height-correlated, fresnel=dielectric(eta=1.5))",
]


@pytest.mark.parametrize("spec", SS_EXACT)
def test_exact_standard_surface_exports_evaluate_like_our_compiled_models(pairs, spec):
    """Standard Surface as MaterialX evaluates it holds Oren & Nayar's eq. 30 and conductors
    (through Gulbrandsen's artistic_ior) exactly: its evaluator and our kernels agree."""
    result = brdf.export(spec, "materialx-standard-surface")
    assert result.exact and result.deviation <= 1e-9, result.notes
    wi, wo = pairs
    ours = np.broadcast_to(brdf.parse(spec).eval(wi, wo), (len(wi), 3))
    np.testing.assert_allclose(mtlx.standard_surface_eval(result.equivalent, wi, wo), ours,
                               rtol=1e-10, atol=1e-14)


def test_conductor_fresnel_and_gulbrandsens_map_and_its_inverse():
    from brdf.models.fresnel import conductor_reflectance
    for cos in (0.0, 0.1, 0.5, 1.0):
        for n, k in ((0.2, 3.0), (1.2, 2.0), (2.5, 0.5)):
            assert mtlx.conductor_fresnel(cos, n, k) == pytest.approx(
                conductor_reflectance(cos, n, k), rel=1e-12)
    n, k = np.array([0.2, 0.5, 1.2]), np.array([3.0, 2.5, 2.0])
    r, g = mtlx.artistic_ior_inverse(n, k)
    assert np.all((g >= 0.0) & (g <= 1.0))
    np.testing.assert_allclose(mtlx.artistic_ior(r, g), (n, k), rtol=1e-12)
    np.testing.assert_allclose(mtlx.conductor_fresnel(1.0, n, k), r, rtol=1e-12)  # r = F0


def test_standard_surface_plastic_keeps_the_specular_weight_in_the_layering():
    """MaterialX's dielectric_bsdf weighs the base by 1 - specular E_spec: a Fresnel-free lobe
    maps to specular = ks with a near-1 Fresnel, closer than OpenPBR can come."""
    spec = "lambert(albedo=[0.5,0.4,0.3]) + ggx(ks=0.3, alpha=0.2, masking=height-correlated)"
    result = brdf.export(spec, "materialx-standard-surface")
    p = result.equivalent
    assert p["metalness"] == 0.0 and p["specular"] * min(p["specular_color"]) > 0.0
    assert not result.exact and result.deviation < 0.03  # measured 0.017
    assert result.deviation < brdf.export(spec, "materialx").deviation  # OpenPBR: 0.052


EXACT = [
    "lambert(albedo=[0.5,0.4,0.3])",
    "ggx(alpha=0.2, masking=height-correlated, fresnel=schlick(f0=[0.9,0.7,0.4]))",
    "ggx(ks=0.7, alpha=0.1, alpha_y=0.3, masking=height-correlated, fresnel=schlick(f0=0.5))",
    "ggx(ks=0.8, alpha=0.3, alpha_y=0.1, masking=height-correlated, fresnel=dielectric(eta=1.5))",
    "ggx(ks=0.5, alpha=0.25, masking=height-correlated)",
    "oren-nayar(albedo=[0.5,0.4,0.3], sigma=0)",
]


@pytest.mark.parametrize("spec", EXACT)
def test_exact_exports_evaluate_like_our_compiled_models(pairs, spec):
    """openpbr_eval (numpy, from the spec) and our numba kernels are separate codes: where the
    BRDFs are the same they agree to rounding, which checks D, G2, F82 and the anisotropy."""
    result = brdf.export(spec, "materialx")
    assert result.exact and result.deviation <= 1e-9, result.notes
    wi, wo = pairs
    ours = np.broadcast_to(brdf.parse(spec).eval(wi, wo), (len(wi), 3))
    np.testing.assert_allclose(mtlx.openpbr_eval(result.equivalent, wi, wo), ours, rtol=1e-10,
                               atol=1e-14)


def test_lambert_is_base_color_over_pi_with_the_specular_layer_off(pairs):
    result = brdf.export("lambert(albedo=[0.5,0.4,0.3])", "materialx")
    p = result.equivalent
    assert p["specular_weight"] == 0.0 and p["base_color"] == (0.5, 0.4, 0.3)
    assert p["base_weight"] == 1.0 and "base_diffuse_roughness" not in p
    wi, wo = pairs
    f = mtlx.openpbr_eval(p, wi, wo)
    assert np.array_equal(f, np.broadcast_to(np.array([0.5, 0.4, 0.3]) / math.pi, f.shape))


# --- openpbr_eval against the specification -----------------------------------------------------

def test_f82_tint_is_schlick_at_tint_one_meets_its_edge_and_a_white_metal_reflects_all():
    mu = np.linspace(0.0, 1.0, 101)
    f0 = np.array([0.9, 0.6, 0.3])
    schlick = f0 + (1.0 - f0) * (1.0 - mu[:, None]) ** 5
    np.testing.assert_allclose(mtlx.f82_tint(f0, 1.0, mu[:, None]), schlick, rtol=1e-15)
    tint = np.array([0.8, 0.5, 0.2])
    edge = mtlx.f82_tint(f0, tint, 1.0 / 7.0)  # F(mu-bar) = tint x Schlick(mu-bar), spec "Metal"
    np.testing.assert_allclose(edge, tint * (f0 + (1.0 - f0) * (6.0 / 7.0) ** 5), rtol=1e-14)
    np.testing.assert_allclose(mtlx.f82_tint(1.0, 1.0, mu), 1.0, rtol=1e-15)
    # a white metal at the smallest roughness: its lobe is our Fresnel-free GGX
    p = {"base_metalness": 1.0, "base_color": (1.0, 1.0, 1.0), "specular_roughness": 0.01}
    wi = brdf.geometry.directions_from_degrees(np.array([10.0, 40.0]), np.array([0.0, 0.0]))
    wo = brdf.geometry.directions_from_degrees(np.array([10.0, 40.0]), np.array([180.0, 180.0]))
    ggx = brdf.parse("ggx(alpha=0.0001, masking=height-correlated)")
    np.testing.assert_allclose(mtlx.openpbr_eval(p, wi, wo),
                               np.broadcast_to(ggx.eval(wi, wo), (2, 3)), rtol=1e-10)


def test_dielectric_fresnel_and_the_specular_weight_modulation():
    from brdf.models.fresnel import dielectric_reflectance
    for cos in (0.0, 0.05, 0.3, 0.7, 1.0):
        for eta in (0.7, 1.33, 1.5, 2.4):
            assert mtlx.dielectric_fresnel(cos, eta) == pytest.approx(
                dielectric_reflectance(cos, eta), rel=1e-12, abs=1e-15)
    f0 = ((1.5 - 1.0) / 2.5) ** 2
    for weight in (0.0, 0.25, 0.5, 1.0, 3.0):  # F0 scales linearly (spec eq. modulated_ior)
        eta = mtlx.modulated_ior(1.5, weight)
        assert mtlx.dielectric_fresnel(1.0, eta) == pytest.approx(weight * f0, rel=1e-12)
    assert math.isinf(mtlx.modulated_ior(1.5, 1.0 / f0))  # the clamp at 1 / F_s: F = 1
    assert mtlx.dielectric_fresnel(1.0, mtlx.ior_of_f0(0.3)) == pytest.approx(0.3)


def test_anisotropy_mapping_inverts_the_specs_formula():
    for at, ab in ((0.3, 0.3), (0.3, 0.1), (0.5, 0.01), (1.0, 0.2)):
        r, a = mtlx.openpbr_roughness(at, ab)
        assert mtlx.openpbr_alphas(r, a) == pytest.approx((at, ab), rel=1e-12)
        assert at ** 2 + ab ** 2 == pytest.approx(2.0 * r ** 4)  # the spec's stated invariant


def test_fujii_albedo_closed_forms_match_quadrature():
    """E_FON and its average (Portsmouth et al. 2025) against a midpoint quadrature of
    (A + B s / t) cos / pi over the hemisphere."""
    n = 400
    theta = (np.arange(n) + 0.5) * (0.5 * math.pi / n)
    phi = (np.arange(n) + 0.5) * (math.pi / n)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    for sigma in (0.2, 0.6, 1.0):
        a = 1.0 / (1.0 + (0.5 - 2.0 / (3.0 * math.pi)) * sigma)
        for mu in (0.05, 0.4, 0.9, 1.0):
            s = np.sin(t) * math.sqrt(1.0 - mu * mu) * np.cos(p)
            ratio = np.where(s > 0.0, s / np.maximum(np.cos(t), mu), s)
            e = np.sum((a + sigma * a * ratio) * np.cos(t) * np.sin(t)) * (
                0.5 * math.pi / n) * (math.pi / n) * 2.0 / math.pi
            assert mtlx.fon_albedo(mu, sigma) == pytest.approx(e, abs=2e-5)
        nodes, weights = np.polynomial.legendre.leggauss(48)
        mus = 0.5 * (nodes + 1.0)
        average = np.sum(weights * mus * mtlx.fon_albedo(mus, sigma))
        assert mtlx.fon_average_albedo(sigma) == pytest.approx(average, rel=1e-6)


@pytest.mark.parametrize("sigma", [0.0, 0.5, 1.0])
def test_white_eon_passes_the_furnace_test(sigma):
    """EON with rho = 1 reflects all the light at every incidence (its design)."""
    p = {"specular_weight": 0.0, "base_color": (1.0, 1.0, 1.0), "base_diffuse_roughness": sigma}
    for theta in (0.0, 45.0, 80.0):
        wo = brdf.geometry.directions_from_degrees(theta, 30.0)
        e = hemisphere_integral(lambda w: mtlx.openpbr_eval(
            p, w, np.broadcast_to(wo, w.shape))[:, 0] * w[:, 2])
        assert e == pytest.approx(1.0, abs=1e-4)


@pytest.mark.parametrize("alpha,alpha_y", [(0.2, 0.2), (0.5, 0.5), (0.4, 0.1)])
def testspecular_albedo_quadrature_matches_our_models_albedo(alpha, alpha_y):
    """E_spec(wo), which weighs the diffuse layer, against the adaptive cubature of our GGX
    with the same Fresnel and masking (a separate integrator)."""
    model = brdf.parse(f"ggx(alpha={alpha}, alpha_y={alpha_y}, masking=height-correlated, "
                       "fresnel=dielectric(eta=1.5))")
    wo = brdf.geometry.directions_from_degrees(np.array([0.0, 30.0, 60.0, 80.0, 60.0]),
                                               np.array([0.0, 0.0, 0.0, 0.0, 60.0]))
    ours = model.albedo(wo)[:, 0]
    theirs = mtlx.specular_albedo(wo, alpha, alpha_y, 1.5)
    np.testing.assert_allclose(theirs, ours, rtol=5e-3)


@pytest.mark.parametrize("roughness", [0.3, 0.7])
def test_white_glossy_diffuse_reflects_at_most_all_and_nearly_all(roughness):
    """A white dielectric (base_color 1, Lambertian) under OpenPBR's albedo scaling reflects
    E_spec + (1 - E_spec) = 1 of the light: within the quadrature's error of 1."""
    p = {"base_color": (1.0, 1.0, 1.0), "specular_roughness": roughness, "specular_ior": 1.5}
    for theta in (0.0, 50.0, 75.0):
        wo = brdf.geometry.directions_from_degrees(theta, 0.0)
        e = hemisphere_integral(lambda w: mtlx.openpbr_eval(
            p, w, np.broadcast_to(wo, w.shape))[:, 0] * w[:, 2])
        assert 0.99 < e <= 1.0 + 3e-3


def test_openpbr_eval_refuses_layers_it_does_not_evaluate():
    with pytest.raises(InputError, match="coat_weight"):
        mtlx.openpbr_eval({"coat_weight": 1.0}, np.array([0, 0, 1.0]), np.array([0, 0, 1.0]))


# --- mapping figures ----------------------------------------------------------------------------

def test_plastic_compensates_the_albedo_scaling_and_states_it():
    result = brdf.export("lambert(albedo=[0.5,0.4,0.3]) + ggx(ks=0.3, alpha=0.2)", "materialx")
    p = result.equivalent
    assert p["base_metalness"] == 0.0
    # ks at normal incidence: specular_color x F0(specular_ior)
    f0 = mtlx.dielectric_fresnel(1.0, p["specular_ior"])
    assert np.multiply(p["specular_color"], f0) == pytest.approx((0.3,) * 3)
    # the diffuse layer is weighted by 1 - E_spec (E_spec near 0.4): base_color > albedo
    assert np.all(np.array(p["base_color"]) > np.array([0.5, 0.4, 0.3]) * 1.2)
    assert any("1 - E_spec" in n for n in result.notes)
    assert not result.exact and result.deviation < 0.08  # measured 0.061


def test_specular_color_tints_the_reflection_not_the_light_into_the_base():
    """spec 1.1, "Dielectric base": a black specular_color removes the highlight but the base
    still gets only 1 - E_spec of the light (the untinted Fresnel's share)."""
    p = {"base_color": (1.0, 1.0, 1.0), "specular_roughness": 0.5, "specular_ior": 2.0,
         "specular_color": (0.0, 0.0, 0.0)}
    for theta in (0.0, 70.0):
        wo = brdf.geometry.directions_from_degrees(theta, 0.0)
        e = hemisphere_integral(lambda w: mtlx.openpbr_eval(
            p, w, np.broadcast_to(wo, w.shape))[:, 0] * w[:, 2])
        e_spec = float(mtlx.specular_albedo(wo, 0.25, 0.25, 2.0))
        assert e_spec > 0.1 and e == pytest.approx(1.0 - e_spec, rel=1e-6)


def test_bright_plastic_is_clamped_and_exported_with_its_deviation():
    result = brdf.export("lambert(albedo=0.9) + ggx(ks=0.6, alpha=0.3)", "materialx")
    assert result.equivalent["base_color"] == (1.0, 1.0, 1.0)
    assert any("clamped" in n for n in result.notes)
    assert result.deviation > 0.1  # measured 0.31


def test_metal_with_an_exact_fresnel_gets_the_f82_tint_of_its_curve():
    result = brdf.export("ggx(alpha=0.3, masking=height-correlated, "
                         "fresnel=conductor(eta=[0.2,0.5,1.2], k=[3,2.5,2]))", "materialx")
    from brdf.models.fresnel import conductor_reflectance
    p = result.equivalent
    f0 = [conductor_reflectance(1.0, e, k) for e, k in ((0.2, 3), (0.5, 2.5), (1.2, 2))]
    assert p["base_metalness"] == 1.0 and p["base_color"] == pytest.approx(f0)
    edge = [conductor_reflectance(1.0 / 7.0, e, k) for e, k in ((0.2, 3), (0.5, 2.5), (1.2, 2))]
    assert mtlx.f82_tint(np.array(p["base_color"]), np.array(p["specular_color"]),
                         1.0 / 7.0) == pytest.approx(edge)
    assert not result.exact and result.deviation < 0.08  # measured 0.052


def test_oren_nayar_maps_to_eon_roughness_and_states_the_deviation():
    result = brdf.export("oren-nayar(albedo=0.5, sigma=0.3)", "materialx")
    p = result.equivalent
    assert 0.0 < p["base_diffuse_roughness"] <= 1.0 and p["specular_weight"] == 0.0
    assert any("EON" in n for n in result.notes) and not result.exact
    assert 0.01 < result.deviation < 0.15  # measured 0.116: the backscattering side differs


def test_rougher_along_y_turns_the_tangent_to_the_bitangent():
    result = brdf.export("ggx(alpha=0.1, alpha_y=0.3, masking=height-correlated, "
                         "fresnel=schlick(f0=0.5))", "materialx")
    assert result.equivalent["geometry_tangent"] == "bitangent"
    assert "<bitangent " in result.text and 'nodename="brdf_bitangent"' in result.text


# --- refusals, files, CLI -----------------------------------------------------------------------

def test_the_export_module_lists_the_same_shapes():
    for format in NODEDEFS:
        assert EXPORTABLE[format] == mtlx.EXPORTABLE and FORMATS[format] == ".mtlx"


@pytest.mark.parametrize("spec", ["phong(ks=0.5, n=20)", "lambert + ggx + ggx(alpha=0.05)"])
def test_models_without_a_counterpart_export_as_the_closest_material(mx, stdlib, tmp_path,
                                                                     spec):
    from brdf.io.closest_material import MAX_ERROR, relative_rms
    model = brdf.parse(spec)
    for format, evaluate in (("materialx", mtlx.openpbr_eval),
                             ("materialx-standard-surface", mtlx.standard_surface_eval)):
        path = tmp_path / f"{format}.mtlx"
        result = brdf.export(spec, format, path)
        assert not result.exact and result.closest and "closest" in result.notes[0]
        load(mx, stdlib, path, format)  # a valid document, every input on the nodedef

        def theirs(wi, wo):
            return evaluate(result.equivalent, wi, wo)
        assert 0.0 < result.error <= MAX_ERROR
        assert result.error == pytest.approx(relative_rms(model, theirs))


def test_delta_lobes_are_one_line_errors_naming_the_format_that_holds_them():
    for call in (lambda: brdf.export("lambert + mirror", "materialx"),
                 lambda: check_families("mirror", "materialx-standard-surface")):
        with pytest.raises(InputError) as info:
            call()
        message = str(info.value)
        assert "\n" not in message and "delta lobe" in message and "mitsuba" in message


def test_writes_atomically_and_replaces_only_with_force(tmp_path):
    path = tmp_path / "paint.mtlx"
    result = brdf.export("lambert(albedo=0.3)", "materialx", path)
    assert result.path == str(path) and path.read_text(encoding="utf-8") == result.text
    with pytest.raises(OutputError, match="exists"):
        brdf.export("lambert(albedo=0.4)", "materialx", path)
    assert "0.3" in path.read_text()
    brdf.export("lambert(albedo=0.4)", "materialx", path, force=True)
    assert "0.4" in path.read_text() and sorted(p.name for p in tmp_path.iterdir()) == [
        "paint.mtlx"]


def test_cli_export_writes_a_valid_document_and_exits_by_exactness(capsys, mx, stdlib,
                                                                   tmp_path):
    target = tmp_path / "x.mtlx"
    status, out, err = run(capsys, "export", "lambert(albedo=0.5)", "--format", "materialx",
                           "-o", str(target))
    assert status == 0 and err == "" and "materialx export" in out and "exact" in out
    assert load(mx, stdlib, target)["base_color"] == (0.5, 0.5, 0.5)
    status, out, err = run(capsys, "export", "lambert(albedo=0.5) + ggx(ks=0.3, alpha=0.2)",
                           "--format", "materialx", "-o", str(tmp_path / "p.mtlx"))
    assert status == 0 and err == "" and "approximate (relative RMS difference" in out
    status, out, err = run(capsys, "export", "oren-nayar(albedo=0.5, sigma=0.3)", "--format",
                           "materialx-standard-surface", "-o", str(tmp_path / "clay.mtlx"))
    assert status == 0 and err == ""
    assert load(mx, stdlib, tmp_path / "clay.mtlx", "materialx-standard-surface")[
        "diffuse_roughness"] == pytest.approx(0.3)
    status, _, err = run(capsys, "export", "mirror", "--format", "materialx", "-o",
                         str(tmp_path / "mirror.mtlx"))
    assert status == 2
    assert_one_error_line(err, "no materialx equivalent", "delta lobe")
    assert not (tmp_path / "mirror.mtlx").exists()


@pytest.mark.parametrize("old,new", [
    ('name="base_color"', 'name="base_colour"'),           # not an input of the nodedef
    ('name="specular_roughness" type="float"', 'name="specular_roughness" type="color3"'),
])
def test_the_document_check_catches_names_and_types_off_the_nodedef(mx, stdlib, tmp_path, old,
                                                                     new):
    text = brdf.export("lambert(albedo=0.5) + ggx(ks=0.3, alpha=0.2)", "materialx").text
    assert old in text
    path = tmp_path / "broken.mtlx"
    path.write_text(text.replace(old, new), encoding="utf-8")
    with pytest.raises(AssertionError):
        load(mx, stdlib, path)


def test_roughness_beyond_openpbrs_range_is_capped_and_stated():
    result = brdf.export("ggx(alpha=2, masking=height-correlated, fresnel=schlick(f0=0.9))",
                         "materialx")
    assert result.equivalent["specular_roughness"] == 1.0
    assert any("capped at 1" in n for n in result.notes) and not result.exact


def test_cli_fit_exports_a_materialx_document_beside_the_report(capsys, mx, stdlib, tmp_path):
    table = tmp_path / "plastic.csv"
    brdf.write(brdf.measure("lambert(albedo=[0.5,0.4,0.3]) + ggx(ks=0.3, alpha=0.2)",
                            "grid:15,30"), table)
    report = tmp_path / "fit.json"
    status, out, _ = run(capsys, "fit", str(table), "lambert + ggx(alpha=0.4)", "--shared",
                         "ks", "-o", str(report), "--export", "materialx")
    assert status == 0 and "materialx export" in out
    document = tmp_path / "fit.mtlx"
    assert brdf.load_report(report).spec in document.read_text(encoding="utf-8")
    assert load(mx, stdlib, document)["base_metalness"] == 0.0
