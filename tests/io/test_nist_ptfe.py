"""NIST PTFE reader: the published data set, a hand-made file, and a bad-input corpus."""

import math

import numpy as np
import pytest

import brdf
from brdf.errors import FormatError
from brdf.geometry import directions_from_degrees, reflect
from brdf.io import nist_ptfe
from measured_data import measured, published_sha256

DATA = "nist-ptfe/PTFE.data.csv"
FILE_HEADER = ("lambda,thetai,phi,thetar,phir,f_r11," +
               ",".join(f"f_r{i}{j}/f_r11" for i in range(1, 5) for j in range(1, 5)
                        if (i, j) != (1, 1)))
NIST_HEADER = ("lambda,thetai,phii,thetar,phir,fr11," +
               ",".join(f"m{i}{j}" for i in range(1, 5) for j in range(1, 5) if (i, j) != (1, 1)))
MUELLER = ",0" * 15


@pytest.fixture(scope="module")
def ptfe():
    return brdf.read(measured(DATA))


def write(tmp_path, lines, header=FILE_HEADER, newline="\r\n"):
    path = tmp_path / "ptfe.csv"
    path.write_bytes(newline.join([header, *lines]).encode() + newline.encode())
    return path


# -- the published file -------------------------------------------------------------------------
def test_counts_wavelengths_and_range(ptfe):
    # README: 7,296 rows = 1,824 geometries at each of 0.351, 0.532, 0.633, 1.064 um
    assert ptfe.source.format == "nist-ptfe"
    assert ptfe.values.shape == (1824, 4)
    assert ptfe.metadata["rows"] == 7296
    np.testing.assert_array_equal(ptfe.wavelengths, [351.0, 532.0, 633.0, 1064.0])
    assert ptfe.channel_names == ("351nm", "532nm", "633nm", "1064nm")
    assert not np.isnan(ptfe.values).any()  # every geometry is measured at every wavelength
    assert ptfe.values.min() == 0.232 and ptfe.values.max() == 0.714
    assert ptfe.isotropic


def test_sha256_matches_published_list(ptfe):
    assert ptfe.source.sha256 == published_sha256(DATA)
    assert ptfe.source.size == measured(DATA).stat().st_size


def test_first_rows_by_hand(ptfe):
    # lines 2 and 1826 of the file: the same geometry at 351 and 532 nm,
    # "0.351,-0.001,0,80.0258,-156.038,2.62E-01,..." and "0.532,...,2.65E-01,..."
    t = math.radians(0.001)
    np.testing.assert_allclose(ptfe.wi[0], [-math.sin(t), 0.0, math.cos(t)], atol=1e-15)
    tr, pr = math.radians(80.0258), math.radians(-156.038)
    np.testing.assert_allclose(ptfe.wo[0], [math.sin(tr) * math.cos(pr),
                                            math.sin(tr) * math.sin(pr), math.cos(tr)],
                               atol=1e-15)
    assert ptfe.values[0, 0] == 0.262 and ptfe.values[0, 1] == 0.265


def test_incidence_angles(ptfe):
    theta_i = np.round(ptfe.angles[:, 0], 6)
    # thetai = -75 ... -15 and -0.001 at phi = 0: folded to azimuth 180
    assert sorted(set(theta_i)) == [0.001, 15.0, 30.0, 45.0, 60.0, 75.0]
    np.testing.assert_allclose(ptfe.angles[:, 1], 180.0)
    assert ptfe.angles[:, 2].max() == pytest.approx(81.8699)


def test_forward_peak_near_mirror(ptfe):
    # README: for thetai = -75 the largest f_r11 is at thetar = 80, phir = +/-24 deg; with a
    # negative theta read as azimuth + 180 that is the forward side, near wi's mirror direction
    at75 = np.flatnonzero(np.isclose(ptfe.angles[:, 0], 75.0))
    k = at75[np.argmax(ptfe.values[at75, 1])]
    to_mirror = math.degrees(math.acos(reflect(ptfe.wi[k]) @ ptfe.wo[k]))
    to_source = math.degrees(math.acos(ptfe.wi[k] @ ptfe.wo[k]))
    assert to_mirror < 25.0 and to_source > 140.0
    np.testing.assert_allclose(ptfe.angles[k, 2:], [80.0258, 360.0 - 23.9625])


def test_directional_albedo_close_to_but_below_one(ptfe):
    # sintered PTFE is a near-perfect diffuser: a(wi) at 532 nm between 0.97 and 1 for
    # theta_i up to 60 deg. The data reach theta_r = 81.87 deg only; beyond, the interpolant
    # takes the nearest sample.
    theta = np.array([0.0, 15.0, 30.0, 45.0, 60.0])
    albedo, error = ptfe.albedo(directions_from_degrees(theta, 0.0 * theta), return_error=True)
    assert np.all((albedo[:, 1] > 0.97) & (albedo[:, 1] < 1.0)), albedo[:, 1]
    assert np.all(error[:, 1] < 0.005), error[:, 1]


# -- hand-made files ----------------------------------------------------------------------------
@pytest.mark.parametrize("header", [FILE_HEADER, NIST_HEADER, NIST_HEADER.upper()])
def test_both_header_spellings(tmp_path, header):
    path = write(tmp_path, [f"0.5,-30,0,30,0,0.3{MUELLER}"], header=header)
    assert nist_ptfe.sniff(path.read_bytes())
    t = nist_ptfe.read(path)
    assert t.values.tolist() == [[0.3]] and t.wavelengths.tolist() == [500.0]


def test_groups_by_geometry_with_nan_for_missing(tmp_path):
    path = write(tmp_path, [f"0.633,-30,0,20,10,0.31{MUELLER}",
                            f"0.532,-30,0,20,10,0.32{MUELLER}",
                            f"0.532,-45,0,40,0,0.33{MUELLER}"], newline="\n")
    t = nist_ptfe.read(path)
    # wavelengths sorted; geometries in order of first appearance
    assert t.wavelengths.tolist() == [532.0, 633.0]
    np.testing.assert_array_equal(t.values, [[0.32, 0.31], [0.33, np.nan]])
    # thetai = -45 at phi = 0 is theta 45 at azimuth 180; thetar = 40 at phir = 0 stays put
    np.testing.assert_allclose(t.angles[1], [45.0, 180.0, 40.0, 0.0], atol=1e-12)


def test_sniff_rejects_other_tables():
    assert not nist_ptfe.sniff(b"theta_i,phi_i,theta_o,phi_o,brdf\n0,0,0,0,0.3\n")
    assert not nist_ptfe.sniff(b"31\n400 410\n")
    assert not nist_ptfe.sniff(b"")


# -- bad input ----------------------------------------------------------------------------------
GOOD = f"0.532,-30,0,30,0,0.3{MUELLER}"
BAD = [
    # (name, file bytes, where, text expected in the message)
    ("not utf-8", (FILE_HEADER + "\n" + GOOD + "\n0.5\xff").encode("latin-1"), "line 3",
     "not UTF-8"),
    ("empty", b"", "", "empty file"),
    ("blank", b" \r\n\r\n", "", "empty file"),
    ("header only", (FILE_HEADER + "\r\n").encode(), "line 2", "no data rows"),
    ("misspelt column", FILE_HEADER.replace(",phi,", ",phy,").encode() + b"\n" + GOOD.encode(),
     "line 1", "column 3 is 'phy'; expected 'phi' or 'phii'"),
    ("missing column", FILE_HEADER.rsplit(",", 1)[0].encode() + b"\n" + GOOD.encode(),
     "line 1", "20 columns; expected 21: lambda,thetai,phi"),
    ("short row", f"{FILE_HEADER}\n{GOOD}\n{GOOD[:-2]}".encode(), "line 3",
     "20 fields; expected 21"),
    ("truncated mid-row", f"{FILE_HEADER}\n{GOOD}\n0.532,-30,0,3".encode(), "line 3",
     "4 fields; expected 21"),
    ("long row", f"{FILE_HEADER}\n{GOOD},0".encode(), "line 2", "22 fields"),
    ("blank line inside", f"{FILE_HEADER}\n\n{GOOD}".encode(), "line 2", "1 fields"),
    ("not a number", f"{FILE_HEADER}\n{GOOD}\n0.532,-30,0,3O,0,0.3{MUELLER}".encode(),
     "line 3", "column thetar: '3O' is not a number"),
    ("empty field", f"{FILE_HEADER}\n0.532,,0,30,0,0.3{MUELLER}".encode(), "line 2",
     "column thetai: is empty"),
    ("nan brdf", f"{FILE_HEADER}\n0.532,-30,0,30,0,nan{MUELLER}".encode(), "line 2",
     "column f_r11: 'nan' is not finite"),
    ("inf mueller", f"{FILE_HEADER}\n0.532,-30,0,30,0,0.3{MUELLER[:-2]},-inf".encode(),
     "line 2", "column f_r44/f_r11: '-inf' is not finite"),
    ("theta out of range", f"{FILE_HEADER}\n{GOOD}\n0.532,-30,0,95,0,0.3{MUELLER}".encode(),
     "line 3", "column thetar: 95 deg is outside the range [-90, 90]"),
    ("azimuth out of range", f"{FILE_HEADER}\n0.532,-30,0,30,361,0.3{MUELLER}".encode(),
     "line 2", "column phir: 361 deg is outside"),
    ("zero wavelength", f"{FILE_HEADER}\n0,-30,0,30,0,0.3{MUELLER}".encode(), "line 2",
     "column lambda: 0 um; expected a positive wavelength"),
    ("duplicate", f"{FILE_HEADER}\n{GOOD}\n0.633{GOOD[5:]}\n{GOOD}".encode(), "line 4",
     "repeats the wavelength and geometry of line 2"),
]


@pytest.mark.parametrize("name, data, where, text", BAD, ids=[b[0] for b in BAD])
def test_bad_input(tmp_path, name, data, where, text):
    path = tmp_path / "bad.csv"
    path.write_bytes(data)
    with pytest.raises(FormatError) as info:
        nist_ptfe.read(path)
    message = str(info.value)
    assert info.value.where == where and text in message, message
    assert "\n" not in message and message.startswith(str(path))
