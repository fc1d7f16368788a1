"""Fit one model to a folder of measurements on a Dask distributed cluster, resumably.

Run: ``python examples/batch_dask.py``

Makes four small synthetic tables (paints of different colours, seeded noise) in a temporary
folder, starts a ``dask.distributed.LocalCluster`` with two single-threaded workers (on a real
cluster you would pass the scheduler's address, e.g. ``tcp://host:8786``, and the workers must
see the same paths), fits ``lambert + ggx`` to every file with ``brdf.batch`` and prints the
summary; a second run skips every file, as its reports are already there.
"""

import tempfile
from pathlib import Path

import brdf

SPEC = "lambert(albedo=0.5) + ggx(alpha=0.3, ks=0.2)"
PAINTS = {"red": [0.6, 0.1, 0.1], "green": [0.1, 0.5, 0.1], "blue": [0.1, 0.2, 0.6],
          "grey": [0.3, 0.3, 0.3]}


def make_tables(folder):
    for i, (name, albedo) in enumerate(PAINTS.items()):
        truth = f"lambert(albedo={albedo}) + ggx(alpha=0.25, ks=0.15)"
        brdf.write(brdf.measure(truth, "random:300", noise="relative:0.01", seed=i),
                   folder / f"{name}.csv")


def main():
    from dask.distributed import LocalCluster
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        make_tables(folder)
        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                          dashboard_address=None) as cluster:
            first = brdf.batch(str(folder / "*.csv"), SPEC, folder / "fits",
                               scheduler=cluster.scheduler_address, shared=["ggx.ks"])
            print(first)
            print("\nfitted diffuse albedo (truth in brackets):")
            for row in first.rows:
                name = Path(row["file"]).stem
                fitted = [row.get(f"lambert.albedo[{c}]", float("nan")) for c in range(3)]
                print(f"  {name:6s} " + " ".join(f"{v:.3f}" for v in fitted)
                      + f"  {PAINTS[name]}")
            again = brdf.batch(str(folder / "*.csv"), SPEC, folder / "fits",
                               scheduler=cluster.scheduler_address, shared=["ggx.ks"])
            print(f"\nsecond run: {[row['status'] for row in again.rows]}")
    return 0 if first.ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
