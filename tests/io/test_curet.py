"""CUReT reader: the published table (61 samples x 205 geometries), options, bad input."""

import math
import shutil

import numpy as np
import pytest

import brdf
from brdf.errors import FormatError, InputError
from brdf.geometry import reflect
from brdf.io import curet
from measured_data import measured, published_sha256

ABRDF, TABLE = "curet/abrdf.dat", "curet/table.txt"


@pytest.fixture(scope="module")
def samples():
    return curet.read_all(measured(ABRDF))


def test_counts_and_value_range(samples):
    # README: 61 samples x 205 geometries, values -0.016 to 2.59 with 29 negative
    assert len(samples) == 61
    values = np.stack([t.values[:, 0] for t in samples])
    assert values.shape == (61, 205)
    assert values.min() == -0.016 and values.max() == 2.59
    assert np.count_nonzero(values < 0) == 29
    for k, t in enumerate(samples, start=1):
        assert t.metadata["sample"] == k and t.metadata["samples"] == 61
        assert t.channel_names == ("mean",) and not t.isotropic
        assert t.source.format == "curet"


def test_default_is_sample_one(samples):
    t = brdf.read(measured(ABRDF))
    assert t.metadata["sample"] == 1 and t.name == "curet sample 1"
    np.testing.assert_array_equal(t.values, samples[0].values)
    np.testing.assert_array_equal(brdf.read(measured(ABRDF), sample=61).values,
                                  samples[60].values)


def test_sha256_of_both_files(samples):
    assert samples[0].source.sha256 == published_sha256(ABRDF)
    assert samples[0].metadata["geometry"]["sha256"] == published_sha256(TABLE)


def test_geometry_by_hand(samples):
    # table.txt line 2: "2  0.981748  0.000000  1.374447  0.000000" (theta_v phi_v theta_i
    # phi_i); abrdf.dat line 1 starts "1  0.200  0.110"
    t = samples[0]
    v, i = 0.981748, 1.374447
    np.testing.assert_allclose(t.wo[1], [math.sin(v), 0.0, math.cos(v)], atol=1e-15)
    np.testing.assert_allclose(t.wi[1], [math.sin(i), 0.0, math.cos(i)], atol=1e-15)
    assert t.values[:2, 0].tolist() == [0.2, 0.11]
    assert t.angles[:, 0].max() == pytest.approx(78.75, abs=1e-4)   # illumination
    assert t.angles[:, 2].max() == pytest.approx(83.882, abs=1e-3)  # viewing


def test_shiniest_sample_peaks_at_mirror(samples):
    # sample 55 holds the table's largest value (2.59): a specular peak, so both directions
    # point away from the surface and wo is wi mirrored about the normal
    t = samples[54]
    k = int(np.argmax(t.values[:, 0]))
    assert t.values[k, 0] == 2.59
    assert math.degrees(math.acos(min(1.0, reflect(t.wi[k]) @ t.wo[k]))) < 0.01


@pytest.mark.parametrize("sample", [0, 62, -1, 1.0, "1", True, None])
def test_sample_option_checked(sample):
    with pytest.raises(InputError, match="sample must be an integer from 1 to 61"):
        curet.read(measured(ABRDF), sample=sample)


def test_geometry_table_next_to_file_or_given(tmp_path):
    alone = tmp_path / "abrdf.dat"
    shutil.copyfile(measured(ABRDF), alone)
    with pytest.raises(FormatError) as info:
        curet.read(alone)
    assert info.value.path == str(tmp_path / "table.txt")
    assert "geometry table not found" in str(info.value)
    t = curet.read(alone, sample=2, geometry=measured(TABLE))
    assert t.metadata["geometry"]["path"] == str(measured(TABLE)) and len(t) == 205


def test_sniff():
    assert curet.sniff(measured(ABRDF).read_bytes()[:4096])
    assert not curet.sniff(measured(TABLE).read_bytes()[:4096])
    assert not curet.sniff(measured("cornell-paints/cayman.brdf").read_bytes()[:4096])
    assert not curet.sniff(b"2 0.1 0.2 0.3 0.4 0.5\n")  # starts at sample 2
    assert not curet.sniff(b"1 0.1 0.2 0.3 0.4 0.5 x\n")


# -- bad input (two samples at three geometries) ------------------------------------------------
TABLE_OK = "1 0.5 0 0.5 3.141593\r\n2 0.2 1 0.3 -2\r\n3 0 0 1.2 0.5"
ABRDF_OK = "1 0.1 0.2 0.3 \n2 0.4 0.5 -0.01 \n"
BAD = [
    # (name, table.txt, abrdf.dat, file named, where, text expected in the message)
    ("abrdf not utf-8", TABLE_OK, b"1 0.1 0.2 0.3\n2 0.4 0.5\xb50.01\n", "abrdf.dat", "line 2",
     "not UTF-8"),
    ("table not utf-8", b"1 0.5 0 0.5 \xb0\n", ABRDF_OK, "table.txt", "line 1", "not UTF-8"),
    ("empty abrdf", TABLE_OK, "", "abrdf.dat", "", "empty file; expected lines of a sample "
                                                   "number and 3 values"),
    ("empty table", " \n", ABRDF_OK, "table.txt", "", "empty file"),
    ("short value line", TABLE_OK, "1 0.1 0.2 0.3\n2 0.4 0.5\n", "abrdf.dat", "line 2",
     "3 fields; expected 4: a sample number and 3 values (one per geometry in table.txt)"),
    ("extra value", TABLE_OK, "1 0.1 0.2 0.3 0.4\n", "abrdf.dat", "line 1", "5 fields"),
    ("short geometry line", "1 0.5 0 0.5 3\n2 0.2 1 0.3\n", ABRDF_OK, "table.txt", "line 2",
     "4 fields; expected 5: a measurement number and 4 angles"),
    ("samples out of order", TABLE_OK, "1 0.1 0.2 0.3\n3 0.4 0.5 0.6\n", "abrdf.dat",
     "line 2", "sample number is '3'; expected 2"),
    ("measurements out of order", "1 0.5 0 0.5 3\n1 0.2 1 0.3 2\n", "1 0.1 0.2\n", "table.txt",
     "line 2", "measurement number is '1'; expected 2"),
    ("not a number", TABLE_OK, "1 0.1 0.2 0.3\n2 0.4 - 0.6\n", "abrdf.dat", "line 2",
     "value 2: '-' is not a number"),
    ("infinite value", TABLE_OK, "1 0.1 inf 0.3\n", "abrdf.dat", "line 1",
     "value 2: 'inf' is not finite"),
    ("nan angle", "1 0.5 0 0.5 nan\n2 0.2 1 0.3 2\n3 0 0 1 0\n", ABRDF_OK, "table.txt",
     "line 1", "column phi_i: 'nan' is not finite"),
    ("theta below horizon", "1 0.5 0 0.5 3\n2 1.6 1 0.3 2\n3 0 0 1 0\n", ABRDF_OK, "table.txt",
     "line 2", "column theta_v: 1.6 rad is outside the range"),
    ("azimuth out of range", "1 0.5 0 0.5 3\n2 0.2 1 0.3 2\n3 0 0 1 -6.3\n", ABRDF_OK,
     "table.txt", "line 3", "column phi_i: -6.3 rad is outside"),
]


@pytest.mark.parametrize("name, table, values, culprit, where, text", BAD,
                         ids=[b[0] for b in BAD])
def test_bad_input(tmp_path, name, table, values, culprit, where, text):
    for file_name, content in (("table.txt", table), ("abrdf.dat", values)):
        (tmp_path / file_name).write_bytes(content if isinstance(content, bytes)
                                           else content.encode())
    with pytest.raises(FormatError) as info:
        curet.read(tmp_path / "abrdf.dat")
    message = str(info.value)
    assert info.value.path == str(tmp_path / culprit)
    assert info.value.where == where and text in message, message
    assert "\n" not in message


def test_small_table_reads(tmp_path):
    (tmp_path / "table.txt").write_text(TABLE_OK)
    (tmp_path / "abrdf.dat").write_text(ABRDF_OK)
    tables = curet.read_all(tmp_path / "abrdf.dat")
    np.testing.assert_array_equal([t.values[:, 0] for t in tables],
                                  [[0.1, 0.2, 0.3], [0.4, 0.5, -0.01]])
    # theta_v = 0.5, phi_v = 0; theta_i = 0.5, phi_i = pi (printed 3.141593): a mirror pair
    np.testing.assert_allclose(tables[0].wo[0], reflect(tables[0].wi[0]), atol=1e-6)
