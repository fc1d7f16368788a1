"""Does a fit look right? Render a measured material and its fitted model side by side.

Run: ``python examples/render_validation.py [OUTDIR]``

Reads the bundled RGL measurement of white paper, fits ``lambert + ggx`` to it, and renders
the table and the fit on BRDF Explorer's lit sphere with the same seed (small settings: a few
seconds once the kernels are compiled). Writes the images, the false-colour difference, the
FLIP error map and comparison.png (all four side by side, with colour bars) into OUTDIR
(default: a temporary folder) and prints the image metrics; the same as ``brdf-fit validate
measurements/rgl/paper_white_rgb.bsdf REPORT -o OUTDIR``.
"""

import sys
import tempfile
from pathlib import Path

import brdf
from brdf.render.validate import validate

DATA = Path(__file__).resolve().parent.parent / "measurements" / "rgl" / "paper_white_rgb.bsdf"


def main(outdir=None):
    table = brdf.read(DATA)
    fit = brdf.fit(table, "lambert + ggx", seed=1)
    print(f"fitted {fit.model} to {DATA.name}")
    outdir = Path(outdir or tempfile.mkdtemp(prefix="render_validation_"))
    metrics = validate(table, fit.model, outdir, scene="sphere", spp=8, size=(48, 48), seed=1,
                       force=True, progress=False)
    print(f"measured vs fitted on the lit sphere, {metrics['spp']} spp, "
          f"{metrics['size'][0]} x {metrics['size'][1]}:")
    for key, label in (("rmse", "RMSE"), ("relmse", "relative MSE"), ("flip", "FLIP (mean)")):
        print(f"  {label:13s} {metrics[key]:.4g}")
    print(f"  mean RGB      measured {', '.join(f'{x:.4f}' for x in metrics['mean_reference'])}"
          f"; fitted {', '.join(f'{x:.4f}' for x in metrics['mean_test'])}")
    print(f"images, difference.png, flip.png, comparison.png and metrics.json in {outdir}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
