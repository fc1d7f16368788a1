"""The main job end to end (``brdf-fit demo --quick``), its report checked in a headless
browser: every picture decodes, opens at full size, and the tables are there, their numbers
with at most four significant digits; off a terminal, one line per stage."""

import contextlib
import io
import json
import re
import shutil
import subprocess
from html.parser import HTMLParser

import pytest
from PIL import Image

from brdf import demo
from brdf.formatting import DECIMAL, round_numbers


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "results"
    err = io.StringIO()  # not a terminal: the stages' lines
    with contextlib.redirect_stderr(err):
        summary = demo.run(out, seed=0, quick=True)
    return out, summary, err.getvalue()


# one worker runs the tests of the demo (README's test command uses --dist loadgroup), so the
# module's fixture runs the demo once
@pytest.mark.xdist_group("demo")
def test_the_demo_s_tests_share_a_worker(request):
    """pytest-xdist schedules a group by the suffix it adds to the test's id; pytest 9.2 lost
    it silently (pytest-xdist#1386) and every worker ran the demo again."""
    if not (hasattr(request.config, "workerinput") and request.config.getvalue("loadgroup")):
        pytest.skip("only under pytest-xdist's --dist loadgroup")
    assert request.node.nodeid.endswith("@demo"), (
        f"pytest {pytest.__version__} and this pytest-xdist lose --dist loadgroup's groups "
        "(pytest-xdist#1386): install the test extra's pytest")


#: Largest relative error of the material recovered from the quick demo's photograph (32 x 24
#: pixels, 128 spp, fitted at 32 spp; measured: up to 8 % at 16 spp)
CAPTURE_QUICK_TOLERANCE = 0.1


@pytest.mark.slow
@pytest.mark.xdist_group("demo")
def test_demo_writes_every_stage(results):
    out, summary, _ = results
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
    # the material photographed by the path tracer comes back from its photograph
    cap = summary["capture"]
    assert [r["parameter"] for r in cap["rows"]] == json.loads(
        (out / "capture-fit.json").read_text())["free"]
    for r in cap["rows"]:
        assert abs(r["relative_error"]) < CAPTURE_QUICK_TOLERANCE, r
        lo, hi = r["interval_95"]
        assert 0.0 < hi - lo < 0.2 * r["estimate"], r
    assert (out / "capture-photo.exr").exists()
    # every stage is timed, and the stages account for the run
    stages = summary["stages"]
    # data, then 5 per data set, the posterior once, and the photographs
    assert len(stages) == 1 + 5 * 2 - 1 + 1 == demo.STAGES
    assert all(s > 0.0 for s in stages.values())
    assert sum(stages.values()) <= summary["seconds"] <= sum(stages.values()) + 30.0


class _Report(HTMLParser):
    """The report's pictures (with the link around each) and its visible text."""

    def __init__(self):
        super().__init__()
        self.links, self.pictures, self.text, self.hidden = [], [], [], 0

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag in ("script", "style"):
            self.hidden += 1
        elif tag == "a":
            self.links.append(attrs)
        elif tag == "img" and attrs.get("src"):
            self.pictures.append((attrs, self.links[-1] if self.links else None))

    def handle_endtag(self, tag):
        if tag in ("script", "style"):
            self.hidden -= 1
        elif tag == "a":
            self.links.pop()

    def handle_data(self, data):
        if not self.hidden:
            self.text.append(data)


def _dom(path, fragment=""):
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        pytest.skip("no chromium: .ci/run installs Debian's chromium for this test")
    return subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu",
                           "--virtual-time-budget=5000", "--dump-dom", path.as_uri() + fragment],
                          capture_output=True, text=True, timeout=120).stdout


def _attribute(dom, name):
    found = re.search(rf'{name}="([^"]*)"', dom)
    assert found, f"{name} not in {dom[:500]}"
    return found.group(1)


@pytest.mark.slow
@pytest.mark.xdist_group("demo")
def test_demo_prints_one_line_per_stage_off_a_terminal(results):
    out, summary, err = results
    numbered = re.compile(r"brdf: demo: (.+) \((\d+) of (\d+)\) in \d+\.\d s")
    stages = [numbered.fullmatch(line) for line in err.splitlines()]
    stages = [m for m in stages if m]
    assert [m.group(1) for m in stages] == list(summary["stages"])
    assert [int(m.group(2)) for m in stages] == list(range(1, demo.STAGES + 1))
    assert {m.group(3) for m in stages} == {str(demo.STAGES)}
    assert err.splitlines()[-1] == (f"brdf: demo: done in {summary['seconds']:.0f} s: "
                                    f"{out / 'report.html'}")
    # the rest can only be compile notices, on a cold cache
    others = [line for line in err.splitlines()[:-1] if not numbered.fullmatch(line)]
    assert all(line.startswith("brdf: compiling ") for line in others), others


@pytest.mark.slow
@pytest.mark.xdist_group("demo")
def test_report_in_a_headless_browser(results):
    out, summary, _ = results
    dom = _dom(out / "report.html")
    expected = (sum(len(e["images"]) for e in summary["datasets"].values()) +
                len(summary["capture"]["images"]))
    assert int(_attribute(dom, "data-images-total")) == expected
    assert int(_attribute(dom, "data-images-loaded")) == expected
    assert "Model comparison" in dom and "Posterior of the best fit" in dom
    # every picture is a link that opens it at full size: report.html#view-N shows picture N
    # in the viewer at its own width (the corner plot is far wider than its thumbnail)
    report = _Report()
    report.feed((out / "report.html").read_text(encoding="utf-8"))
    assert len(report.pictures) == expected
    for k, (picture, link) in enumerate(report.pictures):
        assert picture["src"].startswith("data:image/png;base64,")
        assert link is not None and link.get("class") == "zoom", picture["alt"]
        assert link["href"] == f"#view-{k}"
    corner = [k for k, (p, _) in enumerate(report.pictures) if p["alt"].endswith("corner.png")]
    with Image.open(out / "paper-white-corner.png") as image:
        width = image.width
    dom = _dom(out / "report.html", f"#view-{corner[0]}")
    assert _attribute(dom, "data-viewing") == f"view-{corner[0]}"
    assert int(_attribute(dom, "data-viewer-natural")) == width
    assert int(_attribute(dom, "data-viewer-width")) == width


@pytest.mark.slow
@pytest.mark.xdist_group("demo")
def test_report_numbers_have_four_significant_digits_and_samples_are_not_values(results):
    out, summary, _ = results
    report = _Report()
    report.feed((out / "report.html").read_text(encoding="utf-8"))
    text = " ".join(report.text)
    # decimals only: counts (samples, steps, ranks) are exact integers
    numbers = DECIMAL.findall(text)
    assert len(numbers) > 50
    digits = {n: len(re.sub(r"[-.]", "", n.lower().split("e")[0]).lstrip("0")) for n in numbers}
    assert max(digits.values()) <= 4, [n for n, d in digits.items() if d > 4]
    # the fitted specs are there, rounded
    for e in summary["datasets"].values():
        assert round_numbers(e["compare"][0]["fitted"]) in text
    # the measurement's table counts missing samples (direction pairs) apart from values
    for e in summary["datasets"].values():
        info = e["info"]
        n, c = info["samples"], info["channels"]
        assert f"{n:,} direction pairs x {c} channels = {n * c:,} values" in text
        assert f"missing samples {info['missing_samples']:,} of {n:,}" in text
        assert f"missing values {info['missing_values']:,} of {n * c:,}" in text
    merl = summary["datasets"]["synthetic-merl"]["info"]
    assert merl["missing_values"] == 3 * merl["missing_samples"] > 0


def test_demo_refuses_a_non_empty_folder(tmp_path):
    from brdf.errors import OutputError
    (tmp_path / "keep.txt").write_text("mine")
    with pytest.raises(OutputError, match="not empty"):
        demo.run(tmp_path, quick=True)


def test_the_second_process_compiles_the_renderer_before_the_rest_of_the_models(monkeypatch):
    """The demo waits for the fits' and the renderer's kernels only; the rest of the model
    kernels, which the commands a user runs next need, compile after them."""
    import threading
    from brdf import precompile
    events, ready = [], threading.Event()
    monkeypatch.setattr(precompile, "compile_groups",
                        lambda names: events.append((list(names), ready.is_set())))
    demo._compile_ahead(ready)
    assert events == [(["fitting", "render"], False), (["models"], True)]
    assert ready.is_set()
