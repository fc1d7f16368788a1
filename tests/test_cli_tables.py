"""The measured-table commands: info, convert, synth, and check/eval/albedo on files; the
bad-input corpus through the command line (exit 2, one line naming the file, no traceback)."""

import json
import re
import struct
from pathlib import Path

import numpy as np
import pytest

import brdf
from measured_data import measured, published_sha256
from test_cli import assert_one_error_line, run, run_script

BAD = Path(__file__).parent / "data" / "bad"
REAL = ["nist-ptfe/PTFE.data.csv", "cornell-paints/cayman.brdf", "curet/abrdf.dat",
        "rgl/paper_white_rgb.bsdf"]


@pytest.mark.parametrize("command", ["info", "convert", "synth"])
def test_help(capsys, command):
    status, out, _ = run(capsys, command, "--help")
    assert status == 0 and "exit status" in out


# --- synth and convert -------------------------------------------------------------------------

def test_synth_writes_the_model_with_noise_and_is_deterministic(capsys, tmp_path):
    spec = "lambert(albedo=0.3) + ggx(ks=0.4, alpha=0.3)"
    for name in ("a.npz", "b.npz"):
        status, out, err = run(capsys, "synth", spec, "--geometry", "grid:15,30", "--noise",
                               "relative:0.02", "--seed", "7", "-o", str(tmp_path / name))
        assert status == 0 and err == "" and name in out
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()
    t = brdf.read(tmp_path / "a.npz")
    assert t.metadata["seed"] == 7 and t.sigma is not None
    model = brdf.parse(spec)
    z = (t.values - model.eval(t.wi, t.wo)) / t.sigma
    assert np.abs(z).max() < 6.0


def test_output_is_not_replaced_without_force(capsys, tmp_path):
    out_file = tmp_path / "t.csv"
    out_file.write_text("mine\n")
    status, _, err = run(capsys, "synth", "lambert", "--geometry", "grid:30,90", "-o",
                         str(out_file))
    assert status == 2
    assert_one_error_line(err, str(out_file), "exists", "--force")
    assert out_file.read_text() == "mine\n"
    status, _, _ = run(capsys, "synth", "lambert", "--geometry", "grid:30,90", "-o",
                       str(out_file), "--force")
    assert status == 0 and out_file.read_text().count("\n") > 10
    assert [p.name for p in tmp_path.iterdir()] == ["t.csv"]  # no temporary file left


def test_convert_round_trips_csv_through_npz(capsys, tmp_path):
    source = Path(__file__).parent / "data" / "gonio_rgb.csv"
    assert run(capsys, "convert", str(source), str(tmp_path / "t.npz"))[0] == 0
    assert run(capsys, "convert", str(tmp_path / "t.npz"), str(tmp_path / "t.csv"))[0] == 0
    a, b = brdf.read(source), brdf.read(tmp_path / "t.csv")
    assert a.values.tobytes() == b.values.tobytes()
    np.testing.assert_array_equal(a.angles, b.angles)


def test_convert_writes_a_model_to_a_grid_format_only(capsys, tmp_path):
    """IN may be a spec (or a fit report): formats that sample a model (MERL) take it, formats
    of measured samples refuse it in one line."""
    spec = "lambert(albedo=[0.5,0.4,0.3])"
    status, out, _ = run(capsys, "convert", spec, str(tmp_path / "m.binary"))
    assert status == 0 and "model lambert" in out
    np.testing.assert_allclose(brdf.read(tmp_path / "m.binary").eval([0, 0, 1], [0, 0, 1]),
                               np.array([0.5, 0.4, 0.3]) / np.pi, rtol=1e-3)
    status, _, err = run(capsys, "convert", spec, str(tmp_path / "m.npz"))
    assert status == 2
    assert_one_error_line(err, "write: table must be a brdf.Table", "brdf.measure")


@pytest.mark.slow
def test_synth_merl_and_check_it(capsys, tmp_path):
    path = tmp_path / "gold.binary"
    status, _, _ = run(capsys, "synth", "ggx(ks=[0.9,0.7,0.3], alpha=0.15)", "--geometry",
                       "merl", "-o", str(path))
    assert status == 0 and path.stat().st_size == 34_992_012
    status, out, _ = run(capsys, "info", str(path), "--json")
    info = json.loads(out)
    assert info["format"] == "merl" and info["samples"] == 1_458_000
    # the grid's unmeasurable pairs miss all three channels: samples and values apart
    assert info["missing_values"] == 3 * info["missing_samples"] > 0
    status, out, _ = run(capsys, "info", str(path))
    assert re.search(rf"missing samples +{info['missing_samples']:,} of 1,458,000", out)
    status, out, _ = run(capsys, "check", str(path), "--json")
    report = json.loads(out)
    assert status == 0, out
    energy = next(c for c in report["checks"] if c["name"] == "energy")
    model = brdf.parse("ggx(ks=[0.9,0.7,0.3], alpha=0.15)")
    wi = brdf.geometry.directions_from_degrees(energy["where"]["theta_i"], 0.0)
    assert energy["worst"] == pytest.approx(model.albedo(wi)[0], rel=0.02)


# --- real data --------------------------------------------------------------------------------

@pytest.mark.parametrize("relative", REAL)
def test_info_on_real_data(capsys, relative):
    path = measured(relative)
    status, out, err = run(capsys, "info", str(path), "--json")
    assert status == 0 and err == ""
    info = json.loads(out)
    assert info["source"]["sha256"] == published_sha256(relative)
    assert info["samples"] > 100
    status, out, _ = run(capsys, "info", str(path))
    assert status == 0 and published_sha256(relative) in out


def test_check_on_real_data_flags_curets_negative_values(capsys):
    """Sample 61 of CUReT holds 28 of the file's 29 negative values."""
    path = str(measured("curet/abrdf.dat"))
    status, out, _ = run(capsys, "check", path, "--sample", "61", "--json")
    report = json.loads(out)
    assert status == 1
    nonneg = report["checks"][0]
    assert not nonneg["passed"] and nonneg["negative"] == 28
    status, out, _ = run(capsys, "info", path, "--sample", "4", "--json")
    assert status == 0 and json.loads(out)["negative_values"] == 1
    status, _, err = run(capsys, "info", str(measured("rgl/paper_white_rgb.bsdf")), "--sample",
                         "2")
    assert status == 2 and "holds one" in err


def test_eval_and_albedo_accept_a_file(capsys):
    path = str(measured("cornell-paints/cayman.brdf"))
    status, out, _ = run(capsys, "eval", path, "--wi", "40,0", "--wo", "40,180", "--json")
    assert status == 0
    assert len(json.loads(out)["f"]) == 31
    status, out, _ = run(capsys, "albedo", path, "--theta-i", "20,40", "--json")
    assert status == 0
    rows = json.loads(out)["rows"]
    assert all(0.0 < a < 1.0 for row in rows for a in row["albedo"])


# --- the bad-input corpus ------------------------------------------------------------------------

def merl_header(dims=(90, 90, 180)):
    return struct.pack("<3i", *dims)


def bad_binaries(tmp_path):
    """Generated bad files (too big to commit), each with a fragment its error must hold."""
    full = 3 * 90 * 90 * 180 * 8
    cases = {
        "truncated.binary": (merl_header() + bytes(1000), "bytes"),
        "oversized.binary": (merl_header() + bytes(full + 8), "bytes"),
        "dims.binary": (merl_header((90, 90, 360)) + bytes(full * 2), "90, 90, 180"),
        "short.binary": (b"\x01\x02", "byte"),
        "nan.binary": (merl_header() + np.full(3 * 1_458_000, np.nan).tobytes(), "byte 12"),
        "garbage.bsdf": (b"tensor_file\x00\x01\x00" + bytes(3), "byte"),
        "wrong_magic.bsdf": (b"not a tensor file at all", "byte 0"),
        "truncated.npz": (b"PK\x03\x04" + bytes(40), "npz"),
        "latin1.brdf": ("31 400 410 # caf\xe9\n".encode("latin-1"), "UTF-8"),
        "short_record.brdf": (b"1 500\n0.1 0 0.2 3.1\n", "line"),
        "unknown.xyz": (b"hello", "unrecognised format"),
    }
    for name, (data, _) in cases.items():
        (tmp_path / name).write_bytes(data)
    return {tmp_path / name: fragment for name, (_, fragment) in cases.items()}


def test_every_bad_file_is_one_line_and_exit_2(capsys, tmp_path):
    corpus = {path: "" for path in sorted(BAD.iterdir())}
    corpus.update(bad_binaries(tmp_path))
    corpus[tmp_path / "does_not_exist.csv"] = "no such file"
    assert len(corpus) >= 30
    for path, fragment in corpus.items():
        status, out, err = run(capsys, "info", str(path))
        assert status == 2, (path, out, err)
        assert_one_error_line(err, str(path), fragment)
        assert "Traceback" not in err and out == ""


def test_negative_values_are_a_check_failure_not_a_read_error(capsys, tmp_path):
    path = tmp_path / "negative.csv"
    path.write_text("theta_i,phi_i,theta_o,phi_o,brdf\n0,0,10,0,0.3\n0,0,20,0,-0.01\n"
                    "0,0,30,0,0.3\n0,0,40,0,0.3\n")
    assert run(capsys, "info", str(path))[0] == 0
    status, out, _ = run(capsys, "check", str(path))
    assert status == 1 and "non-negativity  FAIL" in out


def test_shell_sees_one_line_and_no_traceback(tmp_path):
    for path in (BAD / "gonio_nan.csv", *list(bad_binaries(tmp_path))[:1]):
        result = run_script("check", str(path))
        assert result.returncode == 2
        assert len(result.stderr.splitlines()) == 1 and "Traceback" not in result.stderr
        debug = run_script("--debug", "info", str(path))
        assert debug.returncode == 2 and "Traceback" in debug.stderr
