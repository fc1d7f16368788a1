"""brdf-fit lobe and brdf-fit plot KIND: PNGs from specs, tables and fit reports, exit status 2
with one line for bad input, and existing files kept without --force."""

import json

import pytest

import brdf
from pictures import distinct_colours, read_png
from test_cli import assert_one_error_line, run

SPEC = "lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.2, ks=0.6)"
LOBE = ["--resolution", "16"]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A measured CSV, a fit report pointing at it, and a Lambert table for the posterior."""
    folder = tmp_path_factory.mktemp("viz-cli")
    table = brdf.measure(SPEC, "grid:10,30", "relative:0.05", seed=1)
    data = brdf.write(table, folder / "paint.csv")
    result = brdf.fit(brdf.read(data), "lambert + ggx(alpha=0.3)", max_evals=300)
    report = folder / "fit.json"
    report.write_text(json.dumps(result.to_dict()), encoding="utf-8")
    lambert = brdf.write(brdf.measure("lambert(albedo=0.5)", "random:300", "additive:0.01",
                                      seed=4), folder / "lambert.csv")
    return {"data": str(data), "report": str(report), "lambert": str(lambert),
            "folder": folder}


def test_lobe_writes_a_png_and_keeps_it_without_force(capsys, tmp_path):
    out = tmp_path / "lobe.png"
    status, stdout, err = run(capsys, "lobe", SPEC, "--theta-i", "30,60", "-o", str(out),
                              *LOBE)
    assert status == 0 and err == "" and f"wrote {out}" in stdout
    first = read_png(out)
    assert first.shape == (480, 1040, 3) and distinct_colours(first) > 200
    status, _, err = run(capsys, "lobe", SPEC, "--log", "-o", str(out), *LOBE)
    assert status == 2
    assert_one_error_line(err, str(out), "exists", "--force")
    assert (read_png(out) == first).all()
    status, stdout, _ = run(capsys, "lobe", SPEC, "--log", "--no-cosine", "--json", "-o",
                            str(out), "--force", *LOBE)
    summary = json.loads(stdout)
    assert status == 0 and summary["log"] is True and summary["cosine"] is False
    assert read_png(out).shape == (480, 520, 3)


def test_lobe_of_a_report_draws_its_measured_input(capsys, files, tmp_path):
    status, stdout, err = run(capsys, "lobe", files["report"], "--json", "-o",
                              str(tmp_path / "fit.png"), *LOBE)
    assert status == 0, err
    assert json.loads(stdout)["data"] == "paint.csv"


@pytest.mark.parametrize("argv, fragments", [
    (["--theta-i", "95"], ["--theta-i", "outside [0, 90]"]),
    (["--theta-i", "90"], ["--theta-i", "90", "[0, 90)"]),
    (["--theta-i", "abc"], ["--theta-i", "not a number"]),
    (["--channel", "5"], ["channel 5 does not exist"]),
])
def test_lobe_bad_options_are_one_line(capsys, tmp_path, argv, fragments):
    out = tmp_path / "x.png"
    status, _, err = run(capsys, "lobe", SPEC, *argv, "-o", str(out), *LOBE)
    assert status == 2
    assert_one_error_line(err, *fragments)
    assert not out.exists()


def test_lobe_bad_material_and_output(capsys, tmp_path):
    status, _, err = run(capsys, "lobe", "ggx(alpha=-1)", "-o", str(tmp_path / "x.png"))
    assert status == 2 and err.count("\n") == 1 and "alpha" in err
    status, _, err = run(capsys, "lobe", str(tmp_path / "missing.csv"), "-o",
                         str(tmp_path / "x.png"))
    assert status == 2
    assert_one_error_line(err, "missing.csv", "no such file")
    status, _, err = run(capsys, "lobe", SPEC, "-o", str(tmp_path / "x.jpg"))
    assert status == 2
    assert_one_error_line(err, "x.jpg", "PNG")
    assert not list(tmp_path.iterdir())


def test_lobe_without_output_or_display_is_one_line(capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    status, _, err = run(capsys, "lobe", SPEC)
    assert status == 2
    assert_one_error_line(err, "no display", "-o")


@pytest.mark.parametrize("kind, material", [
    ("inplane", "report"), ("inplane", "data"), ("slice", "report"), ("albedo", "report"),
    ("residuals", "report"),
])
def test_plot_kinds_write_pngs(capsys, files, tmp_path, kind, material):
    out = tmp_path / f"{kind}.png"
    status, stdout, err = run(capsys, "plot", kind, files[material], "-o", str(out))
    assert status == 0, err
    drawn = ", measured samples from paint.csv" if kind in ("inplane", "residuals") else ""
    assert stdout.strip() == f"wrote {out} ({kind}{drawn})"
    assert distinct_colours(read_png(out)) > 50


def test_plot_albedo_of_several_materials(capsys, files, tmp_path):
    out = tmp_path / "albedo.png"
    status, stdout, err = run(capsys, "plot", "albedo", files["report"], SPEC,
                              "ward(alpha=0.2)", "--json", "-o", str(out))
    assert status == 0, err
    assert len(json.loads(stdout)["materials"]) == 3


def test_plot_refuses_existing_output_and_bad_input(capsys, files, tmp_path):
    out = tmp_path / "slice.png"
    out.write_bytes(b"mine")
    status, _, err = run(capsys, "plot", "slice", SPEC, "-o", str(out))
    assert status == 2
    assert_one_error_line(err, "exists")
    assert out.read_bytes() == b"mine"
    assert run(capsys, "plot", "slice", SPEC, "-o", str(out), "--force")[0] == 0
    status, _, err = run(capsys, "plot", "residuals", SPEC, "-o", str(tmp_path / "r.png"))
    assert status == 2
    assert_one_error_line(err, "give the measured table DATA")
    status, _, err = run(capsys, "plot", "inplane", SPEC, "--channel", "3", "-o",
                         str(tmp_path / "i.png"))
    assert status == 2
    assert_one_error_line(err, "channel 3 does not exist")
    status, _, err = run(capsys, "plot", "histogram", SPEC, "-o", str(tmp_path / "h.png"))
    assert status == 2
    assert_one_error_line(err, "invalid choice", "histogram")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["slice.png"]


@pytest.mark.parametrize("kind", ["corner", "predictive"])
def test_posterior_plots(capsys, files, tmp_path, kind):
    out = tmp_path / f"{kind}.png"
    extra = ["--draws", "10"] if kind == "predictive" else []
    status, stdout, err = run(capsys, "plot", kind, files["lambert"], "lambert(albedo=0.3)",
                              "--max-steps", "300", "--seed", "1", "--json", "-o", str(out),
                              *extra)
    assert status == 0, err
    assert json.loads(stdout)["parameters"] == ["lambert.albedo"]
    assert distinct_colours(read_png(out)) > 20
