"""Cornell/pbrt ``.brdf`` reader: the five published paints, hand-made files, bad input."""

import math

import numpy as np
import pytest

import brdf
from brdf.errors import FormatError
from brdf.geometry import reflect
from brdf.io import cornell
from measured_data import measured, published_sha256

PAINTS = ("acryl_blue", "cayman", "garnet_red", "krylon_blue", "mystique")
# largest value of each file (README: 29.8 for acryl_blue to 655 for mystique, cayman 645.8)
MAXIMA = {"acryl_blue": 29.8, "cayman": 645.8, "mystique": 655.2}


def relative(paint):
    return f"cornell-paints/{paint}.brdf"


@pytest.fixture(scope="module", params=PAINTS)
def paint(request):
    return request.param, brdf.read(measured(relative(request.param)))


def test_counts_and_wavelengths(paint):
    name, t = paint
    assert t.source.format == "cornell" and t.isotropic
    assert t.values.shape == (1439, 31)
    np.testing.assert_array_equal(t.wavelengths, np.arange(400.0, 701.0, 10.0))
    assert t.values.min() >= 0.0
    if name in MAXIMA:
        assert t.values.max() == pytest.approx(MAXIMA[name], abs=0.05)
    assert 29.8 <= t.values.max() <= 655.2


def test_geometry_as_described(paint):
    _, t = paint
    theta_i, phi_i, theta_s, _ = t.angles.T
    # README: theta_i = 10 ... 80 deg (178 to 182 records each), phi_i = 0, theta_s <= 79 deg
    levels, counts = np.unique(np.round(theta_i, 4), return_counts=True)
    np.testing.assert_allclose(levels, np.arange(10.0, 81.0, 10.0), atol=1e-4)
    assert counts.min() >= 178 and counts.max() <= 182
    np.testing.assert_array_equal(phi_i, 0.0)
    assert theta_s.max() < 79.1


def test_maximum_at_mirror_direction(paint):
    # the specular peak: both directions point away from the surface, so the largest value
    # sits where wo is wi reflected about the normal (within the 1 deg sampling of theta_s)
    _, t = paint
    k = np.unravel_index(np.argmax(t.values), t.values.shape)[0]
    assert math.degrees(math.acos(reflect(t.wi[k]) @ t.wo[k])) < 1.0


def test_sha256_matches_published_list(paint):
    name, t = paint
    assert t.source.sha256 == published_sha256(relative(name))


def test_first_record_by_hand():
    t = cornell.read(measured(relative("acryl_blue")))
    # first record: "0.872665 0.000000 0.573513 0.000000 0.014369 0.018226 ..."
    a, b = 0.872665, 0.573513
    np.testing.assert_allclose(t.wi[0], [math.sin(a), 0.0, math.cos(a)], atol=1e-15)
    np.testing.assert_allclose(t.wo[0], [math.sin(b), 0.0, math.cos(b)], atol=1e-15)
    assert t.values[0, :2].tolist() == [0.014369, 0.018226]


def test_description_from_comments():
    cayman = cornell.read(measured(relative("cayman")))
    assert cayman.metadata["description"] == ("Cornell University, Program of Computer Graphics"
                                              "\nCayman Metallic\nHigh-gloss Paint")
    assert cayman.metadata["comments"][3] == "num wls"
    # acryl_blue has only the labels of the count, the wavelengths and the records
    assert cornell.read(measured(relative("acryl_blue"))).metadata["description"] == ""


# -- hand-made files ----------------------------------------------------------------------------
SMALL = ("# a test paint\n\n# num wls\n2\n# wls\n500 600\n"
         "0.5 0 0.5 3.141593 0.1 0.2\n0.5 0 0.7 -1.5 0.3 0.4\n")


def test_records_are_a_stream(tmp_path):
    # line breaks and comments may fall anywhere between numbers
    path = tmp_path / "stream.brdf"
    path.write_text("2 500 # first\n 600 0.5 0 0.5\n3.141593 0.1 0.2 0.5 0 0.7 -1.5\n0.3 0.4")
    t = cornell.read(path)
    assert t.wavelengths.tolist() == [500.0, 600.0]
    np.testing.assert_array_equal(t.values, [[0.1, 0.2], [0.3, 0.4]])
    np.testing.assert_allclose(t.wo[0], [-math.sin(0.5), 0.0, math.cos(0.5)], atol=1e-6)
    assert t.metadata["comments"] == ["first"] and t.metadata["description"] == ""


def test_small_file_and_description(tmp_path):
    path = tmp_path / "small.brdf"
    path.write_bytes(SMALL.replace("\n", "\r\n").encode())
    t = cornell.read(path)
    assert t.values.shape == (2, 2) and t.metadata["description"] == "a test paint"
    # an angle printed with 6 decimals may exceed pi/2 by rounding: kept above the horizon
    path.write_text(SMALL.replace("0.5 0 0.7", "0.5 0 1.5707965"))
    assert cornell.read(path).wo[1, 2] >= 0.0


def test_sniff():
    assert cornell.sniff(SMALL.encode())
    assert cornell.sniff(measured(relative("cayman")).read_bytes()[:4096])
    assert not cornell.sniff(measured("curet/abrdf.dat").read_bytes()[:4096])
    assert not cornell.sniff(measured("curet/table.txt").read_bytes()[:4096])
    assert not cornell.sniff(b"theta_i,phi_i,theta_o,phi_o,brdf\n")
    assert not cornell.sniff(b"# only a comment\n")
    assert not cornell.sniff(b"2 600 500 0 0 0 0 1 1\n")  # wavelengths must increase


# -- bad input ----------------------------------------------------------------------------------
RECORD = "0.5 0 0.5 3.141593 0.1 0.2"
HEAD = "2\n500 600\n"
BAD = [
    # (name, file bytes, where, text expected in the message)
    ("not utf-8", (HEAD + RECORD + "\n# caf\xe9\n").encode("latin-1"), "line 4", "not UTF-8"),
    ("empty", b"", "", "empty file"),
    ("only comments", b"# num wls\n# wls\n", "", "no numbers, only comments"),
    ("fractional count", b"2.5\n500 600\n", "line 1", "'2.5'; expected a positive integer"),
    ("zero count", b"0\n", "line 1", "'0'; expected a positive integer"),
    ("few wavelengths", b"# n\n3\n500 600\n", "line 3", "ends after 2 of 3 wavelengths"),
    ("unordered wavelengths", f"2\n600 500\n{RECORD}".encode(), "line 2",
     "wavelength 2: 500 nm does not exceed the previous 600 nm"),
    ("negative wavelength", f"2\n-5 500\n{RECORD}".encode(), "line 2",
     "wavelength 1: -5 nm; expected a positive wavelength"),
    ("no records", HEAD.encode(), "line 2", "no records after the wavelengths"),
    ("not a number", f"{HEAD}{RECORD}\n0.5 0 0.5 3.1 O.1 0.2\n".encode(), "line 4",
     "record 2, value 1: 'O.1' is not a number"),
    ("nan", f"{HEAD}{RECORD}\n0.5 0 0.5 3.1 0.1 NaN\n".encode(), "line 4",
     "record 2, value 2: 'NaN' is not finite"),
    ("theta out of range", f"{HEAD}{RECORD}\n0.5 0 1.6 3.1 0.1 0.2\n".encode(), "line 4",
     "record 2, theta_s: 1.6 rad is outside the range"),
    ("negative theta", f"{HEAD}-0.1 0 0.5 3.1 0.1 0.2\n".encode(), "line 3",
     "record 1, theta_i: -0.1 rad"),
    ("azimuth out of range", f"{HEAD}0.5 7 0.5 3.1 0.1 0.2\n".encode(), "line 3",
     "record 1, phi_i: 7 rad is outside"),
    # one record per line: the short line is where the incomplete record starts
    ("short record inside", f"{HEAD}{RECORD}\n0.5 0 0.5 3.1 0.1\n{RECORD}\n".encode(),
     "line 4", "record 2, which starts on this line, has 5 numbers; expected 6 "
               "(4 angles + 2 values)"),
    ("truncated", f"{HEAD}{RECORD}\n{RECORD}\n0.5 0 0.5".encode(), "line 5",
     "record 3, which starts on this line, has 3 numbers"),
    ("extra number", f"{HEAD}{RECORD}\n{RECORD} 0.3\n".encode(), "line 4",
     "record 2, which starts on this line, has 7 numbers"),
    # records spread over lines: only the stream's last, partial record can be named
    ("truncated stream", "2 500 600 0.5 0\n0.5 3.1 0.1 0.2 0.5\n0 0.5".encode(), "line 2",
     "record 2, which starts on this line, has 3 numbers"),
]


@pytest.mark.parametrize("name, data, where, text", BAD, ids=[b[0] for b in BAD])
def test_bad_input(tmp_path, name, data, where, text):
    path = tmp_path / "bad.brdf"
    path.write_bytes(data)
    with pytest.raises(FormatError) as info:
        cornell.read(path)
    message = str(info.value)
    assert info.value.where == where and text in message, message
    assert "\n" not in message and message.startswith(str(path))
