"""Gonioreflectometer CSV: hand-made files read to hand-computed tables, bit-exact round trips of
every layout, a bad-input corpus (tests/data/bad/gonio_*.csv) and interpolation of a table
written from a smooth model."""

import json
from pathlib import Path

import numpy as np
import pytest

import brdf
from brdf.errors import FormatError, InputError
from brdf.geometry import directions_from_degrees, spherical_to_cartesian
from brdf.io import gonio_csv
from brdf.table import AngleTable
from brdf.table import Table

DATA = Path(__file__).resolve().parent.parent / "data"


def exact(a, b):
    """Bit-for-bit equality of two float arrays (NaN where the other has NaN, -0.0 kept)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def round_trip(table, tmp_path, name="out.csv"):
    path = tmp_path / name
    gonio_csv.write(table, path)
    return gonio_csv.read(path), path


def assert_same_samples(a, b):
    for field in ("wi", "wo", "values", "angles"):
        assert exact(getattr(a, field), getattr(b, field)), field
    assert (a.sigma is None) == (b.sigma is None)
    if a.sigma is not None:
        assert exact(a.sigma, b.sigma)
    assert (a.wavelengths is None) == (b.wavelengths is None)
    if a.wavelengths is not None:
        assert exact(a.wavelengths, b.wavelengths)
    assert a.channel_names == b.channel_names and a.isotropic == b.isotropic


# -- hand-made files -------------------------------------------------------------------------------
def test_rgb_file_by_hand():
    # BOM, CRLF, metadata, a plain comment, blank lines, columns in another order, spaces
    t = gonio_csv.read(DATA / "gonio_rgb.csv")
    assert isinstance(t, AngleTable) and t.source.format == "gonio-csv"
    assert t.channel_names == ("r", "g", "b") and t.wavelengths is None and t.isotropic
    assert exact(t.values, [[0.1, 0.2, 0.3], [0.5, 0.25, 0.125], [-0.0625, 1e-300, 350.0]])
    assert exact(t.sigma, [[0.001, 0.002, 0.003], [0.01] * 3, [0.0] * 3])
    # the file's degrees as written: phi not normalised (725, 360), -0.0 kept
    assert exact(t.angles, [[0, 0, 0, 0], [30, -90, 45, 725], [90, 360, 90, 180.5]])
    s45, c45 = np.sqrt(0.5), np.sqrt(0.5)
    # wi at theta 30, phi -90: (0, -sin 30, cos 30); wo at theta 45, phi 725 = 5 degrees
    np.testing.assert_allclose(t.wi[1], [0.0, -0.5, np.sqrt(3) / 2], atol=1e-16)
    np.testing.assert_allclose(t.wo[1], [s45 * np.cos(np.radians(5)), s45 * np.sin(np.radians(5)),
                                         c45], atol=1e-16)
    np.testing.assert_allclose(t.wi[2], [1.0, 0.0, 0.0], atol=1e-15)
    assert t.metadata == {"units": "1/sr", "sample": "red paint, batch 7",
                          "note": "first line\nsecond line"}


def test_spectral_long_form_by_hand():
    t = gonio_csv.read(DATA / "gonio_spectral.csv")
    assert exact(t.wavelengths, [450.0, 550.0, 650.0])
    assert t.channel_names == ("450nm", "550nm", "650nm")
    # geometries in order of first appearance; -0 and 0 are the same angle; a geometry
    # measured at 450 and 550 nm only has NaN (missing) at 650 nm
    assert exact(t.angles, [[10, 0, 20, 180], [60, 90, 30, 270], [-0.0, 0, 0, 0]])
    nan = np.nan
    assert exact(t.values, [[0.1, 0.2, 0.3], [0.5, 0.4, nan], [0.6, nan, 0.7]])
    assert exact(t.sigma, [[0.01, 0.02, 0.03], [0.05, 0.04, nan], [0.06, nan, 0.07]])


def test_isotropic_flag_is_read_from_the_metadata(tmp_path):
    path = tmp_path / "aniso.csv"
    path.write_text("# isotropic: False\ntheta_i,phi_i,theta_o,phi_o,brdf\n30,0,30,180,0.2\n")
    t = gonio_csv.read(path)
    assert t.is_anisotropic and "isotropic" not in t.metadata


def test_sniff():
    assert gonio_csv.sniff((DATA / "gonio_rgb.csv").read_bytes())
    assert gonio_csv.sniff(b"# a: b\n\nphi_o,theta_o,brdf,phi_i,theta_i\n")
    assert not gonio_csv.sniff(b"lambda,thetai,phi,thetar,phir,f_r11\n")
    assert not gonio_csv.sniff(b"\x00\x01binary")


def test_registry_picks_the_format_by_content(tmp_path):
    path = tmp_path / "table.csv"
    path.write_bytes((DATA / "gonio_spectral.csv").read_bytes())
    assert brdf.read(path).source.format == "gonio-csv"


# -- round trips -----------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["gonio_rgb.csv", "gonio_spectral.csv"])
def test_file_round_trip_is_bit_exact_and_stable(name, tmp_path):
    original = gonio_csv.read(DATA / name)
    again, path = round_trip(original, tmp_path)
    assert_same_samples(original, again)
    # the written file records where the samples came from; the rest of the metadata is kept
    source = json.loads(again.metadata.pop("source"))
    assert source["sha256"] == original.source.sha256 and source["format"] == "gonio-csv"
    assert again.metadata == original.metadata
    # writing the re-read table gives the same bytes: nothing drifts on repeated conversion
    third, path3 = round_trip(gonio_csv.read(path), tmp_path, "third.csv")
    assert path3.read_bytes() == path.read_bytes()


def random_table(channels, rng, n=200, sigma=True, wavelengths=None, **options):
    # directions from random angles, values spanning many magnitudes and signs
    theta_i, theta_o = rng.uniform(0, 90, (2, n))
    phi_i, phi_o = rng.uniform(-360, 720, (2, n))
    values = rng.standard_normal((n, channels)) * 10.0 ** rng.uniform(-300, 300, (n, channels))
    return Table(directions_from_degrees(theta_i, phi_i), directions_from_degrees(theta_o, phi_o),
                 values, sigma=np.abs(values) * 0.1 if sigma else None, wavelengths=wavelengths,
                 **options)


@pytest.mark.parametrize("channels, wavelengths, sigma", [
    (1, None, False), (1, None, True), (3, None, False), (3, None, True),
    (4, [700.0, 400.5, 550.0, 1e3], True), (1, [632.8], False)])
def test_table_from_directions_round_trip(channels, wavelengths, sigma, tmp_path):
    rng = np.random.default_rng(channels + 10 * sigma)
    table = random_table(channels, rng, sigma=sigma, wavelengths=wavelengths,
                         metadata={"units": "1/sr", "n": 3, "notes": ["a", "b"]})
    first, path = round_trip(table, tmp_path)
    # degrees computed from the directions, written exactly; the directions made from them
    # again agree to rounding: an azimuth near 360 degrees carries half an ulp, 2.8e-14 degrees
    # = 5e-16 rad, and the degree/radian conversions and sin, cos a few ulps more
    assert exact(first.angles, np.clip(table.angles, [0, 0, 0, 0], [90, 360, 90, 360]))
    np.testing.assert_allclose(first.wi, table.wi, rtol=0, atol=2e-15)
    np.testing.assert_allclose(first.wo, table.wo, rtol=0, atol=2e-15)
    order = np.argsort(wavelengths) if wavelengths else slice(None)
    assert exact(first.values, table.values[:, order])
    if sigma:
        assert exact(first.sigma, table.sigma[:, order])
    # non-string metadata is written as JSON and read back as text
    assert first.metadata == {"units": "1/sr", "n": "3", "notes": '["a", "b"]'}
    second, _ = round_trip(first, tmp_path, "second.csv")
    assert_same_samples(first, second)


def test_anisotropic_flag_round_trip(tmp_path):
    table = random_table(1, np.random.default_rng(3), isotropic=False)
    again, path = round_trip(table, tmp_path)
    assert again.is_anisotropic and "# isotropic: false\n" in path.read_text()


def test_samples_missing_everywhere_are_left_out(tmp_path):
    table = random_table(3, np.random.default_rng(4), n=5)
    values = table.values.copy()
    values[2] = np.nan
    again, _ = round_trip(table.with_values(values, sigma=table.sigma), tmp_path)
    assert exact(again.values, np.delete(values, 2, axis=0))


def test_spectral_gaps_round_trip(tmp_path):
    table = random_table(3, np.random.default_rng(5), n=6, wavelengths=[400.0, 500.0, 600.0])
    values, sigma = table.values.copy(), table.sigma.copy()
    values[1, 0] = values[4, 2] = sigma[1, 0] = sigma[4, 2] = np.nan
    again, path = round_trip(table.with_values(values, sigma=sigma), tmp_path)
    assert exact(again.values, values) and exact(again.sigma, sigma)
    assert len(path.read_text().splitlines()) == 2 + 18 - 2  # flag, header, 16 rows


def with_nan(table, sigma=False):
    """``table`` with one value (or, with ``sigma``, one standard deviation) missing."""
    values = table.values.copy()
    spread = np.abs(values) * 0.1
    (spread if sigma else values)[0, 1] = np.nan
    return table.with_values(values, sigma=spread)


@pytest.mark.parametrize("change, message", [
    (lambda t: t.with_values(np.ones((len(t), 2)), channel_names=None),
     "2 channels without wavelengths"),
    (with_nan, "missing in some channels only"),
    (lambda t: with_nan(t, sigma=True), "missing sigma"),
    (lambda t: t.with_values(t.values[:, :2], wavelengths=[500.0, 500.0], channel_names=None),
     "repeated wavelengths"),
    (lambda t: t.with_values(t.values, metadata={"a: b": 1}), "metadata key 'a: b'"),
    (lambda t: t.with_values(t.values, metadata={"x": object()}), "metadata['x'] is not JSON"),
])
def test_tables_a_csv_cannot_hold_are_refused(change, message, tmp_path):
    table = change(random_table(3, np.random.default_rng(6), n=4, sigma=False))
    with pytest.raises(InputError) as info:
        gonio_csv.write(table, tmp_path / "x.csv")
    assert message in str(info.value)


def test_multiline_metadata_round_trip(tmp_path):
    table = random_table(1, np.random.default_rng(7), n=3,
                         metadata={"description": "line one\nline two", "operator": "A. Lab"})
    again, _ = round_trip(table, tmp_path)
    assert again.metadata == table.metadata


# -- bad input ------------------------------------------------------------------------------------
BAD = {  # file in tests/data/bad -> (where, text that must appear in the message)
    "gonio_missing_column.csv": ("line 2", "missing column phi_o; expected theta_i, phi_i"),
    "gonio_misspelt_column.csv": ("line 1", "unknown column 'theta_in' (did you mean theta_i?); "
                                            "valid columns: theta_i, phi_i, theta_o, phi_o, brdf"),
    "gonio_extra_column.csv": ("line 1", "unknown column 'temperature'; valid columns: theta_i"),
    "gonio_field_count.csv": ("line 4", "4 fields; expected 5 (theta_i,phi_i,theta_o,phi_o,brdf)"),
    "gonio_empty_value.csv": ("line 3", "empty value in column brdf; expected a number"),
    "gonio_not_a_number.csv": ("line 3", "brdf = '0.2x' is not a number"),
    "gonio_nan.csv": ("line 3", "brdf = nan; expected a finite number"),
    "gonio_inf.csv": ("line 3", "phi_i = inf; expected a finite number"),
    "gonio_theta_95.csv": ("line 3", "theta_o = 95; expected a polar angle in [0, 90] degrees"),
    "gonio_not_utf8.csv": ("line 2", "byte 18 (b'\\xe9') is not UTF-8; expected UTF-8 text"),
    "gonio_duplicate_spectral.csv": ("line 5", "same geometry and wavelength as line 2"),
    "gonio_empty.csv": ("", "empty file; expected a header line naming the columns"),
    "gonio_header_only.csv": ("line 3", "end of file after the header (line 2); expected rows"),
    "gonio_only_comments.csv": ("line 3", "end of file after the comments; expected a header"),
    "gonio_comment_after_header.csv": ("line 3", "comments are only allowed before the header"),
    "gonio_partial_rgb.csv": ("line 1", "missing column brdf_b"),
    "gonio_sigma_mismatch.csv": ("line 1", "column sigma does not match the value columns "
                                           "brdf_r, brdf_g, brdf_b; expected sigma_r, sigma_g"),
    "gonio_negative_sigma.csv": ("line 2", "sigma = -0.01; expected a standard deviation >= 0"),
    "gonio_semicolons.csv": ("line 1", "(fields must be separated by commas)"),
    "gonio_bad_isotropic.csv": ("line 1", "isotropic: 'maybe'; expected true or false"),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_file(name):
    path = DATA / "bad" / name
    where, text = BAD[name]
    with pytest.raises(FormatError) as info:
        brdf.read(path, format="gonio-csv")
    message = str(info.value)
    place = f"{path}:{where}: " if where else f"{path}: "
    assert message.startswith(place) and text in message, message
    assert "\n" not in message


def test_first_bad_line_wins_across_rules(tmp_path):
    # line 3 has an angle out of range, line 4 a NaN: the earlier line is reported
    path = tmp_path / "two.csv"
    path.write_text("theta_i,phi_i,theta_o,phi_o,brdf\n0,0,0,0,1\n91,0,0,0,1\n0,0,0,0,nan\n")
    with pytest.raises(FormatError, match=r"two.csv:line 3: theta_i = 91;"):
        gonio_csv.read(path)


@pytest.mark.parametrize("header, text", [
    ("theta_i,phi_i,theta_o,phi_o,brdf,brdf_r,brdf_g,brdf_b", "both brdf and brdf_r"),
    ("theta_i,phi_i,theta_o,phi_o,brdf_r,brdf_g,brdf_b,wavelength_nm", "wavelength_nm with brdf_r"),
    ("theta_i,phi_i,theta_o,phi_o,brdf_r,brdf_g,brdf_b,sigma_r", "missing column sigma_g, sigma_b"),
    ("theta_i,phi_i,theta_o,phi_o,brdf,brdf", "column brdf appears twice"),
    ("theta_i,phi_i,theta_o,phi_o,brdf,", "column 6 of the header has no name"),
    ("Theta_I,phi_i,theta_o,phi_o,brdf", "'Theta_I' (did you mean theta_i?)"),
    ("theta_i,phi_i,theta_o,phi_o", "missing column brdf;"),
])
def test_bad_headers(header, text, tmp_path):
    path = tmp_path / "h.csv"
    path.write_text(f"{header}\n0,0,0,0,1,1,1,1\n")
    with pytest.raises(FormatError) as info:
        gonio_csv.read(path)
    assert str(info.value).startswith(f"{path}:line 1: ") and text in str(info.value)


# -- a large file (its read time is measured by benchmarks/bench_io.py) --------------------------
@pytest.mark.slow
def test_100k_rows_round_trip(tmp_path):
    table = random_table(3, np.random.default_rng(8), n=100_000)
    path = tmp_path / "big.csv"
    gonio_csv.write(table, path)
    again = gonio_csv.read(path)
    assert exact(again.values, table.values) and exact(again.sigma, table.sigma)


# -- interpolation of a table written from a smooth model -----------------------------------------
STEP = np.radians(5.0)


def from_features(theta_i, x, y):
    """Directions from the coordinates the isotropic table interpolates in: theta_i (wi at
    phi = 0) and wo's polar angle on the disk, (x, y) = theta_o (cos phi_o, sin phi_o)."""
    return (spherical_to_cartesian(theta_i, np.zeros_like(theta_i)),
            spherical_to_cartesian(np.hypot(x, y), np.arctan2(y, x)))


def test_interpolation_reproduces_a_smooth_model(tmp_path):
    model = brdf.parse("lambert(albedo=0.5) + ggx(ks=0.3, alpha=0.8)")
    # a grid of spacing h = 5 degrees in the interpolation coordinates:
    # theta_i in [0, 80], x in [-60, 60], y in [0, 60] degrees
    lo = np.radians([0.0, -60.0, 0.0])
    hi = np.radians([80.0, 60.0, 60.0])
    axes = [np.arange(a, b + STEP / 2, STEP) for a, b in zip(lo, hi)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    wi, wo = from_features(*grid.T)
    table, _ = round_trip(Table(wi, wo, model.eval(wi, wo)), tmp_path)

    # Error bound of linear interpolation over a simplex whose vertices v_k are corners of a
    # grid cell (multilinear interpolation of the cell obeys the same one): Taylor expansion at x
    # gives |f(x) - sum_k l_k f(v_k)| <= M/2 sum_k l_k |v_k - x|^2, and for the corners of a cube
    # of side h, sum_k l_k |v_k - x|^2 = sum_j x_j (h - x_j) <= 3 h^2 / 4 (x relative to the
    # cell's lowest corner). M bounds the Hessian's spectral norm, estimated by central
    # differences over the grid's domain, with a factor 1.5 for maxima between the test points.
    # The swapped pair (wo, wi) that the table averages in obeys the same bound.
    rng = np.random.default_rng(9)
    f = lambda p: model.eval(*from_features(*p.T))[:, 0]  # noqa: E731
    p = rng.uniform(lo, hi, (4000, 3))
    e = 1e-3 * np.eye(3)
    hessian = np.array([[(f(p + e[a] + e[b]) - f(p + e[a] - e[b]) - f(p - e[a] + e[b]) +
                          f(p - e[a] - e[b])) / 4e-6 for b in range(3)] for a in range(3)])
    m = 1.5 * np.abs(np.linalg.eigvalsh(hessian.transpose(2, 0, 1))).max()
    tolerance = 0.5 * m * 0.75 * STEP ** 2

    held_out = rng.uniform(lo + STEP, hi - STEP, (400, 3))
    hwi, hwo = from_features(*held_out.T)
    truth = model.eval(hwi, hwo)
    error = np.abs(table.eval(hwi, hwo) - truth).max()
    assert error <= tolerance
    # the bound is tight enough to tell interpolation from a nearest-sample lookup
    assert np.abs(table.eval(hwi, hwo, method="nearest") - truth).max() > tolerance
