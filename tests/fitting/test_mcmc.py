"""brdf.mcmc: the posterior against closed forms, credible-interval coverage over seeds,
determinism, chain files, the corner plot, predictive bands and the CLI flags."""

import json
import math

import numpy as np
import pytest

import brdf
from brdf.errors import InputError
from brdf.fitting.mcmc import NOISE, TAU_MULTIPLE
from test_cli import assert_one_error_line, run, without_progress

SIGMA = 0.01


@pytest.fixture(scope="module")
def lambert_table():
    """Lambert albedo 0.5 with additive Gaussian noise of stated sigma."""
    return brdf.measure("lambert(albedo=0.5)", "random:400", f"additive:{SIGMA}", seed=4)


@pytest.fixture(scope="module")
def lambert_posterior(lambert_table):
    return brdf.mcmc(lambert_table, "lambert(albedo=0.3)", seed=2)


@pytest.fixture(scope="module")
def lambert_posteriors(lambert_table, lambert_posterior):
    """The default moves' posterior and the stretch move's, on the same table."""
    return {"de": lambert_posterior,
            "stretch": brdf.mcmc(lambert_table, "lambert(albedo=0.3)", seed=2, moves="stretch")}


@pytest.mark.parametrize("moves", ["de", "stretch"])
def test_lambert_posterior_matches_the_closed_form(lambert_table, lambert_posteriors, moves):
    # f = rho / pi with y ~ N(f, sigma^2) and a flat prior far from the bounds: rho is normal
    # with mean pi ybar and sd pi sigma / sqrt(n) over the n samples within the cutoff
    post = lambert_posteriors[moves]
    cutoff = math.cos(math.radians(80.0)) - 1e-12
    keep = (lambert_table.wi[:, 2] >= cutoff) & (lambert_table.wo[:, 2] >= cutoff)
    y = lambert_table.values[keep, 0]
    mean, sd = math.pi * y.mean(), math.pi * SIGMA / math.sqrt(len(y))
    draws = post.samples[:, 0]
    mc_error = sd / math.sqrt(len(draws) / 2)      # thinned draws are nearly independent
    assert post.names == ("lambert.albedo",)       # sigma is stated: no noise scale to fit
    assert abs(draws.mean() - mean) < 5 * mc_error
    assert draws.std() == pytest.approx(sd, rel=0.08)
    lo, hi = post.interval("lambert.albedo", 95)
    assert lo == pytest.approx(mean - 1.96 * sd, abs=0.15 * sd)
    assert hi == pytest.approx(mean + 1.96 * sd, abs=0.15 * sd)
    assert post.converged and post.steps > TAU_MULTIPLE * post.tau.max()


def test_without_stated_sigma_the_noise_scale_is_fitted(lambert_table):
    bare = brdf.Table(lambert_table.wi, lambert_table.wo, lambert_table.values)
    post = brdf.mcmc(bare, "lambert(albedo=0.3)", loss="l2", seed=1)
    assert post.names == ("lambert.albedo", NOISE)
    # l2 residuals are f - y, so the noise scale is the stated sigma
    lo, hi = post.interval(NOISE, 95)
    assert lo < SIGMA < hi
    assert post.median[NOISE] == pytest.approx(SIGMA, rel=0.1)
    assert post.correlation.shape == (2, 2) and abs(post.correlation[0, 1]) < 0.3


@pytest.mark.slow
def test_the_truth_lies_in_the_95_percent_interval_for_most_parameters_and_seeds():
    # 2 % relative noise on lambert + ggx; 5 seeds x 3 parameters = 15 intervals, each
    # holding the truth with probability 0.95: at least 12 must (P(fewer) < 0.01)
    truth = {"lambert.albedo": 0.6, "ggx.ks": 0.3, "ggx.alpha": 0.25}
    hits = []
    for seed in range(5):
        t = brdf.measure("lambert(albedo=0.6) + ggx(alpha=0.25, ks=0.3)", "random:1500",
                         "relative:0.02", seed=seed)
        post = brdf.mcmc(t, "lambert(albedo=0.5) + ggx(alpha=0.4, ks=0.5)", seed=seed)
        assert post.converged, post.verdict
        hits += [post.interval(n, 95)[0] <= v <= post.interval(n, 95)[1]
                 for n, v in truth.items()]
    assert sum(hits) >= 12, hits


def test_same_seed_same_chain(lambert_table, lambert_posterior):
    again = brdf.mcmc(lambert_table, "lambert(albedo=0.3)", seed=2)
    assert again.samples.tobytes() == lambert_posterior.samples.tobytes()
    other = brdf.mcmc(lambert_table, "lambert(albedo=0.3)", seed=3)
    assert other.samples.tobytes() != lambert_posterior.samples.tobytes()


def test_chain_files_hold_the_whole_chain(tmp_path, lambert_table, lambert_posterior):
    npz, h5 = tmp_path / "chain.npz", tmp_path / "chain.h5"
    brdf.mcmc(lambert_table, "lambert(albedo=0.3)", seed=2, chain=npz)
    brdf.mcmc(lambert_table, "lambert(albedo=0.3)", seed=2, chain=h5)
    saved = np.load(npz)
    post = lambert_posterior
    assert saved["chain"].shape == (post.steps, post.walkers, 1)
    assert np.array_equal(saved["natural"], post.samples)
    assert list(saved["names"]) == list(post.names)
    import emcee
    backend = emcee.backends.HDFBackend(str(h5), name="mcmc", read_only=True)
    assert np.array_equal(backend.get_chain(), saved["chain"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["chain.h5", "chain.npz"]
    with pytest.raises(brdf.OutputError, match="exists"):
        brdf.mcmc(lambert_table, "lambert(albedo=0.3)", seed=2, chain=npz)


def test_corner_plot_is_a_picture_of_the_posterior(tmp_path, lambert_posterior):
    from PIL import Image
    path = tmp_path / "corner.png"
    lambert_posterior.corner(path)
    image = np.asarray(Image.open(path).convert("L"), dtype=float)
    assert image.shape[0] > 100 and image.std() > 5.0   # not blank
    with pytest.raises(brdf.OutputError):
        lambert_posterior.corner(path)


def test_predictive_bands_bracket_the_fit(lambert_posterior):
    bands = lambert_posterior.predictive(theta_i=30.0, draws=40, step=10.0)
    albedo = bands["albedo"]["bands"]
    assert albedo.shape == (5, len(bands["albedo"]["theta_i_deg"]), 1)
    assert np.all(np.diff(albedo, axis=0) >= 0.0)              # 2.5 <= 16 <= 50 <= 84 <= 97.5
    # a Lambertian albedo is rho at every incidence
    rho = lambert_posterior.median["lambert.albedo"]
    assert np.allclose(albedo[2], rho, rtol=2e-3)
    plane = bands["in_plane"]["bands"]
    assert plane.shape == (5, len(bands["in_plane"]["theta_o_deg"]), 1)
    assert np.allclose(plane[2], rho / np.pi, rtol=2e-3)


@pytest.mark.parametrize("options, fragment", [
    ({"walkers": 1}, "walkers must be an even integer >= 2"),
    ({"walkers": 7}, "walkers must be an even integer"),
    ({"max_steps": 10}, "max_steps must be an integer >= 200"),
    ({"chain": "chain.txt"}, "chain files end in .npz or .h5"),
    ({"seed": -1}, "seed must be an integer >= 0"),
    ({"moves": "gibbs"}, "moves must be one of de, stretch or emcee moves"),
    ({"moves": [("de", 1.0)]}, "moves must be one of de, stretch, an emcee Move or a list"),
    ({"moves": []}, "moves must be one of de, stretch, an emcee Move or a list"),
    ({"walkers": 2}, "walkers must be >= 4 with differential-evolution moves"),
])
def test_bad_options_are_one_line_errors(lambert_table, options, fragment):
    with pytest.raises(InputError, match=fragment):
        brdf.mcmc(lambert_table, "lambert(albedo=0.3)", **options)


def test_emcee_moves_pass_through_and_are_named(lambert_table):
    import emcee
    post = brdf.mcmc(lambert_table, "lambert(albedo=0.3)", seed=2,
                     moves=[(emcee.moves.StretchMove(a=2.5), 0.5),
                            (emcee.moves.DEMove(), 0.5)])
    assert post.converged
    assert post.to_dict()["sampler"] == "emcee ensemble: StretchMove (0.5), DEMove (0.5)"


def test_differential_evolution_mixes_faster_than_stretch(lambert_posteriors):
    # the reason it is the default: on a near-Gaussian posterior its autocorrelation time is
    # well below the stretch move's, so it converges in fewer steps
    de, stretch = lambert_posteriors["de"], lambert_posteriors["stretch"]
    assert de.tau.max() < 0.7 * stretch.tau.max()
    assert "differential evolution" in de.to_dict()["sampler"]
    assert "stretch" in stretch.to_dict()["sampler"]


def test_cli_moves_are_the_library_moves():
    from brdf.fitting.mcmc import MOVES
    from cli.arguments import MOVES as CLI_MOVES
    assert CLI_MOVES == tuple(MOVES)


def test_cli_fit_mcmc_adds_the_posterior_to_the_report(tmp_path, capsys):
    data, report, corner = tmp_path / "t.csv", tmp_path / "r.json", tmp_path / "c.png"
    brdf.write(brdf.measure("lambert(albedo=0.5)", "random:300", "additive:0.01", seed=1), data)
    code, out, err = run(capsys, "fit", str(data), "lambert(albedo=0.3)", "--mcmc", "--seed",
                         "1", "-o", str(report), "--corner", str(corner), "--moves", "stretch")
    assert code == 0, err
    assert "posterior:" in out and "converged" in out
    doc = json.loads(report.read_text())
    assert list(doc)[-2:] == ["posterior", "timing"] and "mcmc_s" in doc["timing"]
    assert doc["posterior"]["converged"] and doc["posterior"]["parameters"] == ["lambert.albedo"]
    assert doc["posterior"]["sampler"] == "emcee ensemble: affine-invariant stretch move"
    assert corner.stat().st_size > 1000


@pytest.mark.parametrize("extra, fragment", [
    (["--corner", "c.png"], "--walkers, --moves, --chain and --corner need --mcmc"),
    (["--moves", "de"], "--walkers, --moves, --chain and --corner need --mcmc"),
    (["--mcmc", "--walkers", "3"], "walkers must be an even integer"),
    (["--mcmc", "--chain", "chain.csv"], "chain files end in .npz or .h5"),
])
def test_cli_bad_mcmc_options_exit_2(tmp_path, capsys, monkeypatch, extra, fragment):
    monkeypatch.chdir(tmp_path)
    brdf.write(brdf.measure("lambert(albedo=0.5)", "random:100", "additive:0.01", seed=1),
               tmp_path / "t.csv")
    code, out, err = run(capsys, "fit", "t.csv", "lambert", *extra)
    assert code == 2
    assert_one_error_line(without_progress(err), fragment)  # some come after the fit
