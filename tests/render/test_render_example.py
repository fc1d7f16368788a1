"""examples/render_validation.py runs and leaves the validation outputs (smoke test, small
settings; tests/test_examples.py runs it too, without looking at its files)."""

import json
import pathlib
import subprocess
import sys

from brdf.render.validate import OUTPUTS

SCRIPT = pathlib.Path(__file__).parent.parent.parent / "examples" / "render_validation.py"


def test_render_validation_example(tmp_path):
    done = subprocess.run([sys.executable, str(SCRIPT), str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=600, cwd=SCRIPT.parent.parent)
    assert done.returncode == 0, done.stderr
    assert "RMSE" in done.stdout and "FLIP" in done.stdout
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(OUTPUTS)
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    # a two-lobe fit of white paper is close to the measurement, not equal to it
    assert 0 < metrics["rmse"] < 0.2 * max(metrics["mean_reference"])
