"""MERL binary tables (docs/conventions.md §6): file format, index and scale, lookup, bad input.

Directions in the oracles are built by hand from Rusinkiewicz angles (:func:`pair_from_angles`),
so the expected grid coordinates are known exactly without the forward transform under test.
"""

import hashlib
import math
import struct
import sys
from pathlib import Path

import numpy as np
import pytest

import brdf
from brdf.errors import FormatError, InputError
from brdf.io import merl
from brdf.table import Table

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from bench_merl import numpy_trilinear  # noqa: E402  (the plain-numpy reference lookup)

SPEC = "lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.2)"
SCALE = (1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0)  # docs/conventions.md §6
FILE_BYTES = 34_992_012
N = 1_458_000


def pair_from_angles(theta_h, theta_d, phi_d, phi_h=0.0):
    """``(wi, wo)`` with the given Rusinkiewicz angles, built by hand (Rusinkiewicz 1998, sec. 3).

    With phi_h = 0 the half vector is h = (sin th, 0, cos th) and the frame around it is
    x' = (cos th, 0, -sin th), y' = y, z' = h; wi is the difference vector (spherical angles
    theta_d, phi_d) in that frame, wo is wi mirrored about h; then both turn by phi_h about z.
    """
    theta_h, theta_d, phi_d, phi_h = np.broadcast_arrays(
        *(np.asarray(a, dtype=float) for a in (theta_h, theta_d, phi_d, phi_h)))
    sh, ch = np.sin(theta_h), np.cos(theta_h)
    dx = np.sin(theta_d) * np.cos(phi_d)
    dy = np.sin(theta_d) * np.sin(phi_d)
    dz = np.cos(theta_d)
    wi = np.stack([dx * ch + dz * sh, dy, -dx * sh + dz * ch], axis=-1)
    h = np.stack([sh, np.zeros_like(sh), ch], axis=-1)
    wo = 2.0 * np.sum(wi * h, axis=-1, keepdims=True) * h - wi
    c, s = np.cos(phi_h)[..., None], np.sin(phi_h)[..., None]

    def turn(v):
        return np.stack([v[..., 0] * c[..., 0] - v[..., 1] * s[..., 0],
                         v[..., 0] * s[..., 0] + v[..., 1] * c[..., 0], v[..., 2]], axis=-1)
    return turn(wi), turn(wo)


def angles_at(u, v, w):
    """Rusinkiewicz angles of continuous grid coordinates: theta_h = (u/90)^2 pi/2,
    theta_d = v (pi/2)/90, phi_d = w pi/180 (docs/conventions.md §6)."""
    return (np.asarray(u) / 90.0) ** 2 * math.pi / 2, np.asarray(v) * math.pi / 180.0, \
        np.asarray(w) * math.pi / 180.0


def random_coordinates(rng, n, top=(90.0, 90.0, 180.0)):
    """``n`` random grid coordinates below ``top`` with both directions above the horizon,
    and their direction pairs (random phi_h, and phi_d shifted by pi for half of them)."""
    u = rng.uniform(0.0, top[0], 4 * n)
    v = rng.uniform(0.0, top[1], 4 * n)
    w = rng.uniform(0.0, top[2], 4 * n)
    shift = math.pi * rng.integers(0, 2, 4 * n)  # phi_d and phi_d + pi are the same node
    theta_h, theta_d, phi_d = angles_at(u, v, w)
    wi, wo = pair_from_angles(theta_h, theta_d, phi_d + shift, rng.uniform(0, 2 * math.pi, 4 * n))
    keep = np.flatnonzero((wi[:, 2] > 1e-3) & (wo[:, 2] > 1e-3))[:n]
    return u[keep], v[keep], w[keep], wi[keep], wo[keep]


def raw_bytes(raw, dims=(90, 90, 180)):
    """A MERL file's bytes written independently of the module: header + float64 samples."""
    return struct.pack("<3i", *dims) + np.asarray(raw, dtype="<f8").tobytes()


def random_pairs(rng, n):
    v = rng.normal(size=(2, n, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[..., 2] = np.abs(v[..., 2])
    return v[0], v[1]


@pytest.fixture(scope="module")
def model():
    return brdf.parse(SPEC)


@pytest.fixture(scope="module")
def smooth(model):
    """The model sampled at the grid nodes (nodes below the horizon missing)."""
    wi, wo = merl.grid_directions()
    return merl.MerlTable.from_grid_values(model.eval(wi, wo), name="smooth")


@pytest.fixture(scope="module")
def smooth_file(smooth, tmp_path_factory):
    path = tmp_path_factory.mktemp("merl") / "smooth.binary"
    merl.write(smooth, path)
    return path


@pytest.fixture(scope="module")
def linear_raw():
    """Stored values linear in the node indices: 1 + c + i/2 + j/4 + k/8."""
    c, i, j, k = np.meshgrid(np.arange(3), np.arange(90), np.arange(90), np.arange(180),
                             indexing="ij")
    return 1.0 + c + 0.5 * i + 0.25 * j + 0.125 * k


# --- file format ------------------------------------------------------------------------------

def test_written_file_has_the_documented_layout(smooth, smooth_file):
    data = smooth_file.read_bytes()
    assert len(data) == FILE_BYTES
    assert struct.unpack("<3i", data[:12]) == (90, 90, 180)
    # sample (c, i, j, k) sits at byte 12 + 8 (c N + 16200 i + 180 j + k)
    (stored,) = struct.unpack("<d", data[12 + 8 * (N + 16200 * 10 + 180 * 20 + 30):][:8])
    assert stored == smooth.raw[1, 10, 20, 30]


def test_read_write_round_trip_is_bit_exact(tmp_path):
    rng = np.random.default_rng(1)
    raw = rng.normal(size=3 * N) * 10.0 ** rng.integers(-300, 300, 3 * N)
    raw[:6] = [-0.0, 5e-324, -5e-324, np.finfo(float).max, -1.0, 0.0]  # signed zero, subnormals
    data = raw_bytes(raw)
    src, out = tmp_path / "in.binary", tmp_path / "out.binary"
    src.write_bytes(data)
    merl.write(merl.read(src), out)
    assert out.read_bytes() == data


def test_model_table_round_trip_is_bit_exact(smooth_file, tmp_path):
    out = tmp_path / "again.binary"
    brdf.io.write(brdf.io.read(smooth_file), out)
    assert out.read_bytes() == smooth_file.read_bytes()


def test_read_gives_provenance_and_channels(smooth_file):
    t = brdf.io.read(smooth_file)
    assert isinstance(t, merl.MerlTable)
    assert t.source.sha256 == hashlib.sha256(smooth_file.read_bytes()).hexdigest()
    assert t.source.format == "merl" and t.source.size == FILE_BYTES
    assert (t.channels, t.channel_names, t.isotropic, len(t)) == (3, ("r", "g", "b"), True, N)
    assert t.name == "smooth.binary" and t.format == "merl"


def test_sniffing_finds_merl_without_the_extension(smooth_file, tmp_path):
    other = tmp_path / "material.dat"
    other.symlink_to(smooth_file)
    assert brdf.io.format_of(other) is merl
    assert not merl.sniff(struct.pack("<3i", 90, 90, 360))
    assert not merl.sniff(b"theta_i,phi_i,theta_o,phi_o,brdf\n")


# --- index and scale ------------------------------------------------------------------------

# theta_d = 0 (wi = wo) has no phi_d: the lookup reads k = 0 there, so nodes with j = 0 use k = 0
NODES = [(0, 0, 0), (45, 30, 60), (12, 77, 179), (89, 1, 90), (60, 29, 1)]


@pytest.fixture(scope="module")
def marked():
    """Stored value 1000 everywhere except the NODES, which hold 3 + 2 n + c (channel c)."""
    raw = np.full((3, 90, 90, 180), 1000.0)
    for n, (i, j, k) in enumerate(NODES):
        raw[:, i, j, k] = [3.0 + 2 * n, 4.0 + 2 * n, 5.0 + 2 * n]
    return merl.MerlTable(raw)


def test_values_follow_the_documented_index(marked):
    for n, (i, j, k) in enumerate(NODES):
        row = k + 180 * j + 16200 * i  # docs/conventions.md §6
        expected = [(3.0 + 2 * n) / 1500, (4.0 + 2 * n) * 1.15 / 1500, (5.0 + 2 * n) * 1.66 / 1500]
        np.testing.assert_allclose(marked.values[row], expected, rtol=1e-15)


@pytest.mark.parametrize("method", ["linear", "nearest"])
def test_eval_at_hand_computed_nodes_gives_stored_times_scale(marked, method):
    # node (i, j, k) sits at theta_h = (i/90)^2 90 deg, theta_d = j deg, phi_d = k deg
    for n, (i, j, k) in enumerate(NODES):
        theta_h = (i / 90.0) ** 2 * math.pi / 2
        for phi_d, phi_h in ((math.radians(k), 0.0), (math.radians(k) + math.pi, 2.0)):
            wi, wo = pair_from_angles(theta_h, math.radians(j), phi_d, phi_h)
            assert wi[2] > 0 and wo[2] > 0
            expected = np.array([3.0 + 2 * n, 4.0 + 2 * n, 5.0 + 2 * n]) * SCALE
            np.testing.assert_allclose(marked.eval(wi, wo, method=method), expected, rtol=1e-9)


def test_cell_centre_is_the_mean_of_its_corners():
    raw = np.ones((3, 90, 90, 180))
    corners = [(i, j, k) for i in (45, 46) for j in (30, 31) for k in (179, 0)]  # phi_d wraps
    for n, node in enumerate(corners):
        raw[(slice(None),) + node] = n + 1.0
    t = merl.MerlTable(raw)
    wi, wo = pair_from_angles(*angles_at(45.5, 30.5, 179.5))
    np.testing.assert_allclose(t.eval(wi, wo), 4.5 * np.array(SCALE), rtol=1e-9)  # mean of 1..8


def test_nearest_rounds_to_the_closest_node(linear_raw):
    t = merl.MerlTable(linear_raw)
    wi, wo = pair_from_angles(*angles_at([45.3, 45.6], [30.4, 30.6], [60.2, 179.7]))
    got = t.eval(wi, wo, method="nearest")
    nodes = [(45, 30, 60), (46, 31, 0)]  # 179.7 rounds to 180, which is phi_d = 0
    expected = [[linear_raw[c][node] * SCALE[c] for c in range(3)] for node in nodes]
    np.testing.assert_allclose(got, expected, rtol=1e-12)


def test_trilinear_reproduces_a_function_linear_in_the_indices(linear_raw):
    t = merl.MerlTable(linear_raw)
    u, v, w, wi, wo = random_coordinates(np.random.default_rng(2), 5000, top=(89, 89, 179))
    # with theta_h -> 0 the azimuth of the half vector, and so phi_d, is lost to rounding
    # (error ~ 1e-16 / theta_h): from u = 0.5 on, theta_h > 5e-5 and phi_d is good to 1e-11
    far = u > 0.5
    got = t.eval(wi[far], wo[far])
    for c in range(3):
        expected = (1.0 + c + 0.5 * u[far] + 0.25 * v[far] + 0.125 * w[far]) * SCALE[c]
        np.testing.assert_allclose(got[:, c], expected, rtol=1e-9)


def test_top_of_theta_is_clamped_to_the_last_node(linear_raw):
    t = merl.MerlTable(linear_raw)
    wi, wo = pair_from_angles(math.radians(89.9), math.radians(0.5), 1.55)  # u = 89.95
    assert wi[2] > 0 and wo[2] > 0
    expected = [(1.0 + c + 0.5 * 89 + 0.25 * 0.5 + 0.125 * math.degrees(1.55)) * SCALE[c]
                for c in range(3)]
    np.testing.assert_allclose(t.eval(wi, wo), expected, rtol=1e-9)


def test_grid_directions_are_the_nodes():
    wi, wo = merl.grid_directions()
    assert wi.shape == wo.shape == (N, 3) and not wi.flags.writeable
    np.testing.assert_allclose(np.linalg.norm(wi, axis=-1), 1.0, atol=1e-14)
    for i, j, k in NODES:
        hand = pair_from_angles((i / 90.0) ** 2 * math.pi / 2, math.radians(j), math.radians(k))
        row = k + 180 * j + 16200 * i
        np.testing.assert_allclose(wi[row], hand[0], atol=1e-15)
        np.testing.assert_allclose(wo[row], hand[1], atol=1e-15)


# --- lookup properties ----------------------------------------------------------------------

@pytest.mark.parametrize("method", ["linear", "nearest"])
def test_eval_is_exactly_reciprocal(smooth, method):
    wi, wo = random_pairs(np.random.default_rng(3), 20000)
    np.testing.assert_array_equal(smooth.eval(wi, wo, method=method),
                                  smooth.eval(wo, wi, method=method))


def test_below_the_horizon_is_zero(smooth):
    wi = np.array([[0.0, 0.6, 0.8], [0.6, 0.0, -0.8]])
    wo = np.array([[0.6, 0.0, -0.8], [0.0, 0.0, 1.0]])
    assert np.all(smooth.eval(wi, wo) == 0.0)


def test_lambert_table_is_reproduced_everywhere_even_near_grazing():
    # a constant is any convex combination of itself: masked corners must not bias it
    lam = brdf.parse("lambert(albedo=[0.5,0.4,0.3])")
    wi, wo = merl.grid_directions()
    t = merl.MerlTable.from_grid_values(lam.eval(wi, wo))
    a, b = random_pairs(np.random.default_rng(4), 20000)
    np.testing.assert_allclose(t.eval(a, b), lam.eval(a, b), rtol=1e-12)


def test_smooth_model_within_the_table_resolution(smooth, model):
    """Tolerance: the lookup is a convex combination of the valid corner samples of the cell
    holding the query, so it may differ from the model by at most how much the model varies
    between the query and those corners (plus rounding of value / scale * scale)."""
    rng = np.random.default_rng(5)
    u, v, w, wi, wo = random_coordinates(rng, 20000)
    got, truth = smooth.eval(wi, wo), model.eval(wi, wo)
    uc, vc = np.minimum(u, 89.0), np.minimum(v, 89.0)
    i0, j0, k0 = np.minimum(uc.astype(int), 88), np.minimum(vc.astype(int), 88), w.astype(int)
    valid = ~np.isnan(smooth.values[:, 0].reshape(90, 90, 180))
    bound = np.zeros_like(truth)
    covered = np.zeros(len(u), dtype=bool)
    for di in (0, 1):
        for dj in (0, 1):
            for dk in (0, 1):
                i, j, k = i0 + di, j0 + dj, (k0 + dk) % 180
                weight = (np.abs(1 - di - (uc - i0)) * np.abs(1 - dj - (vc - j0))
                          * np.abs(1 - dk - (w - k0)))
                use = valid[i, j, k] & (weight > 0)
                corner = model.eval(*pair_from_angles(*angles_at(i, j, k)))
                gap = np.where(use[:, None], np.abs(corner - truth), 0.0)
                bound = np.maximum(bound, gap)
                covered |= use
    assert covered.mean() > 0.99  # the rest fall back on the nearest valid sample
    err = np.abs(got - truth)[covered]
    assert np.all(err <= bound[covered] * (1 + 1e-9) + 1e-12 * truth[covered])
    assert np.median(err / truth[covered]) < 1e-3  # 5e-4 measured: GGX alpha 0.2, 90 x 90 x 180


def test_numba_lookup_matches_the_numpy_reference(smooth):
    rng = np.random.default_rng(6)
    raw = smooth.raw.copy()
    raw[rng.random(raw.shape) < 0.3] = -1.0  # many missing samples, some whole cells
    t = merl.MerlTable(raw)
    wi, wo = random_pairs(rng, 50000)
    grid = t.values.reshape(90, 90, 180, 3)
    reference = numpy_trilinear(grid, merl.fill_missing(grid), wi, wo)
    np.testing.assert_allclose(t.eval(wi, wo), reference, rtol=1e-9, atol=1e-13)


# --- missing samples --------------------------------------------------------------------------

@pytest.fixture(scope="module")
def holed(linear_raw):
    """The linear table with the block i in [40, 44), j in [20, 24), k in [50, 56) missing."""
    raw = linear_raw.copy()
    raw[:, 40:44, 20:24, 50:56] = -1000.0
    return merl.MerlTable(raw)


def test_missing_samples_are_nan_in_values(holed):
    missing = holed.missing.reshape(90, 90, 180, 3)
    assert missing[40:44, 20:24, 50:56].all() and missing.sum() == 4 * 4 * 6 * 3


def test_a_missing_corner_is_left_out_and_the_weights_renormalised(holed, linear_raw):
    # cell (39..40, 19..20, 49..50): only corner (40, 20, 50) is missing; at the centre the
    # 8 weights are equal, so the lookup is the mean of the 7 valid corners
    wi, wo = pair_from_angles(*angles_at(39.5, 19.5, 49.5))
    valid = [(i, j, k) for i in (39, 40) for j in (19, 20) for k in (49, 50)
             if (i, j, k) != (40, 20, 50)]
    expected = [np.mean([linear_raw[c][n] for n in valid]) * SCALE[c] for c in range(3)]
    values, inside = holed.eval_one_sided(wi[None], wo[None])
    np.testing.assert_allclose(values[0], expected, rtol=1e-9)
    assert inside[0]


@pytest.mark.parametrize("method", ["linear", "nearest"])
def test_a_fully_missing_cell_uses_the_nearest_valid_sample(holed, linear_raw, method):
    # all corners of the cell of (40.2, 21.4, 52.3) are missing; its nearest node (40, 21, 52)
    # is 1 node from the valid (39, 21, 52), 2 from j = 19 and 3 from k = 49 or i = 44
    wi, wo = pair_from_angles(*angles_at(40.2, 21.4, 52.3))
    values, inside = holed.eval_one_sided(wi[None], wo[None], method=method)
    np.testing.assert_allclose(values[0], [linear_raw[c, 39, 21, 52] * SCALE[c] for c in range(3)],
                               rtol=1e-12)
    assert not inside[0]


def test_missing_samples_never_leak_into_the_lookup():
    rng = np.random.default_rng(7)
    raw = rng.uniform(1.0, 2.0, (3, 90, 90, 180))
    raw[rng.random(raw.shape) < 0.2] = -1e6  # a leak would drag values far below 1 x scale
    t = merl.MerlTable(raw)
    wi, wo = random_pairs(rng, 50000)
    for method in ("linear", "nearest"):
        got = t.eval(wi, wo, method=method)
        assert np.all(got >= 1.0 * np.array(SCALE) * (1 - 1e-12))
        assert np.all(got <= 2.0 * np.array(SCALE) * (1 + 1e-12))


# --- making tables ----------------------------------------------------------------------------

def test_writing_a_model_resamples_it_at_the_nodes(model, tmp_path):
    path = tmp_path / "model.binary"
    brdf.io.write(model, path)
    t = merl.read(path)
    wi, wo = merl.grid_directions()
    above = (wi[:, 2] > 1e-9) & (wo[:, 2] > 1e-9)
    np.testing.assert_allclose(t.values[above], model.eval(wi[above], wo[above]), rtol=1e-14)
    assert np.isnan(t.values[~above]).all()
    assert np.all(t.raw.reshape(3, N)[:, ~above] == -1.0)


def test_from_grid_values_marks_nan_and_negative_as_missing():
    values = np.full((N, 3), 0.25)
    values[5] = [np.nan, -0.1, 0.0]
    t = merl.MerlTable.from_grid_values(values)
    assert np.isnan(t.values[5, :2]).all() and t.values[5, 2] == 0.0
    assert t.raw[0, 0, 0, 5] < 0 and t.raw[1, 0, 0, 5] < 0


def test_table_albedo_matches_the_model(smooth, model):
    # quadrature over the lookup (Table.albedo) against the model's own albedo: 0.1 % measured
    wi = brdf.geometry.directions_from_degrees([0.0, 30.0, 60.0, 80.0], [0.0, 30.0, 200.0, 90.0])
    np.testing.assert_allclose(smooth.albedo(wi), model.albedo(wi), rtol=5e-3)


# --- bad input ----------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def good_raw():
    return np.ones(3 * N)


def write_bad(tmp_path, data, name="bad.binary"):
    path = tmp_path / name
    path.write_bytes(data)
    return path


def check_error(path, *parts):
    with pytest.raises(FormatError) as err:
        merl.read(path)
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"{path}:")
    for part in parts:
        assert part in message, message
    return message


def test_truncated_header(tmp_path):
    check_error(write_bad(tmp_path, b"\x5a\x00\x00\x00\x5a"), ":byte 5:", "truncated",
                "90, 90, 180")


def test_truncated_samples(tmp_path, good_raw):
    path = write_bad(tmp_path, raw_bytes(good_raw)[:12 + 8000])
    check_error(path, ":byte 8012:", "truncated", "8,012 bytes", "34,992,012")


def test_oversized(tmp_path, good_raw):
    path = write_bad(tmp_path, raw_bytes(good_raw) + b"\0" * 16)
    check_error(path, ":byte 34992012:", "oversized", "34,992,028 bytes", "34,992,012")


@pytest.mark.parametrize("dims, byte", [((90, 90, 360), 8), ((180, 90, 180), 0),
                                        ((90, 45, 180), 4)])
def test_wrong_dimensions(tmp_path, dims, byte):
    path = write_bad(tmp_path, raw_bytes(np.ones(10), dims))
    check_error(path, f":byte {byte}:", ", ".join(map(str, dims)), "expected 90, 90, 180")


def test_big_endian_dimensions_get_a_hint(tmp_path):
    path = write_bad(tmp_path, struct.pack(">3i", 90, 90, 180) + b"\0" * 24)
    check_error(path, ":byte 0:", "big-endian")


@pytest.mark.parametrize("index, value, byte, text", [
    # (c, i, j, k) = (1, 2, 3, 4): 12 + 8 (1 458 000 + 2 16 200 + 3 180 + 4) = 11 927 564
    ((1, 2, 3, 4), np.nan, 11_927_564, "nan (channel g, i_theta_h 2, i_theta_d 3, i_phi_d 4)"),
    # the last sample: 12 + 8 (3 1 458 000 - 1) = 34 992 004
    ((2, 89, 89, 179), -np.inf, 34_992_004, "-inf (channel b, i_theta_h 89"),
])
def test_non_finite_values(tmp_path, good_raw, index, value, byte, text):
    raw = good_raw.reshape(3, 90, 90, 180).copy()
    raw[index] = value
    raw[2, 89, 89, 179] = value  # a later one too: the message names the first
    path = write_bad(tmp_path, raw_bytes(raw))
    check_error(path, f":byte {byte}:", text, "expected a finite number")


def test_missing_file(tmp_path):
    check_error(tmp_path / "absent.binary", "no such file")


def test_non_rgb_tables_cannot_be_written(tmp_path):
    wi = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])
    grey = Table(wi, wi, [[0.3], [0.3]], name="grey")
    with pytest.raises(InputError, match=r"grey is non-RGB with 1 channel\(s\)"):
        merl.write(grey, tmp_path / "grey.binary")
    spectral = Table(wi, wi, np.full((2, 3), 0.3), wavelengths=[450, 550, 650], name="spec")
    with pytest.raises(InputError, match="spec is spectral with 3 channel"):
        merl.write(spectral, tmp_path / "spec.binary")
    assert not (tmp_path / "grey.binary").exists()


def test_constructor_rejects_bad_arrays():
    with pytest.raises(InputError, match=r"\(3, 90, 90, 180\)"):
        merl.MerlTable(np.ones((3, 90, 90, 90)))
    raw = np.ones((3, 90, 90, 180))
    raw[0, 0, 0, 0] = np.nan
    with pytest.raises(InputError, match="NaN or infinite"):
        merl.MerlTable(raw)
    with pytest.raises(InputError, match="'cubic'"):
        merl.MerlTable(np.ones((3, 90, 90, 180))).eval([0, 0, 1], [0, 0, 1], method="cubic")
