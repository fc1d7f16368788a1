"""brdf.progress: on a terminal a bar, elsewhere one plain line per task or stage on standard
error (never standard output), nothing when quiet or asked for nothing; the long calls (fit,
render, batch) report through it."""

import json
import re

import numpy as np
import pytest

import brdf
import brdf.render
from brdf.progress import bar, mode, note, reporting, stage, task


def on_a_terminal(monkeypatch, yes=True):
    """Standard error (as it is now: capsys swaps it in as the test starts) claims to be a
    terminal, or not; tqdm draws on pytest's capture all the same."""
    monkeypatch.setattr("sys.stderr.isatty", lambda: yes, raising=False)


def test_bar_only_when_enabled_or_on_a_terminal(capsys, monkeypatch):
    assert bar(10, "fit", "eval", False) is None
    monkeypatch.setattr("sys.stderr.isatty", lambda: False, raising=False)
    assert bar(10, "fit", "eval") is None
    b = bar(10, "fit", "eval", True)
    b.update(10)
    b.close()
    err = capsys.readouterr().err
    assert "fit" in err and "eval" in err


def test_mode_on_a_terminal_elsewhere_and_quiet(monkeypatch):
    on_a_terminal(monkeypatch)
    assert (mode(None), mode(True), mode(False)) == ("bar", "bar", None)
    with reporting(quiet=True):
        assert (mode(None), mode(True), mode(False)) == (None, "bar", None)
        assert bar(10, "fit", "eval") is None
    on_a_terminal(monkeypatch, False)
    assert (mode(None), mode(True), mode(False)) == ("lines", "bar", None)


def test_a_task_is_one_line_on_stderr_when_it_ends(capsys):
    with task(100, "fit", "eval") as t:
        t.update(41)
        t.update()
        t.set_postfix(loss="0.1")
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1
    assert err.startswith("brdf: fit: 42 evals in ") and err.endswith(" s\n")
    with reporting(prog="brdf-fit"), task(8, "render", "spp", units="spp") as t:
        t.update(8)
    assert capsys.readouterr().err.startswith("brdf-fit: render: 8 spp in ")


def test_quiet_off_and_a_failure_print_no_line(capsys):
    with reporting(quiet=True), task(3, "fit", "eval") as t:
        t.update(3)
        note("compiling")
    with task(3, "fit", "eval", progress=False) as t:
        t.done("a.csv fitted")
    with pytest.raises(ZeroDivisionError), task(3, "fit", "eval") as t:
        t.update(1)
        1 / 0
    assert capsys.readouterr() == ("", "")


def test_each_done_unit_is_a_line_then_the_total(capsys):
    with task(2, "batch", "file") as t:
        t.done("a.csv fitted")
        t.done("b.csv failed")
    lines = capsys.readouterr().err.splitlines()
    assert [line.split(" after ")[0] for line in lines[:2]] == [
        "brdf: batch: a.csv fitted (1 of 2)", "brdf: batch: b.csv failed (2 of 2)"]
    assert lines[2].startswith("brdf: batch: 2 files in ") and len(lines) == 3


def test_a_stage_says_its_number_and_seconds(capsys, monkeypatch):
    on_a_terminal(monkeypatch)
    with stage("demo: fits", None, 3, 8) as timing:
        pass
    assert timing["seconds"] >= 0.0
    started, ended = capsys.readouterr().err.splitlines()
    assert started == "brdf: demo: fits (3 of 8) ..."
    assert ended.startswith("brdf: demo: fits (3 of 8) in ") and ended.endswith(" s")


def test_a_stage_off_a_terminal_is_its_end_line_only(capsys):
    with stage("demo: fits", None, 3, 8):
        pass
    with stage("demo: renders", False, 4, 8):
        pass
    with reporting(quiet=True), stage("demo: plots", None, 5, 8):
        pass
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("brdf: demo: fits (3 of 8) in ")


def test_reporting_is_restored_after_the_block():
    with reporting(prog="brdf-fit", quiet=True) as now:
        assert now == ("brdf-fit", True)
        with reporting(quiet=False):
            assert mode(None) is not None
    assert mode(None) is not None and mode(False) is None


def test_fit_and_render_draw_the_bar_when_asked(capsys):
    table = brdf.measure("lambert(albedo=0.5)", "inplane:15")
    brdf.fit(table, "lambert", starts=1, progress=True)
    assert "fit" in capsys.readouterr().err
    brdf.fit(table, "lambert", starts=1, progress=False)
    assert capsys.readouterr().err == ""
    scene = brdf.render.builtin("sphere", "lambert")
    brdf.render.render(scene, spp=2, size=(8, 8), progress=True)
    assert "render" in capsys.readouterr().err
    result = brdf.render.render(scene, spp=2, size=(8, 8), progress=False)
    assert capsys.readouterr().err == "" and result.image.shape == (8, 8, 3)


def test_a_callable_progress_is_called_with_the_count_and_prints_nothing(capsys):
    table = brdf.measure("lambert(albedo=0.5)", "inplane:15")
    calls = []
    result = brdf.fit(table, "lambert", starts=1, max_evals=200,
                      progress=lambda done, total: calls.append((done, total)))
    assert capsys.readouterr().err == ""
    # against the fit's whole budget (a multiple of max_evals: one per run), one step of 1
    # per objective evaluation, and jumps where a run ends early or is not needed, so that
    # done reaches the total when the runs are over
    (total,) = {total for _, total in calls}
    done = [0] + [d for d, _ in calls]
    steps = np.diff(done)
    assert total % 200 == 0 and done[-1] == total and (steps > 0).all()
    assert (steps == 1).sum() == result.evaluations < total
    assert (steps > 1).sum() >= 1


def test_fit_render_and_batch_print_their_line_off_a_terminal(capsys, tmp_path):
    table = brdf.measure("lambert(albedo=0.5)", "inplane:15")
    brdf.fit(table, "lambert", starts=1)
    brdf.render.render(brdf.render.builtin("sphere", "lambert"), spp=2, size=(8, 8))
    brdf.write(table, tmp_path / "t.csv")
    brdf.batch(str(tmp_path / "*.csv"), "lambert", tmp_path / "out", jobs=1, starts=1)
    out, err = capsys.readouterr()
    lines = err.splitlines()
    assert out == "" and len(lines) == 4, err
    assert re.fullmatch(r"brdf: fit: \d+ evals? in \d+\.\d s", lines[0])
    assert lines[1].startswith("brdf: render: 2 spp in ")
    # the batch's fits are silent: the batch reports each file
    assert lines[2].startswith("brdf: batch: t.csv fitted (1 of 1) after ")
    assert lines[3].startswith("brdf: batch: 1 file in ")
    with reporting(quiet=True):
        brdf.fit(table, "lambert", starts=1)
    assert capsys.readouterr() == ("", "")


def test_the_command_line_prints_lines_on_stderr_and_quiet_silences_them(capsys, tmp_path):
    from test_cli import run
    image = tmp_path / "sphere.png"
    argv = ["render", "lambert", "--spp", "2", "--size", "8x8", "-o", str(image), "--json"]
    status, out, err = run(capsys, *argv)
    assert status == 0 and json.loads(out)["spp"] == 2  # stdout is the JSON alone
    assert re.fullmatch(r"brdf-fit: render: 2 spp in \d+\.\d s\n", err)
    assert run(capsys, "-q", *argv, "--force")[::2] == (0, "")
    data = tmp_path / "t.csv"
    brdf.write(brdf.measure("lambert(albedo=0.3)", "inplane:15"), data)
    status, out, err = run(capsys, "fit", str(data), "lambert", "--starts", "1", "--json")
    assert status == 0 and json.loads(out)["converged"]
    assert re.fullmatch(r"brdf-fit: fit: \d+ evals? in \d+\.\d s\n", err)
    assert run(capsys, "fit", str(data), "lambert", "--starts", "1", "--quiet") == (0, "", "")
