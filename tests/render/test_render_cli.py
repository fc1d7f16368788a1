"""``brdf-fit render`` and ``brdf-fit validate``: outputs, --force, JSON, exit statuses."""

import json

import numpy as np
import pytest

import brdf
import brdf._jit
from brdf.render.image import read_image
from brdf.render.validate import OUTPUTS
from brdf_cli.main import main

SMALL = ["--spp", "2", "--size", "8x6", "--seed", "3"]


def run(capsys, *argv):
    status = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err


def assert_one_error_line(err, *fragments):
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("brdf-fit: error: ")
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


def test_render_writes_exr_and_preview_and_keeps_them_without_force(capsys, tmp_path):
    exr, png = tmp_path / "out.exr", tmp_path / "out.png"
    status, out, err = run(capsys, "render", "lambert(albedo=0.5)", "-o", exr, "--preview", png,
                           "--scene", "plane-point", *SMALL)
    assert status == 0, err
    image = read_image(exr)
    assert image.shape == (6, 8, 3) and image.max() > 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert str(exr) in out and "2 spp" in out
    before = exr.read_bytes()
    status, _, err = run(capsys, "render", "lambert(albedo=0.9)", "-o", exr, "--scene",
                         "plane-point", *SMALL)
    assert status == 2
    assert_one_error_line(err, str(exr), "--force")
    assert exr.read_bytes() == before
    status, _, _ = run(capsys, "render", "lambert(albedo=0.9)", "-o", exr, "--scene",
                       "plane-point", "--force", *SMALL)
    assert status == 0
    # the albedo went from 0.5 to 0.9: the image scales with it (direct light only reaches
    # the plane, the rest escapes)
    np.testing.assert_allclose(read_image(exr), image * 0.9 / 0.5, rtol=1e-6)


def test_render_json_and_png_output(capsys, tmp_path):
    out_png = tmp_path / "img.png"
    status, out, _ = run(capsys, "render", "lambert", "-o", out_png, "--json", *SMALL)
    assert status == 0
    stats = json.loads(out)
    assert stats["output"] == str(out_png) and stats["spp"] == 2 and stats["size"] == [8, 6]
    assert len(stats["mean"]) == 3 and stats["samples_per_second"] > 0
    assert out_png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.skipif(not brdf._jit.HAS_TICKS, reason="x86-64 time-stamp counter")
def test_render_stats_table_and_json(capsys, tmp_path):
    """``--stats`` prints the stages' table after the summary line (and, as this scene is
    traced in blocks without it, a line saying the stages are the packet's), and under
    ``--json`` their CPU seconds and counts; the image is the one written without it, to
    rounding (the packet's and the blocks' images agree to 1e-12)."""
    plain, timed = tmp_path / "plain.exr", tmp_path / "timed.exr"
    assert run(capsys, "render", "lambert", "-o", plain, "--scene", "plane-point", *SMALL)[0] == 0
    status, out, err = run(capsys, "render", "lambert", "-o", timed, "--scene", "plane-point",
                           "--stats", *SMALL)
    assert status == 0, err
    lines = out.splitlines()
    assert str(timed) in lines[0] and lines[1].split()[0] == "stage"
    assert "traced in the packet" in lines[0]
    assert [line.split()[0] for line in lines[2:-1]] == ["paths", "rays", "numbers",
                                                        "vertices", "shadow", "shading",
                                                        "other", "all"]
    assert lines[-1].startswith("(the packet's stages: without --stats this scene is traced")
    np.testing.assert_allclose(read_image(timed), read_image(plain), rtol=1e-6, atol=1e-9)
    status, out, _ = run(capsys, "render", "lambert", "-o", timed, "--scene", "plane-point",
                         "--stats", "--json", "--force", *SMALL)
    stages = json.loads(out)["stages"]
    assert stages["samples"] == 8 * 6 * 2 and stages["shaded"] > 0
    assert set(stages["cpu_seconds"]) == {"paths", "rays", "numbers", "vertices", "shadow rays",
                                          "shading", "other"}


def test_render_no_layers_writes_rgb_only(capsys, tmp_path):
    import OpenEXR
    full, bare = tmp_path / "full.exr", tmp_path / "bare.exr"
    assert run(capsys, "render", "lambert", "-o", full, *SMALL)[0] == 0
    assert run(capsys, "render", "lambert", "-o", bare, "--no-layers", *SMALL)[0] == 0
    with OpenEXR.File(str(full), separate_channels=True) as f:
        assert "variance.R" in f.channels()
    with OpenEXR.File(str(bare), separate_channels=True) as f:
        assert set(f.channels()) == {"R", "G", "B"}
    np.testing.assert_array_equal(read_image(bare), read_image(full))


def test_render_same_seed_same_bytes(capsys, tmp_path):
    a, b = tmp_path / "a.exr", tmp_path / "b.exr"
    for path in (a, b):
        assert run(capsys, "render", "ggx(alpha=0.3)", "-o", path, *SMALL)[0] == 0
    assert read_image(a).tobytes() == read_image(b).tobytes()


@pytest.mark.parametrize("argv, fragments", [
    (["render", "nosuchmodel(x=1)", "-o", "{tmp}/x.exr"], ["nosuchmodel"]),
    (["render", "lambert", "-o", "{tmp}/x.exr", "--scene", "teapot"], ["built-in scenes"]),
    (["render", "lambert", "-o", "{tmp}/x.exr", "--size", "0x4"], ["pixels"]),
    (["render", "lambert", "-o", "{tmp}/x.exr", "--spp", "0"], ["spp"]),
    (["render", "lambert", "-o", "{tmp}/x.exr", "--scene", "{tmp}/none.json"], ["none.json: no such file"]),
    (["render", "{tmp}/none.binary", "-o", "{tmp}/x.exr"], ["none.binary"]),
    (["validate", "{tmp}/none.npz", "lambert", "-o", "{tmp}/v"], ["none.npz"]),
])
def test_bad_input_is_one_line_exit_2(capsys, tmp_path, argv, fragments):
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    status, _, err = run(capsys, *argv)
    assert status == 2
    assert_one_error_line(err, *fragments)
    assert not (tmp_path / "x.exr").exists()


def test_render_stats_without_a_time_stamp_counter_is_one_line(capsys, tmp_path, monkeypatch):
    monkeypatch.setattr(brdf._jit, "HAS_TICKS", False)
    status, _, err = run(capsys, "render", "lambert", "-o", tmp_path / "x.exr", "--stats",
                         *SMALL)
    assert status == 2
    assert_one_error_line(err, "time-stamp counter")
    assert not (tmp_path / "x.exr").exists()


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    """A MERL-grid table synthesised from a model, saved as .npz."""
    path = tmp_path_factory.mktemp("validate") / "paint.npz"
    brdf.write(brdf.measure(brdf.parse("lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.3)"),
                            "merl"), path)
    return path


def test_validate_writes_images_and_metrics(capsys, tmp_path, measured):
    outdir = tmp_path / "val"
    fit = "lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.25)"
    status, out, err = run(capsys, "validate", measured, fit, "-o", outdir, *SMALL)
    assert status == 0, err
    assert sorted(p.name for p in outdir.iterdir()) == sorted(OUTPUTS)
    metrics = json.loads((outdir / "metrics.json").read_text())
    assert {"rmse", "relmse", "flip", "model", "spp", "seed"} <= set(metrics)
    fitted, ref = read_image(outdir / "fitted.exr"), read_image(outdir / "measured.exr")
    assert fitted.shape == (6, 8, 3)
    assert metrics["rmse"] == pytest.approx(np.sqrt(np.mean((fitted - ref) ** 2)), rel=1e-5)
    assert metrics["rmse"] > 0 and 0 <= metrics["flip"] <= 1
    for name in ("measured.png", "fitted.png", "difference.png", "flip.png", "comparison.png"):
        assert (outdir / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "RMSE" in out and "FLIP" in out
    # a second run keeps the outputs unless --force
    stamp = (outdir / "metrics.json").read_bytes()
    status, _, err = run(capsys, "validate", measured, fit, "-o", outdir, *SMALL)
    assert status == 2
    assert_one_error_line(err, "--force")
    assert (outdir / "metrics.json").read_bytes() == stamp
    status, out, _ = run(capsys, "validate", measured, fit, "-o", outdir, "--force", "--json",
                         *SMALL)
    assert status == 0 and json.loads(out)["rmse"] == pytest.approx(metrics["rmse"])


def test_validate_output_must_be_a_folder(capsys, tmp_path, measured):
    f = tmp_path / "file"
    f.write_text("x")
    status, _, err = run(capsys, "validate", measured, "lambert", "-o", f, *SMALL)
    assert status == 2
    assert_one_error_line(err, str(f), "not a folder")
