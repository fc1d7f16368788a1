"""Families written in numpy (brdf.CustomModel): declarations and registration, the horizon,
sums with built-in lobes (against separate evaluations and against the kernels' own mixture),
sampling (chi-square), the albedo cubature against a brute-force integral, the physical checks
(which must catch broken families), fitting and MCMC, rendering, export, the CLI, and the
Minnaert family of examples/custom_model.py against the paper's formula."""

import json
import math
import pathlib

import numpy as np
import pytest

import brdf
from brdf.errors import InputError, ParameterError, SpecError
from brdf.models import Choice, Param, mixed
from chi2 import chi2_test
from lobes import hemisphere_integral, incident, upper_directions

EXAMPLE = pathlib.Path(__file__).parents[2] / "examples" / "custom_model.py"


class Tinted(brdf.CustomModel):
    """f = k / pi (1 + t cos(theta_i) cos(theta_o)): reciprocal, smooth, with a choice."""

    name = "test-tinted"
    aliases = ("test_tinted",)
    citation = "a test family"
    PARAMS = (Param("k", 0.4, (0.0, 1.0), per_channel=True),
              Param("t", 0.5, (0.0, 2.0), prior="log", fit_bounds=(0.01, 2.0)),
              Choice("mode", "plain", ("plain", "squared")))
    reciprocal = True
    isotropic = True

    def formula(self, wi, wo):
        c = wi[:, 2] * wo[:, 2]
        c = c * c if self["mode"] == "squared" else c
        return self["k"] / math.pi * (1.0 + self["t"] * c)[:, None]


class Uniform(brdf.CustomModel):
    """Lambert again (f = k / pi), sampled uniformly over the hemisphere (its own sampler)."""

    name = "test-uniform"
    PARAMS = (Param("k", 0.5, (0.0, 1.0)),)
    reciprocal = energy_conserving = isotropic = True

    def formula(self, wi, wo):
        return np.full(len(wi), self["k"] / math.pi)

    def sample_formula(self, wi, u):
        z, phi = u[:, 0], 2.0 * math.pi * u[:, 1]  # uniform in solid angle: z uniform
        s = np.sqrt(1.0 - z * z)
        return np.stack([s * np.cos(phi), s * np.sin(phi), z], -1), np.full(len(u), 0.5 / math.pi)

    def pdf_formula(self, wi, wo):
        return np.full(len(wi), 0.5 / math.pi)


class OneSided(brdf.CustomModel):
    """Broken on purpose: f = k / pi (1 + cos(theta_i)) is not reciprocal."""

    name = "test-one-sided"
    PARAMS = (Param("k", 0.3, (0.0, 1.0)),)
    reciprocal = True  # claimed, wrongly: the check must say so
    isotropic = True

    def formula(self, wi, wo):
        return self["k"] / math.pi * (1.0 + wi[:, 2])


class Bright(brdf.CustomModel):
    """Broken on purpose: f = 1.5 / pi reflects 1.5 times what it receives."""

    name = "test-bright"
    isotropic = True
    energy_conserving = True  # claimed, wrongly

    def formula(self, wi, wo):
        return np.full(len(wi), 1.5 / math.pi)


class Leaky(brdf.CustomModel):
    """A formula that ignores the horizon (and returns NaN below it)."""

    name = "test-leaky"
    isotropic = True

    def formula(self, wi, wo):
        assert np.all(wi[:, 2] > 0.0) and np.all(wo[:, 2] > 0.0)
        return 1.0 / np.sqrt(wi[:, 2] * wo[:, 2]) * 0.01


class Anisotropic(brdf.CustomModel):
    name = "test-anisotropic"

    def formula(self, wi, wo):
        return 0.2 + 0.1 * wi[:, 0] * wo[:, 0]


FAMILIES = (Tinted, Uniform, OneSided, Bright, Leaky, Anisotropic)


def _load_example():
    """The example as ``brdf-fit --plugin`` loads it (the same module name each time, so that
    loading it again replaces its family instead of clashing)."""
    return brdf.models.load_plugin(EXAMPLE)  # registers minnaert


@pytest.fixture(scope="module", autouse=True)
def families():
    """Register the test families and the example's for this module only: other tests list
    every registered family."""
    for cls in FAMILIES:
        brdf.register_model(cls)
    example = _load_example()
    yield example
    for cls in FAMILIES + (example.Minnaert,):
        brdf.unregister_model(cls.name)


@pytest.fixture(scope="module")
def on(families):
    return families.Minnaert


# --- declarations and registration ------------------------------------------------------------

@pytest.mark.parametrize("spec", [
    "test-tinted",
    "test-tinted(k=[0.2,0.3,0.4], t=1.5, mode=squared)",
    "minnaert(albedo=[0.6,0.5,0.4], k=1.3) + lambert(albedo=0.2)",
    "ggx(alpha=0.2, ks=0.3) + test-tinted(k=0.1) + test_tinted(t=0.25)",
])
def test_specs_and_json_round_trip(spec):
    m = brdf.parse(spec)
    assert brdf.parse(str(m)) == m
    assert brdf.from_json(json.dumps(m.to_dict())) == m


def test_flat_names_and_parameter_access():
    m = brdf.parse("test-tinted(k=[0.2,0.3,0.4]) + lambert + test-tinted(t=1)")
    assert list(m.params) == ["test-tinted0.k[0]", "test-tinted0.k[1]", "test-tinted0.k[2]",
                              "test-tinted0.t", "lambert.albedo", "test-tinted2.k",
                              "test-tinted2.t"]
    lobe = m.lobes[0]
    assert lobe["mode"] == "plain" and lobe.channels == 3
    assert lobe.replace(t=2.0)["t"] == 2.0


@pytest.mark.parametrize("spec, exc, fragments", [
    ("test-tinted(t=3)", ParameterError, ["t=3", "outside its bounds [0, 2]"]),
    ("test-tinted(k=nan)", ParameterError, ["must be finite"]),
    ("test-tinted(q=1)", SpecError, ["unknown parameter 'q'", "k, t, mode"]),
    ("test-tinted(mode=cubed)", ParameterError, ["plain, squared"]),
    ("test-tinted(k=[0.1,0.2]) + lambert(albedo=[0.1,0.2,0.3])", ParameterError,
     ["disagree on the number of channels"]),
    ("test-tinte", SpecError, ["unknown model", "test-tinted"]),
])
def test_bad_parameters_give_the_usual_errors(spec, exc, fragments):
    with pytest.raises(exc) as info:
        brdf.parse(spec)
    assert all(f in str(info.value) for f in fragments), str(info.value)
    assert "\n" not in str(info.value)


def _family(**attrs):
    attrs.setdefault("formula", lambda self, wi, wo: wo[:, 2])
    return type("Family", (brdf.CustomModel,), attrs)


@pytest.mark.parametrize("cls, fragments", [
    (_family(name="ggx"), ["'ggx' is taken by the built-in family 'ggx'"]),
    (_family(name="mine", aliases=("diffuse",)), ["'diffuse'", "built-in family 'lambert'"]),
    (_family(name="test-tinted"), ["taken by the custom family", "unregister_model"]),
    (_family(name="two words"), ["must start with a letter"]),
    (type("NoFormula", (brdf.CustomModel,), {"name": "mine"}), ["define formula"]),
    (_family(name="mine", sample_formula=lambda self, wi, u: None), ["both sample_formula"]),
    (_family(name="mine", PARAMS=("k",)), ["Param or Choice"]),
    (brdf.models.Lambert, ["subclass of brdf.CustomModel"]),
])
def test_registration_errors(cls, fragments):
    with pytest.raises(SpecError) as info:
        brdf.register_model(cls)
    assert all(f in str(info.value) for f in fragments), str(info.value)
    assert "mine" not in brdf.models.MODELS


def test_redefining_the_same_class_replaces_it_and_builtins_stay():
    again = type("Tinted", (Tinted,), {"__module__": Tinted.__module__,
                                        "__qualname__": Tinted.__qualname__})
    try:
        assert brdf.register_model(again) is again
        assert type(brdf.parse("test-tinted")) is again
    finally:
        brdf.register_model(Tinted)
    with pytest.raises(SpecError, match="built-in"):
        brdf.unregister_model("lambert")


# --- eval and the horizon ---------------------------------------------------------------------

def test_the_horizon_is_enforced_whatever_the_formula():
    m = brdf.parse("test-leaky")
    wi = np.array([[0.0, 0.6, 0.8], [0.0, 0.6, -0.8], [0.6, 0.0, 0.8], [1.0, 0.0, 0.0]])
    wo = np.array([[0.0, -0.6, 0.8], [0.0, 0.6, 0.8], [0.0, 0.6, -0.8], [0.0, 0.0, 1.0]])
    f = m.eval(wi, wo)
    assert f.shape == (4, 1) and f[0, 0] > 0.0 and np.all(f[1:] == 0.0)
    assert np.all(m.pdf(wi, wo)[1:] == 0.0)
    u = np.random.default_rng(0).random((4, 2))
    _, pdf, weight = m.sample_weighted(np.array([[0.0, 0.6, -0.8]] * 4), u)
    assert np.all(pdf == 0.0) and np.all(weight == 0.0)
    assert np.all(m.albedo(np.array([0.0, 0.6, -0.8])) == 0.0)


def test_eval_broadcasts_like_built_in_models():
    m = brdf.parse("test-tinted(k=[0.2,0.3,0.4])")
    wo = upper_directions(np.random.default_rng(1), 12).reshape(3, 4, 3)
    f = m.eval(incident(30.0), wo)
    assert f.shape == (3, 4, 3)
    assert np.allclose(f[..., 1] / f[..., 0], 1.5)


def test_a_formula_of_the_wrong_shape_is_a_one_line_error():
    bad = _family(name="test-bad-shape", formula=lambda self, wi, wo: np.ones((len(wi), 2)))
    with pytest.raises(InputError, match=r"test-bad-shape.formula returned shape \(1, 2\)"):
        bad().eval(incident(10.0), incident(20.0))


# --- sums with built-in lobes -----------------------------------------------------------------

SUMS = ["minnaert(albedo=[0.6,0.5,0.4], k=1.5) + ggx(alpha=0.3, ks=0.4)",
        "lambert(albedo=0.2) + test-tinted(k=[0.3,0.2,0.1]) + ggx(alpha=0.1, ks=0.2)",
        "test-uniform(k=0.3) + mirror(reflectance=0.5)"]


@pytest.mark.parametrize("spec", SUMS)
def test_a_sum_is_the_sum_of_its_lobes(spec):
    m = brdf.parse(spec)
    assert not m.uses_kernels
    rng = np.random.default_rng(2)
    wi, wo = upper_directions(rng, 500), upper_directions(rng, 500)
    separate = sum(np.broadcast_to(lobe.eval(wi, wo), (500, m.channels)) for lobe in m.lobes)
    assert np.allclose(m.eval(wi, wo), separate, rtol=1e-14, atol=0.0)
    a, err = m.albedo(wi[:5], return_error=True)
    parts = [lobe.albedo(wi[:5], return_error=True) for lobe in m.lobes]
    assert np.allclose(a, sum(p[0] for p in parts), rtol=1e-14)
    assert np.allclose(err, sum(p[1] for p in parts), rtol=1e-14)


@pytest.mark.parametrize("spec", SUMS)
def test_out_receives_a_sums_values_and_density(spec):
    """``out=`` on the numpy path: the same values as a new array, written into ``out``."""
    m = brdf.parse(spec)
    rng = np.random.default_rng(4)
    wi, wo = upper_directions(rng, 40), upper_directions(rng, 40)
    out, dens = np.full((40, m.channels), np.nan), np.full(40, np.nan)
    assert m.eval(wi, wo, out=out) is out
    assert np.array_equal(out, m.eval(wi, wo))
    assert m.pdf(wi, wo, out=dens) is dens
    assert np.array_equal(dens, m.pdf(wi, wo))
    with pytest.raises(InputError, match=r"^out: expected a float64 array shaped \(40,\)"):
        m.pdf(wi, wo, out=np.empty(39))


@pytest.mark.parametrize("spec", ["lambert(albedo=0.4) + ggx(alpha=0.2, ks=0.5)",
                                  "lambert(albedo=[0.5,0.3,0.2]) + mirror(reflectance=0.6) + "
                                  "beckmann(alpha=0.4)"])
def test_the_python_mixture_follows_the_kernels_rule(spec):
    """On built-in lobes, the numpy mixture picks the same lobes and returns the same samples,
    densities and weights as the kernels."""
    m = brdf.parse(spec)
    wi = np.broadcast_to(incident(40.0, 20.0), (2000, 3))
    u = np.random.default_rng(3).random((2000, 2))
    wo, pdf, weight = m.sample_weighted(wi, u)
    wo2, pdf2, weight2 = mixed.sample_weighted(m, np.ascontiguousarray(wi), u)
    assert np.allclose(wo, wo2, rtol=0, atol=1e-12)
    assert np.allclose(pdf, pdf2, rtol=1e-12) and np.array_equal(np.isinf(pdf), np.isinf(pdf2))
    assert np.allclose(weight, weight2, rtol=1e-12)
    assert np.allclose(m.pdf(wi, wo), mixed.pdf(m, wi, wo), rtol=1e-12)


@pytest.mark.parametrize("spec, theta", [
    ("test-tinted(k=0.5, t=1)", 30.0),              # the default cosine sampler
    ("test-uniform", 60.0),                          # a family's own sampler
    ("minnaert(k=1.4) + ggx(alpha=0.2, ks=0.6)", 50.0),
    ("test-uniform(k=0.2) + mirror(reflectance=0.7)", 20.0),
])
def test_sampling_follows_the_pdf(spec, theta):
    m = brdf.parse(spec)
    wi = incident(theta, 30.0)
    result = chi2_test(lambda u: m.sample(np.broadcast_to(wi, (len(u), 3)), u),
                       lambda wo: m.pdf(np.broadcast_to(wi, wo.shape), wo),
                       n_samples=100_000, shape=(16, 32), seed=4)
    assert not result.rejected(1e-3), result.describe()


def test_sample_weights_are_f_cos_over_pdf():
    m = brdf.parse("minnaert(albedo=[0.6,0.5,0.4], k=1.4) + ggx(alpha=0.3, ks=0.3)")
    wi = np.broadcast_to(incident(35.0), (1000, 3))
    wo, pdf, weight = m.sample_weighted(wi, np.random.default_rng(5).random((1000, 2)))
    ok = pdf > 0.0
    assert ok.mean() > 0.9
    assert np.allclose(weight[ok], m.eval(wi, wo)[ok] * (wo[ok, 2] / pdf[ok])[:, None],
                       rtol=1e-12)
    assert np.allclose(pdf[ok], m.pdf(wi, wo)[ok], rtol=1e-12)


def test_the_numpy_cosine_warp_is_the_kernels_warp():
    u = np.random.default_rng(6).random((1000, 2))
    wo, _ = brdf.parse("lambert").sample(incident(20.0), u)
    assert np.allclose(brdf.models.custom.square_to_cosine_hemisphere(u), wo, atol=1e-15)


# --- albedo -----------------------------------------------------------------------------------

@pytest.mark.parametrize("spec", ["minnaert(albedo=0.8, k=1.6)", "test-tinted(t=2)",
                                  "test-uniform(k=0.9) + ggx(alpha=0.25, ks=0.5)"])
@pytest.mark.parametrize("theta", [0.0, 45.0, 80.0])
def test_albedo_matches_a_brute_force_integral(spec, theta):
    m = brdf.parse(spec)
    wi = incident(theta, 10.0)
    exact = hemisphere_integral(lambda wo: m.eval(wi, wo)[:, 0] * wo[:, 2])
    a, err = m.albedo(wi, return_error=True)
    assert abs(a[0] - exact) < 2e-5 * max(1.0, exact)
    assert err[0] < 2e-5 + 1e-9  # tol 1e-5 per lobe
    tight, tight_err = m.albedo(wi, tol=1e-8, return_error=True)
    assert abs(tight[0] - exact) <= max(tight_err[0], 1e-7)


def test_a_tighter_tolerance_spends_more_and_errs_less():
    m = brdf.parse("minnaert(albedo=1, k=2)")
    wi = np.stack([incident(t) for t in (10.0, 50.0, 70.0)])
    loose = m.albedo(wi, tol=1e-3, return_error=True)[1]
    tight = m.albedo(wi, tol=1e-7, return_error=True)[1]
    assert np.all(loose <= 1e-3) and np.all(tight < loose)


# --- the physical checks ----------------------------------------------------------------------

def test_checks_pass_on_good_families_and_sums(on):
    for spec in ("minnaert(albedo=[0.9,0.6,0.3], k=1.7)",
                 "minnaert(albedo=0.6) + ggx(alpha=0.3, ks=0.3)"):
        report = brdf.check(spec, pairs=20_000, theta_steps=20)
        assert report.passed, str(report)
    assert brdf.check("test-anisotropic", pairs=2000).declared["is_anisotropic"] is True


def test_checks_catch_broken_families():
    one_sided = brdf.check("test-one-sided", pairs=20_000, theta_steps=10)
    assert not one_sided["reciprocity"].passed and one_sided["reciprocity"].worst > 0.1
    assert one_sided.declared["reciprocal"] is True  # what it claimed
    bright = brdf.check("test-bright", pairs=2000, theta_steps=10)
    assert not bright["energy"].passed and bright["energy"].worst == pytest.approx(1.5, 1e-6)
    assert not brdf.check("test-bright + lambert", pairs=2000, theta_steps=10).passed


# --- fitting, MCMC ----------------------------------------------------------------------------

def test_fit_recovers_a_custom_lobe_in_a_sum(on):
    truth = brdf.parse("minnaert(albedo=[0.55,0.4,0.3], k=1.5) + "
                       "ggx(alpha=0.25, ks=[0.3,0.3,0.3])")
    table = brdf.measure(truth, "grid:10,30")
    result = brdf.fit(table, "minnaert(k=1.2) + ggx(alpha=0.4, ks=0.5)")
    assert result.converged
    for name, value in truth.params.items():
        assert result.params[name] == pytest.approx(value, rel=1e-4, abs=1e-6), name
    assert result.checks["passed"]


def test_fit_with_fixed_shared_log_parameters_and_a_derivative_free_optimizer():
    table = brdf.measure("test-tinted(k=[0.3,0.4,0.5], t=0.8)", "grid:15,45")
    result = brdf.fit(table, "test-tinted(t=0.2, mode=plain)", optimizer="LN_BOBYQA")
    assert result.params["test-tinted.t"] == pytest.approx(0.8, rel=1e-3)
    shared = brdf.fit(table, "test-tinted", shared=["k"], fix={"t": 0.8})
    assert shared.free == ("test-tinted.k",)
    assert shared.params["test-tinted.k"] == pytest.approx(0.4, rel=2e-2)


def test_mixed_problem_gradient_and_metrics_agree_with_the_kernels():
    """On built-in lobes the central differences reproduce the analytic gradient."""
    from brdf.fitting.mixed_problem import MixedProblem
    from brdf.fitting.problem import Problem
    table = brdf.measure("lambert(albedo=[0.5,0.4,0.3]) + ggx(ks=0.5, alpha=0.2)", "grid:10,20")
    spec = "lambert + ggx(alpha=0.3, ks=0.4)"
    p, q = Problem(table, spec), MixedProblem(table, spec)
    loss, grad = p.loss_and_gradient(p.x0)
    loss2, grad2 = q.loss_and_gradient(p.x0)
    assert loss2 == pytest.approx(loss, rel=1e-12)
    assert np.allclose(grad2, grad, rtol=1e-6, atol=1e-9 * np.abs(grad).max())
    assert q.metrics(p.x0) == pytest.approx(p.metrics(p.x0), rel=1e-12)


def test_mcmc_samples_a_custom_family(on):
    table = brdf.measure("minnaert(albedo=0.5, k=1.4)", "random:300", "additive:0.002",
                         seed=3)
    post = brdf.mcmc(table, "minnaert", seed=1, max_steps=200, walkers=16)
    albedo = post.percentiles["minnaert.albedo"]
    assert post.names[:2] == ("minnaert.albedo", "minnaert.k")
    assert albedo["2.5"] < 0.5 < albedo["97.5"] and albedo["97.5"] - albedo["2.5"] < 0.05


def test_batch_workers_are_told_the_plugins(tmp_path, on):
    from brdf.models.custom import plugin_sources
    assert plugin_sources() == [__name__, str(EXAMPLE)]  # a module name, a plugin file
    brdf.write(brdf.measure("minnaert(albedo=0.4, k=1.3)", "grid:15,45"),
               tmp_path / "on.csv")
    result = brdf.batch([tmp_path / "on.csv"], "minnaert", tmp_path / "out", jobs=1)
    assert [r["status"] for r in result.rows] == ["fitted"]
    assert result.rows[0]["minnaert.k"] == pytest.approx(1.3, rel=1e-4)


# --- rendering, export, the command line ------------------------------------------------------

def test_render_tabulates_custom_materials(on):
    from brdf import render
    a = render.render(render.builtin("sphere", "minnaert(albedo=[0.6,0.5,0.4], k=1)"),
                      spp=32, size=16, seed=2)
    b = render.render(render.builtin("sphere", "lambert(albedo=[0.6,0.5,0.4])"),
                      spp=32, size=16, seed=3)
    mean_a, mean_b = a.image.mean(axis=(0, 1)), b.image.mean(axis=(0, 1))
    assert np.all(np.abs(mean_a - mean_b) < 0.03 * mean_b), (mean_a, mean_b)
    with pytest.raises(InputError, match="anisotropic.*isotropic = True"):
        render.render(render.builtin("sphere", "test-anisotropic"), spp=1, size=4)


def test_a_custom_material_is_tabulated_once_for_its_parameters(monkeypatch):
    """Rendering the same custom-lobe model again reuses its MERL-grid table; other parameters
    (however close), another family of the same name, or a sum with it tabulate anew."""
    from brdf import render
    from brdf.render import scene as S
    monkeypatch.setattr(S, "_CUSTOM_TABLES", S._Recent(S._CUSTOM_TABLES.kept))
    calls = []
    evaluate = Tinted.formula
    monkeypatch.setattr(Tinted, "formula", lambda self, wi, wo: calls.append(1)
                        or evaluate(self, wi, wo))

    def table(spec):
        calls.clear()
        mats = render.builtin("sphere", spec).compile().mats
        return mats.grids[0], len(calls)

    first, n = table("test-tinted(k=0.4, t=0.5)")
    assert n > 0
    again, n = table("test-tinted(k=0.4, t=0.5)")
    assert n == 0 and np.shares_memory(again, first)
    closer, n = table(f"test-tinted(k={0.4 + 1e-15!r}, t=0.5)")
    assert n > 0 and not np.array_equal(closer, first)
    _, n = table("test-tinted(k=0.4, t=0.5) + lambert(albedo=0.1)")
    assert n > 0
    assert len(S._CUSTOM_TABLES) == S._CUSTOM_TABLES.kept  # the oldest was let go


@pytest.mark.parametrize("format", ["mitsuba", "gltf"])
def test_export_of_a_custom_lobe_is_a_one_line_error(on, format):
    with pytest.raises(InputError) as info:
        brdf.export("minnaert + ggx", format)
    assert "custom lobe(s) minnaert" in str(info.value) and "merl" in str(info.value)
    assert "\n" not in str(info.value)


def test_the_cli_loads_plugins(capsys):
    from brdf_cli.main import main
    assert main(["--plugin", str(EXAMPLE), "models"]) == 0
    out = capsys.readouterr().out
    assert "minnaert" in out and "Minnaert 1941" in out
    assert main(["check", "--plugin", str(EXAMPLE), "--json", "minnaert(k=1.2)"]) == 0
    assert json.loads(capsys.readouterr().out)["passed"] is True
    assert main(["--plugin", "no/such/plugin.py", "models"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "plugin no/such/plugin.py: no such file" in err


# --- the example's Minnaert family ------------------------------------------------------------

@pytest.mark.parametrize("angles", [(30, 0, 60, 0), (60, 0, 30, 180), (0, 0, 50, 90),
                                    (80, 0, 20, 30), (5, 45, 85, 60)])
@pytest.mark.parametrize("k", [1.0, 1.4, 2.5])
def test_minnaert_is_the_papers_law(on, angles, k):
    """Minnaert 1941, eq. 2: radiance I_0 cos^k(i) cos^(k-1)(e) per unit irradiance cos(i),
    normalised to albedo 0.7 at normal incidence by (k + 1) / (2 pi)."""
    ti, pi_, to, po = angles
    f = on(albedo=0.7, k=k).eval(incident(ti, pi_), incident(to, po))[0]
    ci, co = math.cos(math.radians(ti)), math.cos(math.radians(to))
    law = ci ** k * co ** (k - 1.0) / ci
    assert f == pytest.approx(0.7 * (k + 1.0) / (2.0 * math.pi) * law, rel=1e-12)


def test_minnaert_at_k_one_is_lambert_and_is_reciprocal(on):
    rng = np.random.default_rng(7)
    wi, wo = upper_directions(rng, 2000), upper_directions(rng, 2000)
    albedo = [0.8, 0.5, 0.2]
    assert np.allclose(on(albedo=albedo, k=1.0).eval(wi, wo),
                       brdf.models.Lambert(albedo=albedo).eval(wi, wo), rtol=1e-15, atol=0)
    m = on(albedo=albedo, k=2.2)
    assert np.array_equal(m.eval(wi, wo), m.eval(wo, wi))


@pytest.mark.parametrize("theta", [0.0, 40.0, 75.0, 88.0])
def test_minnaert_albedo_is_its_closed_form(on, theta):
    """The albedo at theta_i is albedo cos^(k-1)(theta_i): the normalisation checked, to the
    cubature's absolute tolerance (1e-5)."""
    m = on(albedo=0.9, k=1.8)
    a = m.albedo(incident(theta, 15.0))[0]
    assert a == pytest.approx(0.9 * math.cos(math.radians(theta)) ** 0.8, abs=1e-5)
