"""brdf.progress: one bar factory, on standard error, on a terminal by default; the long
calls (fit, render) draw it when asked and stay silent when not."""

import numpy as np

import brdf
import brdf.render
from brdf.progress import bar


def test_bar_only_when_enabled_or_on_a_terminal(capsys, monkeypatch):
    assert bar(10, "fit", "eval", False) is None
    monkeypatch.setattr("sys.stderr.isatty", lambda: False, raising=False)
    assert bar(10, "fit", "eval") is None
    b = bar(10, "fit", "eval", True)
    b.update(10)
    b.close()
    err = capsys.readouterr().err
    assert "fit" in err and "eval" in err


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
    assert capsys.readouterr().err == "" and np.isfinite(result.image).all()
