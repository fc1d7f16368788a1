"""brdf.viz.plots: every kind draws the subject's own eval/albedo, writes a valid PNG of the
stated size atomically, and refuses bad input in one line."""

import math

import numpy as np
import pytest

import brdf
from brdf.errors import InputError, OutputError
from brdf.render.image import flip_error, luminance
from brdf.viz import (albedo_plot, corner_plot, inplane_plot, predictive_plot, residual_plot,
                      save_figure, slice_plot, validation_figure)
from pictures import distinct_colours, drawn_fraction, read_png

MODEL = "lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.2, ks=0.6)"


@pytest.fixture(scope="module")
def model():
    return brdf.parse(MODEL)


@pytest.fixture(scope="module")
def table(model):
    return brdf.measure(model, "grid:10,30", "relative:0.05", seed=3)


@pytest.fixture(scope="module")
def posterior():
    table = brdf.measure("lambert(albedo=0.5)", "random:300", "additive:0.01", seed=4)
    # a short chain: the plots, not convergence, are under test here
    return table, brdf.mcmc(table, "lambert(albedo=0.3)", seed=2, max_steps=400)


def assert_png(path, fig, dpi=100):
    img = read_png(path)
    width, height = fig.get_size_inches() * dpi
    assert img.shape[:2] == (round(height), round(width))
    assert distinct_colours(img) > 50 and drawn_fraction(img) > 0.03
    return img


def test_inplane_plot(tmp_path, model, table):
    fig = inplane_plot(model, [0.0, 30.0, 60.0], data=table, log=False)
    ax = fig.axes[0]
    curves = [line for line in ax.lines if line.get_label().startswith("theta_i")]
    assert [c.get_label() for c in curves] == ["theta_i = 0°", "theta_i = 30°", "theta_i = 60°"]
    # the 30-degree curve is the model's mean over channels along the plane of incidence
    angle = np.asarray(curves[1].get_xdata())
    wo = brdf.geometry.spherical_to_cartesian(np.abs(angle), np.where(angle < 0, 0.0, math.pi))
    wi = brdf.geometry.spherical_to_cartesian(math.radians(30.0), 0.0)
    np.testing.assert_allclose(curves[1].get_ydata(),
                               model.eval(np.broadcast_to(wi, wo.shape), wo).mean(axis=-1))
    markers = [line for line in ax.lines if line.get_marker() == "o" and len(line.get_xdata())]
    assert len(markers) == 3 and all(len(m.get_xdata()) >= 10 for m in markers)
    assert_png(save_figure(fig, tmp_path / "inplane.png"), fig)


def test_inplane_log_radius_says_what_it_draws_at_the_centre():
    def labels(fig):
        return [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    # a sharp lobe falls more than the 3 decades of the log radius below its peak
    assert any("drawn at the centre" in k for k in labels(inplane_plot(brdf.parse(
        "ggx(alpha=0.05)"))))
    assert not any("drawn at the centre" in k for k in labels(inplane_plot(brdf.parse(
        "lambert(albedo=0.5)"))))


def test_inplane_of_a_table_draws_its_own_samples(tmp_path, table):
    fig = inplane_plot(table, [30.0], channel=1)
    assert any(line.get_marker() == "o" and len(line.get_xdata()) for line in fig.axes[0].lines)
    assert "channel g" in fig.axes[0].get_title()


def test_slice_plot_is_the_merl_layout_in_log_colour(tmp_path, model):
    fig = slice_plot(model, resolution=32)
    image = fig.axes[0].images[0]
    values = np.ma.filled(image.get_array(), np.nan)
    assert values.shape == (32, 32)
    # pixel (row j, column i) is f at theta_h = (pi/2) u_i^2 (MERL), theta_d linear, phi_d 90
    u = (np.arange(32) + 0.5) / 32
    for j, i in [(3, 0), (10, 5), (20, 25)]:
        wi, wo = brdf.geometry.directions_from_half_diff(0.5 * math.pi * u[i] ** 2, 0.0,
                                                         0.5 * math.pi * u[j], 0.5 * math.pi)
        assert values[j, i] == pytest.approx(model.eval(wi, wo).mean(), rel=1e-9)
    assert values[10, 0] > 5 * values[10, 20]      # the specular column stands out
    assert type(image.norm).__name__ == "LogNorm"
    assert fig.axes[1].get_ylabel() == "f_r [1/sr] (log)"
    assert_png(save_figure(fig, tmp_path / "slice.png"), fig)


def _key(fig):
    """The texts of the legend under a figure (what its grey and clipped regions mean)."""
    return [t.get_text() for legend in fig.legends for t in legend.get_texts()]


def test_slice_plot_says_what_grey_and_black_mean(model):
    # at phi_d = 90 every pair is above the horizon: no grey, and the darkest colour is the
    # lowest value, not a gap
    key = _key(slice_plot(model, resolution=32))
    assert len(key) == 1 and "the lowest value (not missing data)" in key[0]
    # at phi_d = 0 theta_h + theta_d > 90 degrees puts wi below the horizon: a grey wedge
    fig = slice_plot(model, phi_d=0.0, resolution=32)
    assert np.isnan(np.ma.filled(fig.axes[0].images[0].get_array(), np.nan)).any()
    assert "grey: no value, a direction below the horizon" in _key(fig)
    # a sharp lobe spans more than the colours' 4 decades: the rest is clipped, and says so
    fig = slice_plot(brdf.parse("ggx(alpha=0.05)"), phi_d=30.0, resolution=32)
    assert any("lower values clipped" in k for k in _key(fig))
    assert fig.axes[1].get_ylabel() == "f_r [1/sr] (log)"
    assert fig.axes[0].images[0].colorbar.extend == "min"


def test_albedo_plot_draws_the_subjects_albedo_and_the_limit(tmp_path):
    fig = albedo_plot(brdf.parse("lambert(albedo=[0.2,0.5,0.8])"), steps=10)
    ax = fig.axes[0]
    (line,) = [ln for ln in ax.lines if "lambert" in ln.get_label()]
    np.testing.assert_allclose(line.get_ydata(), 0.5, rtol=1e-4)
    limit = [ln for ln in ax.lines if ln.get_label().startswith("1:")]
    assert len(limit) == 1 and np.allclose(limit[0].get_ydata(), 1.0)
    band = ax.collections[0].get_paths()[0].vertices[:, 1]
    assert band.min() == pytest.approx(0.2, rel=1e-4) and band.max() == pytest.approx(0.8,
                                                                                     rel=1e-4)
    assert_png(save_figure(fig, tmp_path / "albedo.png"), fig)


def test_albedo_of_an_in_plane_scan_is_refused(model):
    scan = brdf.measure(model, "inplane:10", "none", seed=0)
    with pytest.raises(InputError, match="in-plane scan has no directional albedo"):
        albedo_plot(scan)


def test_residual_plot(tmp_path, model, table):
    fig = residual_plot(model, table, channel=0)
    rms = float(fig.axes[0].get_title().split("ratio ")[1])
    # 5 % relative noise on one channel: log10(1 + 0.05 z) has an RMS near 0.05 / ln 10 (the
    # mean of three channels would average the independent noise down by sqrt(3))
    assert rms == pytest.approx(0.05 / math.log(10), rel=0.2)
    worse = residual_plot(brdf.parse("lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.4, ks=0.6)"),
                          table, channel=0)
    assert float(worse.axes[0].get_title().split("ratio ")[1]) > 2 * rms
    assert fig.axes[2].get_ylabel() == "log10(model / measured)"
    # bins without samples are grey and bins past the colour range clipped: the legend says
    # both, the bar's ends point out
    key = _key(fig)
    assert any(k.startswith("grey: no sample in the bin") for k in key)
    assert any("(the 99th percentile): clipped to the bar's ends" in k for k in key)
    assert fig.axes[1].images[0].colorbar.extend == "both"
    assert_png(save_figure(fig, tmp_path / "residuals.png"), fig)


def test_residuals_need_a_table(model):
    with pytest.raises(InputError, match="need a measured table"):
        residual_plot(model, model)


def test_corner_and_predictive(tmp_path, posterior):
    table, post = posterior
    path = corner_plot(post, tmp_path / "corner.png")
    assert distinct_colours(read_png(path)) > 20
    fig = predictive_plot(post, table, theta_i=30.0, draws=20)
    left, right = fig.axes
    bands = post.predictive(theta_i=30.0, draws=20, seed=0)
    (median,) = [ln for ln in right.lines if ln.get_label() == "median"]
    np.testing.assert_allclose(median.get_ydata(), bands["albedo"]["bands"][2, :, 0])
    assert_png(save_figure(fig, tmp_path / "predictive.png"), fig)


def test_save_figure_is_atomic_and_keeps_existing_files(tmp_path, model):
    fig = albedo_plot(model, steps=5)
    path = tmp_path / "a.png"
    path.write_bytes(b"mine")
    with pytest.raises(OutputError, match="exists"):
        save_figure(fig, path)
    assert path.read_bytes() == b"mine"
    save_figure(fig, path, force=True)
    read_png(path)
    with pytest.raises(InputError, match="PNG"):
        save_figure(fig, tmp_path / "a.pdf")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png"]


def test_a_missing_channel_is_a_one_line_error(model):
    with pytest.raises(InputError, match="channel 7 does not exist"):
        slice_plot(model, channel=7)


def test_validation_figure_shows_four_panels_each_with_its_scale(tmp_path):
    rng = np.random.default_rng(1)
    measured = np.full((40, 50, 3), 0.5)
    measured[:5] = 2.0                               # 12.5 % of the pixels above white
    fitted = measured + rng.normal(0.0, 0.01, measured.shape)
    fig = validation_figure(measured, fitted, title="a sphere")
    panels, bars = fig.axes[:4], fig.axes[4:]
    assert all(ax.images for ax in panels) and len(bars) == 4
    titles = [ax.get_title() for ax in panels]
    assert titles[0].startswith("measured") and titles[1].startswith("fitted")
    assert titles[2].startswith("difference") and titles[3].startswith("FLIP")
    # the renders share their tone mapping and say what it clips
    assert "above 1 clipped to white:\n12 % of pixels" in bars[0].get_xlabel()
    assert "above 1 clipped to white:\n12 % of pixels" in bars[1].get_xlabel()
    # the difference is the luminance of fitted - measured, clipped at its 99th percentile
    shown = panels[2].images[0]
    np.testing.assert_allclose(shown.get_array(), luminance(fitted - measured))
    limit = np.percentile(np.abs(luminance(fitted - measured)), 99)
    assert shown.norm.vmax == pytest.approx(limit) and shown.norm.vmin == pytest.approx(-limit)
    assert f"clipped at ±{limit:.3g}" in bars[2].get_xlabel()
    assert "1 % of pixels beyond" in bars[2].get_xlabel()
    # FLIP on its fixed scale 0 to 1, its mean in the title
    mean, error = flip_error(fitted, measured)
    np.testing.assert_allclose(panels[3].images[0].get_array(), error)
    assert (panels[3].images[0].norm.vmin, panels[3].images[0].norm.vmax) == (0.0, 1.0)
    assert f"mean {mean:.4g}" in titles[3]
    assert "FLIP" in bars[3].get_xlabel()
    img = assert_png(save_figure(fig, tmp_path / "comparison.png"), fig)
    assert img.shape[1] >= 4 * 256


def test_validation_figure_refuses_images_of_two_sizes():
    with pytest.raises(InputError, match="one size"):
        validation_figure(np.zeros((4, 4, 3)), np.zeros((4, 5, 3)))
