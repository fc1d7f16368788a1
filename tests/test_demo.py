"""The main job end to end (``brdf-fit demo --quick``), its report checked in a headless
browser: every picture decodes and the tables are there."""

import json
import re
import shutil
import subprocess

import pytest
from PIL import Image

from brdf import demo


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "results"
    summary = demo.run(out, seed=0, quick=True, progress=False)
    return out, summary


# one worker runs both tests of the demo (README's test command uses --dist loadgroup), so the
# module's fixture runs the demo once
@pytest.mark.slow
@pytest.mark.xdist_group("demo")
def test_demo_writes_every_stage(results):
    out, summary = results
    assert set(summary["datasets"]) == {"paper-white", "synthetic-merl"}
    for name, e in summary["datasets"].items():
        assert len(e["compare"]) == len(demo.CANDIDATES)
        assert all(r["checks_pass"] for r in e["compare"][:1]), name
        for path in e["images"].values():
            assert (out / path).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert (out / f"{name}-fit.json").exists() and (out / f"{name}-measured.exr").exists()
        assert 0.0 <= e["image_metrics"]["flip"] < 0.3
        # one figure per material holds measured | fitted | difference | FLIP (brdf-fit
        # validate's comparison.png), each panel at least 256 pixels wide
        assert e["images"][demo.VALIDATION_FIGURE] == f"{name}-comparison.png"
        with Image.open(out / f"{name}-comparison.png") as figure:
            assert figure.width >= 4 * 256
    # the synthetic table is recovered: its true model wins and its parameters come back
    syn = summary["datasets"]["synthetic-merl"]
    assert syn["compare"][0]["spec"] == "lambert + ggx"
    fit = json.loads((out / "synthetic-merl-fit.json").read_text())
    alpha = [v for k, v in fit["params"].items() if k.endswith("alpha")][0]
    assert abs(alpha - 0.18) < 0.01
    # the real paper is nearly diffuse and keeps its energy
    assert "posterior" in summary["datasets"]["paper-white"]
    assert json.loads((out / "summary.json").read_text())["seed"] == 0
    # every stage is timed, and the stages account for the run
    stages = summary["stages"]
    assert len(stages) == 1 + 5 * 2 - 1  # data, then 5 per data set, the posterior once
    assert all(s > 0.0 for s in stages.values())
    assert sum(stages.values()) <= summary["seconds"] <= sum(stages.values()) + 30.0


@pytest.mark.slow
@pytest.mark.xdist_group("demo")
def test_report_in_a_headless_browser(results):
    out, summary = results
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        pytest.skip("no chromium: .ci/run installs Debian's chromium for this test")
    dom = subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu",
                          "--virtual-time-budget=5000", "--dump-dom",
                          (out / "report.html").as_uri()],
                         capture_output=True, text=True, timeout=120).stdout
    loaded = re.search(r'data-images-loaded="(\d+)"', dom)
    total = re.search(r'data-images-total="(\d+)"', dom)
    assert loaded and total, dom[:500]
    expected = sum(len(e["images"]) for e in summary["datasets"].values())
    assert int(total.group(1)) == expected
    assert int(loaded.group(1)) == expected
    assert "Model comparison" in dom and "Posterior of the best fit" in dom


def test_demo_refuses_a_non_empty_folder(tmp_path):
    from brdf.errors import OutputError
    (tmp_path / "keep.txt").write_text("mine")
    with pytest.raises(OutputError, match="not empty"):
        demo.run(tmp_path, quick=True)
