"""brdf.fit and its Problem: free parameters and their layout, the analytic gradient against a
slow one-coordinate-at-a-time reference and against central differences of the compiled loss for
every loss and family (with shared, fixed and log-scaled parameters), recovery of known parameters from noise-free
synthetic tables, the energy constraint, reproducibility, option errors and the CLI."""

import json

import numpy as np
import pytest

import brdf
from brdf._threads import using_threads
from brdf.errors import BRDFError, InputError, ParameterError
from brdf.fitting import losses
from brdf.fitting.problem import Problem
from test_cli import assert_one_error_line, run, without_progress

GRID = "grid:10,20"
RGB_TRUTH = "lambert(albedo=[0.5,0.4,0.3]) + ggx(ks=[0.6,0.5,0.4], alpha=0.2)"


@pytest.fixture(scope="module")
def rgb_table():
    return brdf.measure(RGB_TRUTH, GRID)


# --- the problem: what is free, and the layout ------------------------------------------------

def test_free_parameters_expand_per_channel_and_share_on_request(rgb_table):
    p = Problem(rgb_table, "lambert + ggx(alpha=0.3)")
    assert p.names == ("lambert.albedo[0]", "lambert.albedo[1]", "lambert.albedo[2]",
                       "ggx.ks[0]", "ggx.ks[1]", "ggx.ks[2]", "ggx.alpha")
    shared = Problem(rgb_table, "lambert + ggx(alpha=0.3)", shared=("ks", "ggx.alpha"))
    assert shared.names == ("lambert.albedo[0]", "lambert.albedo[1]", "lambert.albedo[2]",
                            "ggx.ks", "ggx.alpha")
    fixed = Problem(rgb_table, "lambert + ggx", fix={"alpha": 0.25, "lambert.albedo[1]": 0.4})
    assert "ggx.alpha" not in fixed.names and "lambert.albedo[1]" not in fixed.names
    model = fixed.model(fixed.x0)
    assert model.params["ggx.alpha"] == 0.25 and model.params["lambert.albedo[1]"] == 0.4


def test_log_parameters_are_optimised_as_logarithms(rgb_table):
    p = Problem(rgb_table, "lambert + ggx(alpha=0.3)", bounds={"ggx.alpha": (0.05, 0.8)})
    k = p.names.index("ggx.alpha")
    assert p.x0[k] == pytest.approx(np.log(0.3))
    assert (p.lower[k], p.upper[k]) == pytest.approx((np.log(0.05), np.log(0.8)))
    assert p.model(p.x0).params["ggx.alpha"] == pytest.approx(0.3)


SPECS = [
    "lambert + ggx(alpha=0.3, fresnel=schlick(f0=[0.04,0.05,0.06]))",
    "lambert + beckmann(alpha=0.2, alpha_y=0.4, fresnel=conductor(eta=0.2, k=3))",
    "ggx(alpha=0.3)",  # alpha_y unset: it follows alpha in the packed parameters
    "ward(rho_s=0.3, alpha=0.2, variant=gmd)",
    "blinn-phong(ks=0.5, n=20, normalization=approx)",
    "ashikhmin-shirley(rd=[0.5,0.4,0.3], rs=0.1, nu=50, nv=200)",
    "lafortune(cx=-0.8, cy=-0.8, cz=0.9, n=15) + lambert",
    "modified-phong(ks=0.5, n=10) + lambert(albedo=0.2)",
]


@pytest.mark.parametrize("spec", SPECS)
def test_packed_parameters_agree_with_the_model_they_build(rgb_table, spec):
    p = Problem(rgb_table, spec)
    # a fifth of the way to random points of the box: the whole box of Lafortune's lobe holds
    # coefficients whose power overflows (the model rejects those)
    rng = np.random.default_rng(3)
    for x in [p.x0, *(p.x0 + 0.2 * (p.random_x(rng, 3) - p.x0))]:
        assert np.array_equal(p.packed(x)[0], p.model(x).compile(3).params)


def slow_gradient(p, x, h=1e-6):
    """One coordinate at a time, through Model.eval and the numpy metric."""
    def loss(x):
        return losses.evaluate(p.terms, p.model(x).eval(p.samples.wi, p.samples.wo))
    grad = np.empty(len(x))
    for i in range(len(x)):
        up, down = x.copy(), x.copy()
        up[i] += h
        down[i] -= h
        grad[i] = (loss(up) - loss(down)) / (2.0 * h)
    return grad


@pytest.mark.parametrize("spec,loss", [(SPECS[0], "cosine-l2"), (SPECS[1], "log"),
                                        (SPECS[4], "relative-l2"), (SPECS[5], "l2"),
                                        (SPECS[6], "cosine-l2")])
def test_gradient_matches_a_slow_reference(rgb_table, spec, loss):
    p = Problem(rgb_table, spec, loss=loss)
    x = p.random_x(np.random.default_rng(7), 1)[0]
    x = p.lower + 0.1 * (p.upper - p.lower) + 0.8 * (x - p.lower)  # away from the bounds
    value, grad = p.loss_and_gradient(x)
    assert value == pytest.approx(losses.evaluate(p.terms, p.model(x).eval(
        p.samples.wi, p.samples.wo)), rel=1e-12)
    ref = slow_gradient(p, x)
    assert np.abs(grad - ref).max() <= 1e-5 * np.abs(ref).max()


def per_pair_loss_and_gradient(p, x):
    """The loss and its gradient from the per-pair derivatives of ``grad_array`` (a kernel of
    its own, one pair at a time) and the chain rule in numpy, summed in another order."""
    from brdf.models import _kernels
    s, t = p.samples, p.terms
    params = p.packed(x)[0]
    f = np.zeros(s.values.shape)
    d = np.zeros((len(params),) + f.shape)
    _kernels.grad_array(p._kinds, p._offsets, params, p.channels, s.wi, s.wo, f, d)
    g = np.log(t.offset + t.scale * f) if t.offset > 0.0 else t.scale * f
    r = g - t.target
    dg = 1.0 / (t.offset + t.scale * f) if t.offset > 0.0 else 1.0
    dl = 2.0 * t.weight[:, None] * r * t.scale * dg
    value = float((t.weight[:, None] * r * r).sum() / t.norm)
    return value, p._in_x(np.einsum("kc,jkc->j", dl, d) / t.norm, x)


# RGB models of Lambertian lobes and one other lobe fold each row into the sums (with and
# without a Fresnel term, two Lambertian lobes); other RGB models of at most 16 packed
# parameters take the pass on the stack (two GGX-like lobes), the rest the heap's
@pytest.mark.parametrize("spec,loss,shared", [(SPECS[0], "cosine-l2", ("lambert.albedo",)),
                                               (SPECS[1], "log", ()), (SPECS[2], "l2", ("ks",)),
                                               (SPECS[6] + " + lambert(albedo=0.1)", "log", ()),
                                               (SPECS[0] + " + beckmann", "relative-l2", ())])
def test_loss_gradient_pass_agrees_with_per_pair_derivatives(rgb_table, spec, loss, shared):
    p = Problem(rgb_table, spec, loss=loss, shared=shared)
    x = p.x0 + 0.2 * (p.random_x(np.random.default_rng(2), 1)[0] - p.x0)
    value, grad = p.loss_and_gradient(x)
    ref_value, ref_grad = per_pair_loss_and_gradient(p, x)
    assert value == pytest.approx(ref_value, rel=1e-12)
    assert np.all(np.abs(grad - ref_grad) <= 1e-12 * np.abs(ref_grad).max()), (grad, ref_grad)
    with using_threads(1):  # the same bits on one thread: the blocks' sums add in a fixed order
        again = p.loss_and_gradient(x)
    assert again[0] == value and np.array_equal(again[1], grad)


# the loss alone folds each row into its terms for the same models as the gradient pass (every
# SPECS entry with Lambertian lobes, one other lobe and three channels); the rest store the rows
@pytest.mark.parametrize("spec", SPECS)
@pytest.mark.parametrize("loss", ["cosine-l2", "l2", "log"])
def test_loss_pass_agrees_with_values_scored_apart(rgb_table, spec, loss):
    p = Problem(rgb_table, spec, loss=loss)
    rng = np.random.default_rng(3)
    X = np.array([p.x0 + 0.2 * (x - p.x0) for x in p.random_x(rng, 4)])
    X[2] = X[0]  # rows equal to the first reuse nothing they should not
    losses_ = p.channel_losses(X)
    for x, got in zip(X, losses_):
        ref = p.score(p.model_values(x), p.terms)  # f stored, then the terms in numpy's order
        assert np.all(np.abs(got - ref) <= 1e-12 * np.abs(ref).max()), (got, ref)
        assert got.sum() == pytest.approx(per_pair_loss_and_gradient(p, x)[0], rel=1e-12)
    with using_threads(1):  # the same bits on one thread
        again = p.channel_losses(X)
    assert np.array_equal(again, losses_)


@pytest.mark.parametrize("spec,loss", [(SPECS[0], "cosine-l2"), (SPECS[0], "log"),
                                       (SPECS[0] + " + beckmann", "relative-l2")])
def test_passes_over_many_blocks_give_the_same_bytes_on_one_thread_and_on_two(spec, loss):
    # 20,000 samples: 10 blocks of the loss, 3 groups of blocks of the gradient pass, shared
    # out to the threads from a queue (the grid tables above fill one block)
    import numba
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has one thread here")
    rng = np.random.default_rng(11)
    wi, wo = (brdf.geometry.directions_from_degrees(rng.uniform(0, 80, 20_000),
                                                    rng.uniform(0, 360, 20_000))
              for _ in range(2))
    values = brdf.parse(RGB_TRUTH).eval(wi, wo) * rng.uniform(0.9, 1.1, (20_000, 3))
    p = Problem(brdf.Table(wi, wo, values), spec, loss=loss)
    X = np.array([p.x0 + 0.2 * (x - p.x0) for x in p.random_x(rng, 3)])
    metric = losses.terms("l2", p.samples, len(p.free))

    def passes():
        return (p.channel_losses(X), *p.loss_and_gradient(X[1]),
                p.score(p.model_values(X[2]), metric))

    with using_threads(2):
        two = passes()
    with using_threads(1):
        one = passes()
    for a, b in zip(one, two):
        assert np.array_equal(a, b)


def test_difference_rows_stay_inside_the_bounds(rgb_table):
    p = Problem(rgb_table, "lambert(albedo=0) + ggx(alpha=0.3)")  # albedo at its lower bound
    rows, width = p.difference_rows(p.x0)
    assert np.all(rows >= p.lower) and np.all(rows <= p.upper)
    grad = p.gradient(p.x0)
    assert np.all(np.isfinite(grad)) and np.all(width > 0.0)


@pytest.fixture(scope="module")
def noisy_table():
    """With stated sigma, so that chi-square is among the losses."""
    return brdf.measure(RGB_TRUTH, GRID, "relative:0.05", seed=4)


def central_gradient(p, x, h=1e-5):
    """Central differences of the compiled loss, one coordinate at a time."""
    grad = np.empty(len(x))
    for i in range(len(x)):
        up, down = x.copy(), x.copy()
        up[i] += h
        down[i] -= h
        grad[i] = (p.loss(up) - p.loss(down)) / (2.0 * h)
    return grad


def assert_gradient_matches_differences(p, seed):
    # a fifth of the way to a random point of the box: far into it, Lafortune's powers reach
    # 1e170, where differences of the loss keep no digits of the smaller derivatives
    x = p.x0 + 0.2 * (p.random_x(np.random.default_rng(seed), 1)[0] - p.x0)
    value, grad = p.loss_and_gradient(x)
    assert value == pytest.approx(p.loss(x), rel=1e-12)
    ref = central_gradient(p, x)
    assert np.all(np.abs(grad - ref) <= 1e-6 * (np.abs(ref) + 1e-3 * np.abs(ref).max())), (
        p.names, grad, ref)


# shared, fixed and log-scaled parameters, a Fresnel term, a fallback (alpha_y) and anisotropy
OPTIONS = [
    ("lambert + ggx(alpha=0.3, fresnel=schlick(f0=[0.04,0.05,0.06]))",
     {"shared": ("ks",), "fix": {"lambert.albedo[1]": 0.4}}),
    ("lambert + beckmann(alpha=0.2, alpha_y=0.4, fresnel=conductor(eta=0.2, k=3))",
     {"shared": ("eta",), "fix": {"k": 3.5}}),
    ("ggx(alpha=0.3, masking=height-correlated, fresnel=dielectric(eta=1.5))", {}),
]


@pytest.mark.parametrize("loss", list(losses.LOSSES))
@pytest.mark.parametrize("spec,options", OPTIONS)
def test_analytic_gradient_matches_differences_for_every_loss(noisy_table, loss, spec, options):
    p = Problem(noisy_table, spec, loss=loss, **options)
    assert_gradient_matches_differences(p, seed=5)


@pytest.mark.parametrize("spec", SPECS[3:])
def test_analytic_gradient_matches_differences_for_every_family(noisy_table, spec):
    for i, loss in enumerate(losses.LOSSES):
        assert_gradient_matches_differences(Problem(noisy_table, spec, loss=loss), seed=i)


def test_metrics_from_one_evaluation_agree_with_the_loss_passes(noisy_table):
    p = Problem(noisy_table, OPTIONS[0][0], loss="log")
    x = p.x0 + 0.2 * (p.random_x(np.random.default_rng(1), 1)[0] - p.x0)
    metrics = p.metrics(x)
    assert set(metrics) == set(losses.LOSSES)  # the table states sigma: chi-square too
    for name, value in metrics.items():
        terms = losses.terms(name, p.samples, len(p.free))
        assert value == pytest.approx(float(p.channel_losses(x, terms)[0].sum()), rel=1e-12)


# --- recovery ------------------------------------------------------------------------------------

#: (truth, start, geometry): every family, and the variants (anisotropy, masking, Fresnel
#: terms, normalisations) that change what the parameters do. The mirror family is absent: a
#: delta lobe evaluates to 0 everywhere, so no table holds a trace of it.
RECOVERY = [
    (RGB_TRUTH, "lambert(albedo=0.2) + ggx(ks=1, alpha=0.5)", GRID),
    ("lambert(albedo=[0.3,0.2,0.1]) + beckmann(ks=[0.7,0.6,0.5], alpha=0.15)",
     "lambert(albedo=0.5) + beckmann(ks=0.3, alpha=0.3)", GRID),
    ("ward(rho_s=[0.2,0.3,0.4], alpha=0.12)", "ward(rho_s=0.6, alpha=0.3)", GRID),
    ("blinn-phong(ks=[0.7,0.6,0.5], n=30)", "blinn-phong(ks=0.3, n=8)", GRID),
    ("blinn-phong(ks=0.5, n=40, normalization=approx)",
     "blinn-phong(ks=0.3, n=10, normalization=approx)", GRID),
    ("phong(ks=[0.3,0.25,0.2], n=25)", "phong(ks=0.5, n=10)", GRID),
    ("modified-phong(ks=[0.6,0.5,0.4], n=40) + lambert(albedo=[0.3,0.2,0.1])",
     "modified-phong(ks=0.3, n=15) + lambert(albedo=0.5)", GRID),
    # grid: fixes the incident azimuth at 0 for isotropic models, where cy multiplies
    # wi_y = 0: only incident directions off the xz-plane determine it
    ("lafortune(cx=-0.9, cy=-0.9, cz=0.8, n=12)", "lafortune(cx=-0.7, cy=-0.7, cz=0.7, n=8)",
     "random:1500"),
    ("lafortune(cx=-0.95, cy=-0.8, cz=0.9, n=15) + lambert(albedo=0.2)",
     "lafortune(cx=-0.8, cy=-0.8, cz=0.8, n=10) + lambert(albedo=0.4)", GRID),
    ("ashikhmin-shirley(rd=[0.5,0.4,0.3], rs=[0.1,0.08,0.06], nu=60, nv=200)",
     "ashikhmin-shirley(rd=0.3, rs=0.2, nu=100, nv=100)", GRID),
    ("ggx(ks=[0.8,0.7,0.6], alpha=0.15, alpha_y=0.4)", "ggx(ks=0.5, alpha=0.3, alpha_y=0.3)",
     GRID),
    ("ward(rho_s=0.3, alpha=0.1, alpha_y=0.3, variant=gmd) + lambert(albedo=0.2)",
     "ward(rho_s=0.5, alpha=0.2, alpha_y=0.2, variant=gmd) + lambert(albedo=0.4)", GRID),
    ("lambert(albedo=0.3) + ggx(ks=0.6, alpha=0.25, masking=height-correlated)",
     "lambert(albedo=0.5) + ggx(ks=0.3, alpha=0.4, masking=height-correlated)", GRID),
    ("lambert(albedo=0.3) + ggx(ks=0.9, alpha=0.2, fresnel=schlick(f0=0.05))",
     "lambert(albedo=0.5) + ggx(ks=0.5, alpha=0.3, fresnel=schlick(f0=0.2))", GRID),
    ("ggx(ks=0.9, alpha=0.3, fresnel=dielectric(eta=1.6))",
     "ggx(ks=0.5, alpha=0.2, fresnel=dielectric(eta=1.3))", GRID),
    ("beckmann(ks=[1,1,1], alpha=0.2, fresnel=conductor(eta=[0.2,0.4,1.2], k=[3.5,2.7,2.2]))",
     "beckmann(ks=1, alpha=0.3, fresnel=conductor(eta=0.5, k=2))", GRID),
]


@pytest.mark.parametrize("truth,start,geometry", RECOVERY)
def test_noise_free_tables_give_back_the_true_parameters(truth, start, geometry):
    table = brdf.measure(truth, geometry, seed=1)
    result = brdf.fit(table, start)
    expected = brdf.parse(truth).params
    assert result.converged, result.runs
    assert set(result.params) == set(expected)
    for name, value in expected.items():
        assert result.params[name] == pytest.approx(value, rel=1e-3), name
    assert str(result.model) == result.spec and brdf.parse(result.spec) == result.model


def test_an_isotropic_grid_does_not_determine_lafortunes_cy():
    # why the isotropic Lafortune case above is measured at random pairs: on grid: (incident
    # azimuth 0 for isotropic models) cy multiplies wi_y = 0 and the loss cannot see it
    truth = "lafortune(cx=-0.9, cy=-0.9, cz=0.8, n=12)"
    p = Problem(brdf.measure(truth, GRID), truth)
    x = p.x0.copy()
    x[p.names.index("lafortune.cy")] *= 0.7
    assert p.loss(x) == p.loss(p.x0) < 1e-30  # bit for bit: cy meets only exact zeros
    x = p.x0.copy()
    x[p.names.index("lafortune.cx")] *= 0.7
    assert p.loss(x) > 1e-6


def test_random_starts_keep_the_best_run(rgb_table):
    result = brdf.fit(rgb_table, "lambert + ggx(alpha=0.5)", starts=4, seed=2)
    assert len(result.runs) == 4
    assert result.runs[-1]["loss"] == min(r["loss"] for r in result.runs)
    assert result.loss < 1e-12


def test_a_global_optimizer_is_polished_to_convergence(rgb_table):
    result = brdf.fit(rgb_table, "lambert + ggx(alpha=0.5)", optimizer="GN_CRS2_LM",
                      max_evals=300, seed=1)
    assert [r["run"] for r in result.runs] == ["global search", "polish"]
    assert result.converged and result.params["ggx.alpha"] == pytest.approx(0.2, rel=1e-3)


def test_chi_square_is_about_one_at_the_truth_with_the_stated_noise():
    table = brdf.measure("lambert(albedo=0.4) + ggx(ks=0.5, alpha=0.25)", GRID,
                         noise="relative:0.05", seed=4)
    p = Problem(table, "lambert(albedo=0.4) + ggx(ks=0.5, alpha=0.25)", loss="chi-square")
    # mean of n squared standard normals: 1 +- sqrt(2 / n), n = 1305 here
    assert p.loss(p.x0) == pytest.approx(1.0, abs=4.0 * np.sqrt(2.0 / len(p.samples.wi)))


# --- the energy constraint -----------------------------------------------------------------------

@pytest.fixture(scope="module")
def bright_table():
    # albedo 0.5 + 0.8 x 0.88 above 1: a lambert + ggx fit reproduces it exactly, and exceeds 1
    return brdf.measure("lambert(albedo=0.5) + ggx(ks=0.8, alpha=0.3)", GRID)


@pytest.mark.slow
@pytest.mark.parametrize("optimizer", ["LD_SLSQP", "LD_LBFGS"])
def test_the_energy_constraint_holds_where_the_free_fit_exceeds_one(bright_table, optimizer):
    start = "lambert(albedo=0.1) + ggx(ks=0.5, alpha=0.2)"
    free = brdf.fit(bright_table, start)
    assert not free.energy["holds"] and free.energy["worst_albedo"] > 1.1
    held = brdf.fit(bright_table, start, optimizer=optimizer, energy_constraint=True)
    assert held.energy["constrained"] and held.energy["holds"]
    assert held.energy["worst_albedo"] <= 1.0 + held.energy["tolerance"]
    albedo = held.model.albedo(brdf.geometry.directions_from_degrees(
        np.linspace(0.0, 89.9, 40), np.zeros(40)))
    assert albedo.max() <= 1.0 + 1e-4
    assert held.loss > free.loss


# --- reproducibility and reports -----------------------------------------------------------------

def report_bytes(result):
    d = result.to_dict()
    assert list(d)[-1] == "timing"
    del d["timing"]
    return json.dumps(d, sort_keys=True, allow_nan=False).encode()


def test_same_seed_same_report_bytes(rgb_table):
    a, b = (brdf.fit(rgb_table, "lambert + ggx(alpha=0.5)", starts=3, seed=11)
            for _ in range(2))
    assert report_bytes(a) == report_bytes(b)
    c = brdf.fit(rgb_table, "lambert + ggx(alpha=0.5)", optimizer="GN_ISRES", max_evals=200,
                 seed=5)
    d = brdf.fit(rgb_table, "lambert + ggx(alpha=0.5)", optimizer="GN_ISRES", max_evals=200,
                 seed=5)
    assert report_bytes(c) == report_bytes(d)


def test_the_report_holds_metrics_checks_and_provenance(tmp_path):
    path = tmp_path / "plastic.csv"
    brdf.write(brdf.measure("lambert(albedo=0.3) + ggx(ks=0.4, alpha=0.3)", GRID), path)
    d = brdf.fit(path, "lambert + ggx", fix={"ggx.alpha": 0.3}).to_dict()
    assert d["provenance"]["input"]["sha256"] == brdf.read(path).source.sha256
    assert set(d["provenance"]["versions"]) >= {"brdf", "numpy", "scipy", "nlopt"}
    assert d["provenance"]["options"]["fix"] == {"ggx.alpha": 0.3}
    assert d["fixed"] == {"ggx.alpha": 0.3} and "ggx.alpha" not in d["free"]
    assert set(d["metrics"]) == {"cosine-l2", "l2", "relative-l2", "log"}
    assert d["loss"]["value"] == d["metrics"]["cosine-l2"]
    assert [c["name"] for c in d["checks"]["checks"]] == ["non-negativity", "reciprocity",
                                                         "energy"]
    assert brdf.parse(d["spec"]).params["ggx.alpha"] == 0.3


# --- bad options ---------------------------------------------------------------------------------

@pytest.mark.parametrize("options,error,fragments", [
    ({"optimizer": "LD_FOO"}, InputError, ["unknown optimizer", "LD_LBFGS", "MLSL"]),
    ({"fix": {"ggx.beta": 1.0}}, InputError, ["unknown parameter", "ggx.alpha",
                                               "lambert.albedo"]),
    ({"shared": ["rho"]}, InputError, ["unknown parameter", "ggx.ks"]),
    ({"fix": {"ggx.alpha": 9.0}}, ParameterError, ["outside the bounds", "ggx.alpha"]),
    ({"fix": {"lambert.albedo[3]": 0.1}}, InputError, ["channels 0 to 2"]),
    ({"bounds": {"ggx.alpha": (0.5, 0.2)}}, InputError, ["lower < upper"]),
    ({"bounds": {"ggx.alpha": (0.1, 9.0)}}, InputError, ["inside the declared"]),
    ({"starts": 0}, InputError, ["starts"]),
    ({"optimizer": "GN_DIRECT_L", "starts": 3}, InputError, ["local optimizers"]),
    ({"loss": "chi-square"}, InputError, ["sigma"]),
    ({"fix": {"lambert.albedo": 0.5, "ggx.ks": 1.0, "ggx.alpha": 0.2}}, InputError,
     ["nothing to fit"]),
])
def test_bad_options_are_one_line_errors(rgb_table, options, error, fragments):
    with pytest.raises(error) as info:
        brdf.fit(rgb_table, "lambert + ggx", **options)
    message = str(info.value)
    assert isinstance(info.value, BRDFError) and "\n" not in message
    for fragment in fragments:
        assert fragment in message


# --- command line --------------------------------------------------------------------------------

@pytest.fixture()
def csv_table(tmp_path):
    path = tmp_path / "paint.csv"
    brdf.write(brdf.measure("lambert(albedo=[0.5,0.4,0.3]) + ggx(ks=0.5, alpha=0.3)",
                            "grid:15,30"), path)
    return path


def test_cli_fit_writes_the_report_atomically_and_refuses_to_overwrite(capsys, csv_table):
    report = csv_table.parent / "report.json"
    status, out, err = run(capsys, "fit", str(csv_table), "lambert + ggx(alpha=0.4)",
                           "--shared", "ks", "-o", str(report))
    assert status == 0 and without_progress(err) == "" and "converged" in out
    d = json.loads(report.read_text(encoding="utf-8"))
    assert d["params"]["ggx.alpha"] == pytest.approx(0.3, rel=1e-3)
    assert sorted(p.name for p in report.parent.iterdir()) == ["paint.csv", "report.json"]
    status, _, err = run(capsys, "fit", str(csv_table), "lambert + ggx", "-o", str(report))
    assert status == 2
    assert_one_error_line(err, "report.json", "exists", "--force")
    status, _, _ = run(capsys, "fit", str(csv_table), "lambert + ggx", "-o", str(report),
                       "--force", "--fix", "ggx.alpha=0.3", "-q")
    assert status == 0 and json.loads(report.read_text())["fixed"] == {"ggx.alpha": 0.3}


def test_cli_fit_json_and_exit_status_one_when_not_converged(capsys, csv_table):
    status, out, _ = run(capsys, "fit", str(csv_table), "lambert + ggx", "--json",
                         "--max-evals", "3")
    assert status == 1 and json.loads(out)["status"] == "MAXEVAL_REACHED"


@pytest.mark.parametrize("argv,fragments", [
    (["--fix", "alpha"], ["NAME=VALUE"]),
    (["--fix", "beta=1"], ["unknown parameter", "ggx.alpha"]),
    (["--optimizer", "FOO"], ["unknown optimizer"]),
    (["--loss", "l3"], ["unknown loss", "cosine-l2"]),
])
def test_cli_fit_bad_options_exit_2(capsys, csv_table, argv, fragments):
    status, _, err = run(capsys, "fit", str(csv_table), "lambert + ggx", *argv)
    assert status == 2
    assert_one_error_line(err, *fragments)
