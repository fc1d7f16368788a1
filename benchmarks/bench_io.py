"""Table formats and interpolation: read/write speed against plain numpy, and the cost of the
interpolants a measured table answers ``eval`` with.

Run: ``python benchmarks/bench_io.py [--rows 100000] [--repeats 3]``

- ``csv``: ``brdf.io.gonio_csv.read`` of a 100k-row RGB file with sigma columns (validation,
  line-exact errors, the table) against a bare ``np.loadtxt`` of the same file;
- ``alta``: ``brdf.io.alta`` write and read of the same table as an ALTA text file
  (``ISOTROPIC_TV_TL_DPHI`` with ``#VS`` radii) against ``np.savetxt`` / ``np.loadtxt``;
- ``npz``: write + read of a MERL-size plain table (1.458 M samples x 3) against ``np.save`` +
  ``np.load`` of the same arrays;
- ``real``: reading each real data set of ``../shared/measured`` (when present) with its reader,
  against reading the same bytes (``Path.read_bytes``);
- ``eval``: 1 M lookups in a regular grid table (multilinear), a sliced scan (8 incidence
  angles, per-slice triangulation) and a scattered table (3-D Delaunay), each against the
  model it was measured from (the parametric numba eval) as the yardstick.

Figures are the best of ``--repeats`` runs after a warm-up.
"""

import argparse
import tempfile
from pathlib import Path

import numpy as np

import brdf
from brdf.gonioreflectometer import geometry_directions
from brdf.io import alta, gonio_csv, npz
from brdf.table import Table
from timing import best_time

SPEC = "lambert(albedo=[0.5,0.4,0.3]) + ggx(ks=0.5, alpha=0.3)"


def show(name, ours, base, base_name):
    print(f"{name:<28} {ours * 1e3:9.1f} ms   {base_name:<26} {base * 1e3:9.1f} ms   "
          f"ratio {ours / base:5.2f}x")


def bench_csv(folder, rows, repeats):
    model = brdf.parse(SPEC)
    t = brdf.measure(model, f"random:{rows}", "relative:0.02", seed=1)
    path = folder / "big.csv"
    gonio_csv.write(t, path)
    ours = best_time(lambda: gonio_csv.read(path), repeats)[0]
    base = best_time(lambda: np.loadtxt(path, delimiter=",", comments="#", skiprows=8),
                     repeats)[0]
    show(f"csv read {rows:,} rows", ours, base, "np.loadtxt")


def bench_alta(folder, rows, repeats):
    model = brdf.parse(SPEC)
    t = brdf.measure(model, f"random:{rows}", "relative:0.02", seed=1)
    path = folder / "big.alta"
    ours = best_time(lambda: alta.write(t, path), repeats)[0]
    numbers = np.loadtxt(path, comments="#")
    base = best_time(lambda: np.savetxt(folder / "plain.txt", numbers, fmt="%r"), repeats)[0]
    show(f"alta write {rows:,} rows", ours, base, "np.savetxt")
    ours = best_time(lambda: alta.read(path), repeats)[0]
    base = best_time(lambda: np.loadtxt(path, comments="#"), repeats)[0]
    show(f"alta read {rows:,} rows", ours, base, "np.loadtxt")


def bench_npz(folder, repeats):
    wi, wo = geometry_directions("random:1458000", np.random.default_rng(2))
    values = np.random.default_rng(3).random((len(wi), 3))
    t = Table(wi, wo, values)
    path = folder / "big.npz"
    ours = best_time(lambda: (npz.write(t, path), npz.read(path)), repeats)[0]

    def plain():
        np.save(folder / "a.npy", np.concatenate([wi, wo, values], axis=1))
        np.load(folder / "a.npy")
    base = best_time(plain, repeats)[0]
    show("npz write+read 1.458M", ours, base, "np.save + np.load")


REAL = ["nist-ptfe/PTFE.data.csv", "cornell-paints/mystique.brdf", "curet/abrdf.dat",
        "rgl/paper_white_rgb.bsdf"]


def bench_real(repeats):
    folder = Path(__file__).resolve().parents[2] / "shared" / "measured"
    for relative in REAL:
        path = folder / relative
        if not path.is_file():
            print(f"{relative}: not found under {folder}, skipped")
            continue
        ours = best_time(lambda: brdf.read(path), repeats)[0]
        base = best_time(lambda: path.read_bytes(), repeats)[0]
        show(f"read {path.name}", ours, base, "Path.read_bytes")


def bench_eval(repeats, n=1_000_000):
    model = brdf.parse(SPEC)
    wi, wo = geometry_directions(f"random:{n}", np.random.default_rng(4))
    base = best_time(lambda: model.eval(wi, wo), repeats)[0]
    theta_i = np.repeat(np.arange(0.0, 80.0, 10.0), 2000)
    swi = brdf.geometry.directions_from_degrees(theta_i, np.zeros_like(theta_i))
    _, swo = geometry_directions(f"random:{len(theta_i)}", np.random.default_rng(5))
    tables = {"grid 5x5 deg (multilinear)": brdf.measure(model, "grid:5,5"),
              "sliced 8 x 2000 (2-D Delaunay)": Table(swi, swo, model.eval(swi, swo)),
              "scattered 20k (3-D Delaunay)": brdf.measure(model, "random:20000", seed=6)}
    for name, table in tables.items():
        table.eval(wi[:10], wo[:10])  # builds the interpolant
        ours = best_time(lambda: table.eval(wi, wo), repeats)[0]
        show(f"eval 1M, {name}", ours, base, "parametric model eval")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        bench_csv(folder, args.rows, args.repeats)
        bench_alta(folder, args.rows, args.repeats)
        bench_npz(folder, args.repeats)
    bench_real(args.repeats)
    bench_eval(args.repeats)


if __name__ == "__main__":
    main()
