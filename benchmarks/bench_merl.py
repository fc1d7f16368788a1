"""MERL tables: reading a full-size file and 1 M trilinear lookups, against plain numpy.

Run: ``python benchmarks/bench_merl.py [--lookups 1000000] [--repeats 5]``

A MERL-size file (34,992,012 bytes) of ``lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.2)``
sampled at the grid nodes is written to a temporary folder, then:

- ``read``: ``brdf.io.merl.read`` (checks, SHA-256 of the bytes, the table) against a bare
  ``np.fromfile`` of the same bytes; target under 0.3 s. Also shown: read plus a first ``eval``,
  which builds the lookup grids (the values in 1/sr, and the nearest valid sample of each
  missing one: a quarter of the nodes are below the horizon and missing in this table);
- ``lookup``: ``MerlTable.eval`` on random direction pairs against :func:`numpy_trilinear`, the
  same masked trilinear lookup written with vectorised numpy (also the slow reference that
  tests/io/test_merl.py compares the kernel with); target 1 M lookups under 0.2 s.

Both are the best of ``--repeats`` runs after a warm-up (numba compilation, page cache).
"""

import argparse
import math
import tempfile
from pathlib import Path

import numpy as np

import brdf
from brdf.geometry import half_diff_from_directions
from brdf.io import merl
from timing import best_time, random_pairs

SPEC = "lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.2)"
READ_TARGET_S = 0.3
LOOKUP_TARGET_S = 0.2


def grid_coordinates(wi, wo):
    """Continuous grid coordinates ``(u, v, w)`` (docs/conventions.md §6) of direction pairs, from
    :func:`brdf.geometry.half_diff_from_directions`: u = sqrt(theta_h / (pi/2)) 90,
    v = theta_d / (pi/2) 90, w = (phi_d mod pi) / pi 180."""
    theta_h, _, theta_d, phi_d = half_diff_from_directions(wi, wo)
    n0, n1, n2 = merl.SHAPE
    u = np.sqrt(theta_h / (0.5 * math.pi)) * n0
    v = theta_d / (0.5 * math.pi) * n1
    w = np.mod(phi_d, math.pi) / math.pi * n2  # reciprocity folds phi_d by pi
    return u, v, np.where(w >= n2, w - n2, w)


def numpy_trilinear(grid, filled, wi, wo):
    """Reference lookup ``(n, C)``: trilinear in (u, v, w) over the valid (non-NaN) corners,
    weights renormalised; ``filled`` at the nearest node where no corner with positive weight is
    valid; theta indices clamped to the last node, phi_d periodic; 0 below the horizon."""
    n0, n1, n2, _ = grid.shape
    u, v, w = grid_coordinates(wi, wo)
    u, v = np.clip(u, 0.0, n0 - 1.0), np.clip(v, 0.0, n1 - 1.0)
    i0 = np.minimum(u.astype(int), n0 - 2)
    j0 = np.minimum(v.astype(int), n1 - 2)
    p0 = np.minimum(w.astype(int), n2 - 1)
    fu, fv, fw = u - i0, v - j0, w - p0
    total = np.zeros((len(u), grid.shape[3]))
    weight = np.zeros_like(total)
    for di in (0, 1):
        for dj in (0, 1):
            for dp in (0, 1):
                wt = ((fu if di else 1 - fu) * (fv if dj else 1 - fv) * (fw if dp else 1 - fw))
                sample = grid[i0 + di, j0 + dj, (p0 + dp) % n2]
                valid = ~np.isnan(sample)
                total += np.where(valid, wt[:, None] * sample, 0.0)
                weight += np.where(valid, wt[:, None], 0.0)
    nearest = filled[np.minimum((u + 0.5).astype(int), n0 - 1),
                     np.minimum((v + 0.5).astype(int), n1 - 1), (w + 0.5).astype(int) % n2]
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(weight > 0.0, total / weight, nearest)
    above = (wi[:, 2] > 0.0) & (wo[:, 2] > 0.0)
    return np.where(above[:, None], out, 0.0)


def row(name, best, median, per=None):
    rate = f"{per / best / 1e6:10.1f}" if per else f"{'':10s}"
    print(f"  {name:50s} {best * 1e3:9.1f} {median * 1e3:10.1f} {rate}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lookups", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    model = brdf.parse(SPEC)
    wi, wo = merl.grid_directions()
    table = merl.MerlTable.from_grid_values(model.eval(wi, wo), name="bench")
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "bench.binary"
        merl.write(table, path)
        read = best_time(lambda: merl.read(path), args.repeats)
        fromfile = best_time(lambda: np.fromfile(path, dtype="<f8", offset=12), args.repeats)
        # the samples (values, the grid of nearest valid samples) are built on first use
        first = best_time(lambda: merl.read(path).eval([0.0, 0.0, 1.0], [0.0, 0.0, 1.0]),
                          args.repeats)
        size = path.stat().st_size
        table = merl.read(path)

    a, b = random_pairs(args.lookups)
    ours = best_time(lambda: table.eval(a, b), args.repeats)
    grid = table.values.reshape(merl.SHAPE + (3,))
    filled = merl.fill_missing(grid)
    numpy_ref = best_time(lambda: numpy_trilinear(grid, filled, a, b), args.repeats)
    diff = np.max(np.abs(table.eval(a, b) - numpy_trilinear(grid, filled, a, b)))

    print(f"MERL table of {SPEC}, {size:,} bytes; best and median of {args.repeats}")
    print(f"  {'':50s} {'best ms':>9s} {'median ms':>10s} {'M/s':>10s}")
    row("merl.read (checks + SHA-256 + table)", *read)
    row("np.fromfile of the same bytes", *fromfile)
    row("merl.read + first eval (builds the lookup grids)", *first)
    print(f"  ratio read / fromfile: {read[0] / fromfile[0]:.2f}x; target read < "
          f"{READ_TARGET_S * 1e3:.0f} ms: {'met' if read[0] < READ_TARGET_S else 'MISSED'}")
    row(f"MerlTable.eval, {args.lookups:,} pairs (numba)", *ours, per=args.lookups)
    row(f"numpy vectorised trilinear, {args.lookups:,} pairs", *numpy_ref, per=args.lookups)
    target = LOOKUP_TARGET_S * args.lookups / 1e6
    print(f"  speed-up over numpy: {numpy_ref[0] / ours[0]:.1f}x; target < {target * 1e3:.0f} ms "
          f"per {args.lookups:,}: {'met' if ours[0] < target else 'MISSED'}")
    print(f"  max |numba - numpy| = {diff:.2e} 1/sr")


if __name__ == "__main__":
    main()
