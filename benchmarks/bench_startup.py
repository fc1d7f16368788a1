"""Start-up time of ``import brdf`` and ``brdf-fit --help`` (target: under 0.5 s each).

Run: ``python benchmarks/bench_startup.py [--repeats 5]``

Each is timed as a fresh interpreter process, best of the repeats; the baseline is the bare
interpreter (``python -c pass``) measured in the same run, and the budget of 0.5 s.
"""

import argparse
import shutil
import subprocess
import sys
import time


def best_of(cmd, repeats):
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        best = min(best, time.perf_counter() - start)
    return best


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    cli = shutil.which("brdf-fit")
    rows = [("python -c pass (baseline)", [sys.executable, "-c", "pass"]),
            ("python -c 'import brdf'", [sys.executable, "-c", "import brdf"])]
    if cli:
        rows.append(("brdf-fit --help", [cli, "--help"]))
    else:
        print("brdf-fit is not on PATH: install the package to time the command line")
    base = None
    print(f"{'command':32s} {'best s':>8s} {'/ 0.5 s':>8s} {'minus python':>13s}")
    for name, cmd in rows:
        t = best_of(cmd, args.repeats)
        base = t if base is None else base
        print(f"{name:32s} {t:8.3f} {t / 0.5:8.2f} {t - base:13.3f}")


if __name__ == "__main__":
    main()
