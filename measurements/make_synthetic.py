"""Regenerate the synthetic tables of measurements/synthetic/ with ``brdf-fit synth``.

Each entry is the exact command line (also quoted in measurements/README.md); the same seed
gives the same bytes, which tests/test_measurements.py checks by regenerating every file.

    python measurements/make_synthetic.py [OUTPUT_FOLDER]
"""

import sys
from pathlib import Path

#: file name -> (model spec with the true parameters, geometry, noise, seed)
TABLES = {
    "plastic_grid.csv": ("lambert(albedo=[0.35,0.2,0.1]) + ggx(alpha=0.15, "
                         "fresnel=schlick(f0=0.04))", "grid:10,15", "relative:0.02", 1),
    "brushed_metal_random.csv": ("ggx(ks=[0.95,0.64,0.54], alpha=0.1, alpha_y=0.35)",
                                 "random:3000", "poisson:0.01", 2),
    "matte_paint_inplane.csv": ("lambert(albedo=0.6) + beckmann(ks=0.3, alpha=0.25)",
                                "inplane:2", "additive:0.002", 3),
}


def commands(folder):
    """The ``brdf-fit`` argument lists that write every table into ``folder``."""
    return [["synth", spec, "--geometry", geometry, "--noise", noise, "--seed", str(seed),
             "-o", str(Path(folder) / name), "--force", "--quiet"]
            for name, (spec, geometry, noise, seed) in TABLES.items()]


def main(folder):
    from brdf_cli.main import main as brdf_fit
    for argv in commands(folder):
        status = brdf_fit(argv)
        if status:
            return status
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).parent / "synthetic"))
