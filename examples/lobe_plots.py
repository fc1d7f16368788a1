"""Look at a fit the way a BRDF analyst would: 3-D lobes and the standard 2-D plots.

Run: ``python examples/lobe_plots.py [OUTDIR]`` (default: a new temporary folder)

Measures a glossy paint with the virtual gonioreflectometer (5 % noise), fits Lambert + GGX to
it, then writes: the 3-D lobes of the fit with the measured samples on them (pyvista, off
screen), the in-plane polar plot, the theta_h / theta_d slice, the directional albedo against
the limit 1 and the residual map. Without a display the lobes need EGL (see README).
"""

import sys
import tempfile
from pathlib import Path

import brdf
from brdf import viz
from brdf.viz.samples import label

TRUTH = "lambert(albedo=[0.45,0.30,0.20]) + ggx(alpha=0.15, ks=0.5)"


def main(outdir):
    outdir.mkdir(parents=True, exist_ok=True)
    table = brdf.measure(TRUTH, "grid:10,30", "relative:0.05", seed=7)
    fit = brdf.fit(table, "lambert + ggx(alpha=0.3)", seed=7, max_evals=400)
    print(f"fitted {label(fit.model)} to {len(table)} samples ({fit.loss_name} {fit.loss:.4g})")
    model = fit.model
    pictures = {
        "lobes.png": lambda p: viz.plot_lobes(model, [20.0, 50.0], data=table, path=p,
                                              force=True, resolution=32),
        "lobes_log.png": lambda p: viz.plot_lobes(model, [50.0], data=table, log=True,
                                                  path=p, force=True, resolution=32),
        "inplane.png": lambda p: viz.save_figure(
            viz.inplane_plot(model, [0.0, 30.0, 60.0], data=table), p, force=True),
        "slice.png": lambda p: viz.save_figure(viz.slice_plot(model), p, force=True),
        "albedo.png": lambda p: viz.save_figure(viz.albedo_plot(model, table), p, force=True),
        "residuals.png": lambda p: viz.save_figure(viz.residual_plot(model, table), p,
                                                   force=True),
    }
    for name, draw in pictures.items():
        draw(outdir / name)
        print(f"wrote {outdir / name}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="lobes-")))
