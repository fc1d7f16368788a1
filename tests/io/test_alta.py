"""ALTA text data files: ALTA's own files read to hand-computed tables, files written here by
hand-written formulas (independent of the reader) for every parameterisation, round trips,
sigma from #VS, the default #PARAM_OUT note, every refusal, and the command line."""

import math
from pathlib import Path

import numpy as np
import pytest

import brdf
from brdf.errors import FormatError, InputError
from brdf.io import alta
from brdf_cli.main import main

DATA = Path(__file__).resolve().parent.parent / "data" / "alta"
TWO_LAYERS = DATA / "brdf_small_simu_two_layers_txt.alta"
JAUNE = DATA / "retro-3M-jaune-every25.dat"
GRAY = DATA / "retro-gray-tape-every50.dat"
MODEL = "lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.3, ks=0.4)"


def sph(theta, phi):
    """Unit vector of polar angle theta and azimuth phi (written out, not the library's)."""
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)],
                    axis=-1)


def rot_z(w, angle):
    """``w`` rotated about the normal by ``angle``."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * w[:, 0] - s * w[:, 1], s * w[:, 0] + c * w[:, 1], w[:, 2]], axis=-1)


def rot_y(w, angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * w[:, 0] + s * w[:, 2], w[:, 1], -s * w[:, 0] + c * w[:, 2]], axis=-1)


def body_rows(path):
    """The data rows of an ALTA text file, split by hand (plain Python floats)."""
    rows = [line.split() for line in Path(path).read_text().splitlines()
            if line.strip() and not line.startswith("#")]
    return np.array([[float(t) for t in row] for row in rows])


def pairs(n=40, seed=3):
    """``n`` random direction pairs in the upper hemisphere, away from the pole and horizon."""
    rng = np.random.default_rng(seed)
    theta = rng.uniform(0.05, 1.35, (2, n))
    phi = rng.uniform(0.0, 2 * math.pi, (2, n))
    return sph(theta[0], phi[0]), sph(theta[1], phi[1])


def write_file(path, dim, param_in, rows, param_out="INV_STERADIAN", extra=""):
    head = f"#DIM {dim[0]} {dim[1]}\n#PARAM_IN {param_in}\n"
    if param_out is not None:
        head += f"#PARAM_OUT {param_out}\n"
    text = head + extra + "".join(" ".join(repr(float(v)) for v in row) + "\n" for row in rows)
    Path(path).write_text(text)
    return path


# -- ALTA's files ----------------------------------------------------------------------------------

def test_two_layers_file_by_hand():
    t = brdf.read(TWO_LAYERS)
    rows = body_rows(TWO_LAYERS)
    assert t.format == "alta" and len(t) == len(rows) == 29 and t.isotropic
    assert t.channel_names == ("r", "g", "b") and t.sigma is None
    # ISOTROPIC_TV_TL_DPHI: [theta_v, theta_l, phi_l - phi_v], V at phi = 0 (params.cpp)
    np.testing.assert_allclose(t.wo, sph(rows[:, 0], 0.0 * rows[:, 0]), atol=1e-15)
    np.testing.assert_allclose(t.wi, sph(rows[:, 1], rows[:, 2]), atol=1e-15)
    np.testing.assert_array_equal(t.values, rows[:, 3:6])
    assert t.metadata["param_in"] == "ISOTROPIC_TV_TL_DPHI"
    assert t.metadata["param_out"] == "RGB_COLOR"


def test_retro_cosine_factor_file_by_hand():
    t = brdf.read(JAUNE)
    rows = body_rows(JAUNE)
    assert len(t) == len(rows) == 296 and t.channel_names == ("value",)
    theta_v = np.hypot(rows[:, 1], rows[:, 2])
    wo = sph(theta_v, np.arctan2(rows[:, 2], rows[:, 1]))
    cos_v = np.cos(theta_v)
    grazing = cos_v < 1e-5
    assert grazing.sum() > 0  # the file's theta_v = pi/2 rows
    np.testing.assert_allclose(t.wi, sph(rows[:, 0], 0.0 * rows[:, 0]), atol=1e-15)
    np.testing.assert_allclose(t.wo[~grazing], wo[~grazing], atol=1e-12)
    # INV_STERADIAN_COSINE_FACTOR: f cos(theta_o) in the file (params.h)
    np.testing.assert_allclose(t.values[~grazing, 0], rows[~grazing, 3] / cos_v[~grazing],
                               rtol=1e-12)
    assert np.isnan(t.values[grazing, 0]).all()
    note = t.metadata["param_out"]
    assert note.startswith("INV_STERADIAN_COSINE_FACTOR: values divided by cos theta_o")
    assert f"{grazing.sum()} samples at grazing view" in note
    assert t.metadata["SAMPLE"] == '"3M Yellow"'
    assert t.metadata["URL"] == "https://hal.archives-ouvertes.fr/hal-01083366/"


def test_file_without_param_out_gets_the_default_and_a_note(capsys):
    t = brdf.read(GRAY)
    rows = body_rows(GRAY)
    np.testing.assert_array_equal(t.values[:, 0], rows[:, 3])
    note = "none in the file; read as INV_STERADIAN (BRDF in 1/sr, no cosine factor)"
    assert t.metadata["param_out"] == note
    assert main(["info", str(GRAY)]) == 0
    out = capsys.readouterr().out
    assert "meta param_out" in out and note in out and "alta" in out


def test_dat_files_are_recognised_by_content():
    assert brdf.io.format_of(JAUNE).FORMAT == "alta"
    assert alta.sniff(TWO_LAYERS.read_bytes()[:4096])
    assert not alta.sniff(b"1 0.2 0.3 0.4 0.5 0.6 0.7\n")
    assert not alta.sniff(b"theta_i,phi_i,theta_o,phi_o,brdf\n")


# -- an analytic oracle per parameterisation -------------------------------------------------------

def hand_numbers(param, wi, wo):
    """The input numbers of (wi, wo) in ``param`` from ALTA's definitions (params.h/.cpp),
    and the directions a reader must return: the same pair rotated about the normal for the
    parameterisations without an absolute azimuth."""
    theta_l, phi_l = np.arccos(wi[:, 2]), np.arctan2(wi[:, 1], wi[:, 0])
    theta_v, phi_v = np.arccos(wo[:, 2]), np.arctan2(wo[:, 1], wo[:, 0])
    if param == "CARTESIAN":  # [V, L]
        return np.hstack([wo, wi]), wi, wo
    if param == "SPHERICAL_TL_PL_TV_PV":
        return np.stack([theta_l, phi_l, theta_v, phi_v], 1), wi, wo
    if param == "ISOTROPIC_TV_TL_DPHI":  # V at phi = 0
        return (np.stack([theta_v, theta_l, phi_l - phi_v], 1), rot_z(wi, -phi_v),
                rot_z(wo, -phi_v))
    if param == "ISOTROPIC_TL_TV_PROJ_DPHI":  # L at phi = 0
        d = phi_v - phi_l
        return (np.stack([theta_l, theta_v * np.cos(d), theta_v * np.sin(d)], 1),
                rot_z(wi, -phi_l), rot_z(wo, -phi_l))
    # Rusinkiewicz 1998: half vector, then V in the half vector's frame
    h = wi + wo
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    theta_h, phi_h = np.arccos(h[:, 2]), np.arctan2(h[:, 1], h[:, 0])
    d = rot_y(rot_z(wo, -phi_h), -theta_h)
    theta_d, phi_d = np.arccos(d[:, 2]), np.arctan2(d[:, 1], d[:, 0])
    if param == "RUSIN_TH_PH_TD_PD":
        return np.stack([theta_h, phi_h, theta_d, phi_d], 1), wi, wo
    assert param == "RUSIN_TH_TD_PD"
    return (np.stack([theta_h, theta_d, phi_d], 1), rot_z(wi, -phi_h), rot_z(wo, -phi_h))


@pytest.mark.parametrize("param", list(alta.PARAMS))
def test_each_parameterisation_against_hand_formulas(tmp_path, param):
    model = brdf.parse(MODEL)
    wi, wo = pairs()
    x, wi_read, wo_read = hand_numbers(param, wi, wo)
    f = model.eval(wi, wo)
    path = write_file(tmp_path / "m.alta", (x.shape[1], 3), param, np.hstack([x, f]), "RGB_COLOR")
    t = brdf.read(path)
    np.testing.assert_allclose(t.wi, wi_read, atol=1e-12)
    np.testing.assert_allclose(t.wo, wo_read, atol=1e-12)
    np.testing.assert_allclose(t.values, model.eval(t.wi, t.wo), rtol=1e-9)
    assert t.isotropic == alta.PARAMS[param].isotropic


def test_cosine_factor_is_the_view_cosine(tmp_path):
    model = brdf.parse("lambert(albedo=0.5) + ggx(alpha=0.2, ks=0.5)")
    wi, wo = pairs()
    f = model.eval(wi, wo)
    rows = np.hstack([wo, wi, f * wo[:, 2:3]])
    t = brdf.read(write_file(tmp_path / "c.alta", (6, 1), "CARTESIAN", rows,
                             "INV_STERADIAN_COSINE_FACTOR"))
    np.testing.assert_allclose(t.values, f, rtol=1e-12)


# -- round trips ----------------------------------------------------------------------------------

@pytest.mark.parametrize("param", list(alta.PARAMS))
def test_round_trip_per_parameterisation(tmp_path, param):
    model = brdf.parse(MODEL)
    table = brdf.measure(model, "random:50", "relative:0.05", seed=4)
    path = brdf.write(table, tmp_path / "r.alta", param=param)
    back = brdf.read(path)
    assert back.metadata["param_in"] == param and back.channel_names == ("r", "g", "b")
    np.testing.assert_array_equal(back.values, table.values)
    np.testing.assert_array_equal(back.sigma, table.sigma)  # #VS 1 radii are sigma
    if param == "CARTESIAN":  # the vectors themselves, bit for bit
        np.testing.assert_array_equal(back.wi, table.wi)
        np.testing.assert_array_equal(back.wo, table.wo)
    else:  # isotropic coordinates of the pairs (theta_i, theta_o, cos of the angle between)
        for a, b in ((back.wi[:, 2], table.wi[:, 2]), (back.wo[:, 2], table.wo[:, 2]),
                     (np.sum(back.wi * back.wo, 1), np.sum(table.wi * table.wo, 1))):
            np.testing.assert_allclose(a, b, atol=1e-13)
    if not alta.PARAMS[param].isotropic:
        np.testing.assert_allclose(back.wi, table.wi, atol=1e-13)
        np.testing.assert_allclose(back.wo, table.wo, atol=1e-13)


def test_default_parameterisations_and_header(tmp_path):
    iso = brdf.measure("lambert(albedo=0.5)", "inplane:30", "none", seed=0)
    brdf.write(iso, tmp_path / "iso.alta")
    head = (tmp_path / "iso.alta").read_text().splitlines()[:3]
    assert head == ["#DIM 3 1", "#PARAM_IN ISOTROPIC_TV_TL_DPHI", "#PARAM_OUT INV_STERADIAN"]
    aniso = brdf.Table(iso.wi, iso.wo, iso.values, isotropic=False)
    brdf.write(aniso, tmp_path / "aniso.alta")
    assert (tmp_path / "aniso.alta").read_text().splitlines()[1] == "#PARAM_IN CARTESIAN"
    back = brdf.read(tmp_path / "aniso.alta")
    np.testing.assert_array_equal(back.wi, aniso.wi)
    assert not back.isotropic and brdf.read(tmp_path / "aniso.alta", isotropic=True).isotropic


def test_vs_intervals_read_as_sigma(tmp_path):
    rows = [[0.3, 0.2, 1.0, 0.5, 0.02], [0.4, 0.1, 2.0, 0.7, 0.03]]
    t = brdf.read(write_file(tmp_path / "v1.alta", (3, 1), "ISOTROPIC_TV_TL_DPHI", rows,
                             extra="#VS 1\n"))
    np.testing.assert_array_equal(t.sigma[:, 0], [0.02, 0.03])
    assert t.metadata["vs"].startswith("1: radius")
    # VS 2: distances a below and b above; sigma is the half width (a + b) / 2
    rows = [[0.3, 0.2, 1.0, 0.5, 0.6, 0.01, 0.03, 0.02, 0.04]]  # outputs, then intervals
    t = brdf.read(write_file(tmp_path / "v2.alta", (3, 2), "ISOTROPIC_TV_TL_DPHI", rows,
                             extra="#VS 2 2\n"))
    np.testing.assert_allclose(t.sigma, [[0.02, 0.03]], rtol=1e-15)
    assert t.channel_names == ("c0", "c1")


def test_metadata_round_trip(tmp_path):
    t = brdf.read(JAUNE)
    brdf.write(t, tmp_path / "j.alta")
    back = brdf.read(tmp_path / "j.alta")
    assert back.metadata["SAMPLE"] == '"3M Yellow"'
    assert '"format": "alta"' in back.metadata["source"]
    # the missing grazing samples are left out; the rest keep their values
    kept = ~np.isnan(t.values[:, 0])
    np.testing.assert_allclose(back.values[:, 0], t.values[kept, 0], rtol=1e-15)
    assert back.metadata["param_out"] == "INV_STERADIAN"


# -- what the writer refuses ----------------------------------------------------------------------

def test_writer_refusals(tmp_path):
    table = brdf.measure(MODEL, "random:20", "none", seed=1)
    spectral = brdf.Table(table.wi, table.wo, table.values, wavelengths=[450, 550, 650])
    two = brdf.Table(table.wi, table.wo, table.values[:, :2])
    aniso = brdf.Table(table.wi, table.wo, table.values, isotropic=False)
    partial = table.values.copy()
    partial[3, 1] = np.nan
    cases = [(spectral, {}, "wavelengths"), (two, {}, "2 channels"),
             (aniso, {"param": "RUSIN_TH_TD_PD"}, "anisotropic"),
             (table, {"param": "COS_TH"}, "param 'COS_TH'"),
             (brdf.Table(table.wi, table.wo, partial), {}, "sample 3")]
    for t, options, fragment in cases:
        with pytest.raises(InputError) as e:
            brdf.write(t, tmp_path / "x.alta", **options)
        assert fragment in str(e.value) and "\n" not in str(e.value)
        assert not (tmp_path / "x.alta").exists()
    with pytest.raises(InputError, match="takes no option 'param'"):
        brdf.write(table, tmp_path / "x.csv", param="CARTESIAN")
    brdf.write(table, tmp_path / "x.alta")
    with pytest.raises(brdf.errors.OutputError, match="exists"):
        brdf.write(table, tmp_path / "x.alta")


# -- what the reader refuses ----------------------------------------------------------------------

GOOD = "#DIM 3 1\n#PARAM_IN ISOTROPIC_TV_TL_DPHI\n#PARAM_OUT INV_STERADIAN\n"

BAD = {
    "truncated line": (GOOD + "0.1 0.2 0.3 0.4\n0.1 0.2 0.3\n", "line 5", "3 numbers; expected 4"),
    "extra column": (GOOD + "0.1 0.2 0.3 0.4 0.5\n", "line 4", "5 numbers; expected 4"),
    "nan": (GOOD + "0.1 0.2 0.3 0.4\n0.1 nan 0.3 0.4\n", "line 5", "theta_l: 'nan' is not "
            "finite"),
    "not a number": (GOOD + "0.1 0.2 x 0.4\n", "line 4", "delta_phi: 'x' is not a number"),
    "unknown param": ("#DIM 3 1\n#PARAM_IN ISOTROPIC_FOO\n0.1 0.2 0.3 0.4\n", "line 2",
                      "'ISOTROPIC_FOO' is unknown"),
    "param not read": ("#DIM 1 1\n#PARAM_IN COS_TH\n0.1 0.2\n", "line 2", "'COS_TH' is not read"),
    "bad dim": ("#DIM 3\n#PARAM_IN CARTESIAN\n0.1 0.2 0.3 0.4\n", "line 1", "expected two "
                "integers"),
    "dim mismatch": ("#DIM 4 1\n#PARAM_IN ISOTROPIC_TV_TL_DPHI\n0.1 0.2 0.3 0.4 0.5\n",
                     "line 1", "ISOTROPIC_TV_TL_DPHI has 3"),
    "no dim": ("#PARAM_IN CARTESIAN\n0 0 1 0 0 1 0.5\n", "header", "no #DIM line"),
    "no param_in": ("#DIM 6 1\n0 0 1 0 0 1 0.5\n", "header", "no #PARAM_IN line"),
    "energy": ("#DIM 3 1\n#PARAM_IN RUSIN_TH_TD_PD\n#PARAM_OUT ENERGY\n0.1 0.2 0.3 0.4\n",
               "line 3", "ALTA defines no unit for ENERGY"),
    "rgb with one output": ("#DIM 3 1\n#PARAM_IN RUSIN_TH_TD_PD\n#PARAM_OUT RGB_COLOR\n"
                            "0.1 0.2 0.3 0.4\n", "line 3", "holds 3 outputs"),
    "dim twice": (GOOD + "#DIM 3 1\n0.1 0.2 0.3 0.4\n", "line 4", "#DIM appears twice"),
    "bad vs": (GOOD + "#VS 3\n0.1 0.2 0.3 0.4\n", "line 4", "expected 0, 1 or 2"),
    "first output only": ("#DIM 3 3\n#PARAM_IN ISOTROPIC_TV_TL_DPHI\n#VS 1\n"
                          "0.1 0.2 0.3 0.4 0.5 0.6 0.01\n", "line 4",
                          "an interval for the first output only"),
    "negative radius": (GOOD + "#VS 1\n0.1 0.2 0.3 0.4 -0.01\n", "line 5", "radius of output 1 "
                        "is -0.01"),
    "polar out of range": (GOOD + "1.7 0.2 0.3 0.4\n", "line 4", "theta_v: 1.7 rad is outside"),
    "below the horizon": ("#DIM 3 1\n#PARAM_IN RUSIN_TH_TD_PD\n1.4 1.4 0 0.5\n", "line 3",
                          "below the horizon"),
    "not a unit vector": ("#DIM 6 1\n#PARAM_IN CARTESIAN\n0 0 1 0 0 2 0.5\n", "line 3",
                          "|L| (a unit vector): 2"),
    "overflow": ("#DIM 3 1\n#PARAM_IN ISOTROPIC_TV_TL_DPHI\n#PARAM_OUT "
                 "INV_STERADIAN_COSINE_FACTOR\n1.5 0.2 0.3 1e308\n", "line 4", "overflows"),
    "huge vector": ("#DIM 6 1\n#PARAM_IN CARTESIAN\n1e300 1e300 1 0 0 1 0.5\n", "line 3",
                    "|V| (a unit vector): inf"),
    "header only": (GOOD, "line 4", "end of file after the header"),
    "empty": ("", "", "empty file"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_input_is_one_line_naming_file_and_line(tmp_path, case):
    text, where, fragment = BAD[case]
    path = tmp_path / "bad.alta"
    path.write_text(text)
    with pytest.raises(FormatError) as e:
        brdf.read(path)
    message = str(e.value)
    assert "\n" not in message and message.startswith(str(path))
    assert e.value.where == where and fragment in message, message


def test_binary_file_reads_as_its_text_twin():
    # ALTA's tests hold the same 29 samples in both formats; the text prints 17 digits
    binary = brdf.read(DATA / "brdf_small_simu_two_layers_binary.alta")
    text = brdf.read(TWO_LAYERS)
    np.testing.assert_allclose(binary.values, text.values, rtol=0, atol=1e-17)
    np.testing.assert_allclose(binary.wi, text.wi, rtol=0, atol=1e-16)
    np.testing.assert_allclose(binary.wo, text.wo, rtol=0, atol=1e-16)
    assert binary.format == "alta" and binary.channel_names == ("r", "g", "b")


def binary_file(path, numbers, header="", endian="little", count=None, tail=b"\n#END_STREAM\n"):
    numbers = np.asarray(numbers, dtype=("<" if endian == "little" else ">") + "f8")
    text = (f"#DIM 3 1\n#PARAM_IN ISOTROPIC_TV_TL_DPHI\n#PARAM_OUT INV_STERADIAN\n"
            f"#FORMAT binary\n#VERSION 0\n#PRECISION ieee754-double\n"
            f"#SAMPLE_COUNT {len(numbers) if count is None else count}\n#ENDIAN {endian}\n"
            f"{header}#BEGIN_STREAM\n")
    Path(path).write_bytes(text.encode() + numbers.tobytes() + tail)
    return path


def test_binary_big_endian_and_refusals(tmp_path):
    rows = [[0.3, 0.2, 1.0, 0.5], [0.4, 0.1, 2.0, 0.7]]
    t = brdf.read(binary_file(tmp_path / "b.alta", rows, endian="big", tail=b""))
    np.testing.assert_array_equal(t.values[:, 0], [0.5, 0.7])
    np.testing.assert_allclose(t.wi[1], sph(0.1, 2.0), atol=1e-16)
    cases = {
        "truncated": (binary_file(tmp_path / "t.alta", rows, count=3), "byte",
                      "expected 96 (3 samples x 4 doubles): truncated"),
        "trailing": (binary_file(tmp_path / "r.alta", rows, tail=b"junk"), "byte",
                     "4 bytes after the 2 samples"),
        "nan": (binary_file(tmp_path / "n.alta", [[0.3, 0.2, 1.0, np.nan]]), "sample 1 (byte",
                "number 4 is nan"),
        "vs": (binary_file(tmp_path / "v.alta", rows, header="#VS 1\n"), "line", "#VS in a binary"),
        "precision": (binary_file(tmp_path / "p.alta", rows, header="#X 1\n").read_bytes()
                      .replace(b"ieee754-double", b"ieee754-single"), "line 6",
                      "'ieee754-single'"),
        "below": (binary_file(tmp_path / "h.alta", [[1.7, 0.2, 1.0, 0.5]]), "sample 1 (byte",
                  "theta_v: 1.7 rad is outside"),
    }
    for name, (path, where, fragment) in cases.items():
        if isinstance(path, bytes):
            (tmp_path / "p.alta").write_bytes(path)
            path = tmp_path / "p.alta"
        with pytest.raises(FormatError) as e:
            brdf.read(path)
        assert e.value.where.startswith(where) and fragment in str(e.value), (name, str(e.value))
        assert "\n" not in str(e.value)
    no_stream = tmp_path / "s.alta"
    no_stream.write_bytes(b"#DIM 3 1\n#PARAM_IN ISOTROPIC_TV_TL_DPHI\n#FORMAT binary\n" + bytes(64))
    with pytest.raises(FormatError, match="line 4: #FORMAT binary without #BEGIN_STREAM"):
        brdf.read(no_stream)


def test_comments_and_markers_are_skipped(tmp_path):
    text = ("#ALTA_BEGIN_HEADER\n# a comment\n# operator: R. P.\n#DIM 3 1\n#VS 0\n"
            "#PARAM_IN ISOTROPIC_TV_TL_DPHI\n#ALTA_END_HEADER\n0.1 0.2 0.3 0.4\t\n"
            "# body comment\n\n0.2 0.2 0.3 0.5\r\n")
    path = tmp_path / "c.txt"
    path.write_text(text)
    t = brdf.read(path)
    assert t.values[:, 0].tolist() == [0.4, 0.5] and t.metadata["operator"] == "R. P."


# -- command line ---------------------------------------------------------------------------------

def test_cli_convert_round_trip_and_exit_2(tmp_path, capsys):
    csv = tmp_path / "in.csv"
    brdf.write(brdf.measure(MODEL, "grid:15,30", "relative:0.02", seed=2), csv)
    out = tmp_path / "out.alta"
    assert main(["convert", str(csv), str(out), "-q"]) == 0
    assert main(["convert", str(out), str(tmp_path / "back.csv"), "-q"]) == 0
    a, b = brdf.read(csv), brdf.read(tmp_path / "back.csv")
    np.testing.assert_array_equal(a.values, b.values)
    np.testing.assert_array_equal(a.sigma, b.sigma)
    assert main(["convert", str(csv), str(out), "-q"]) == 2  # exists, no --force
    capsys.readouterr()
    bad = tmp_path / "bad.dat"
    bad.write_text(GOOD + "0.1 0.2 0.3\n")
    assert main(["info", str(bad)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [f"brdf-fit: error: {bad}:line 4: 3 numbers; expected 4: theta_v, theta_l, "
                   "delta_phi, output 1"]
