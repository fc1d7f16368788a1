"""The command line's own cost: start-up, a warm ``brdf-fit check`` and ``brdf-fit render`` of
the Cornell box stage by stage, and (``--cold``) the first run after ``pip install``.

Run: ``python benchmarks/bench_startup.py [--repeats 5] [--cold]``

Warm (the kernels in numba's disk cache): each command is timed as a fresh process, best and
median of the repeats, in wall seconds and in CPU seconds (user + system, the steadier figure on
a shared host); the baselines are the bare interpreter (``python -c pass``) and, for the
render, the same render alone in a warm process (best of the repeats), both measured in the
same run; ``import numpy, numba`` is the floor of any command that runs a kernel. Targets (issue 27): ``check`` of one model under 0.5 s, and the render's overhead
(the command's wall time minus the render alone) under 0.3 s. The stages are timed inside the
command's own code path (``brdf_cli.main.main`` with timers around the library calls it makes):
python start (the bare interpreter), imports, argument parsing, scene compilation, kernel
loading (the render's first call: numba's cache load), the render and the EXR write. The
package's bytecode is compiled first (``compileall``), as ``pip install`` does: with
``PYTHONDONTWRITEBYTECODE`` set, an editable install otherwise compiles every module of the
package from source in every process (0.1-0.15 s of each command on the 2-core host).

``--cold`` times, on a throwaway kernel cache (numba's own locator for ``NUMBA_CACHE_DIR``, the
user's warm cache untouched): ``python -m brdf.precompile`` (all groups, its default 2
processes) and ``brdf-fit precompile --processes 1`` (one process), each on an empty cache;
then, on another empty cache, a new user's first ``check`` and first ``render`` in turn, with
the notices they print. Targets: all kernels in under 60 s in one process, the first ``check``
under 10 s. Several minutes of CPU.
"""

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

SPEC = "lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.2)"
#: The render of issue 27: the Cornell box (its own materials), 256 x 256, 64 spp, depth 8.
RENDER = ["render", "lambert", "--scene", "cornell", "--size", "256x256", "--spp", "64",
          "--force"]
STAGES = ("python start", "import", "argument parsing", "scene compile", "kernel load",
          "render", "write", "other")


def _cli():
    return shutil.which("brdf-fit") or os.path.join(os.path.dirname(sys.executable), "brdf-fit")


def _children_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def timed(cmd, repeats, env=None, overhead=False):
    """``(best, median, best CPU, median CPU)`` wall and CPU seconds of ``repeats`` runs of
    ``cmd`` (exit status 0 or 1); with ``overhead``, wall seconds minus the render's own
    ``seconds`` (``--json``), and no CPU figures (None)."""
    times, cpus = [], []
    for _ in range(repeats):
        start, cpu = time.perf_counter(), _children_cpu()
        done = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
        times.append(time.perf_counter() - start)
        cpus.append(_children_cpu() - cpu)
        if done.returncode not in (0, 1):
            raise SystemExit(f"{' '.join(cmd)}: exit {done.returncode}\n{done.stderr.decode()}")
        if overhead:
            times[-1] -= json.loads(done.stdout)["seconds"]
    if overhead:
        return min(times), statistics.median(times), None, None
    return min(times), statistics.median(times), min(cpus), statistics.median(cpus)


def compile_bytecode():
    """Compile the bytecode of ``brdf`` and ``brdf_cli`` where it is missing or stale, as
    ``pip install`` does; whether Python would have written it itself."""
    import compileall
    import brdf
    import brdf_cli
    for package in (brdf, brdf_cli):
        compileall.compile_dir(os.path.dirname(package.__file__), quiet=1)
    return not sys.flags.dont_write_bytecode


# --- the render's stages, inside one command ---------------------------------------------------

def stages(out):
    """Run ``brdf-fit render`` (:data:`RENDER` to ``out``) in this process, timing its stages;
    print them as JSON. Called in a fresh interpreter (``--stages OUT``)."""
    start, cpu_start = time.perf_counter(), time.process_time()
    import brdf_cli.main as cli_main
    import brdf_cli.render as cli_render
    import brdf
    import brdf.render as R
    import brdf.render.image  # noqa: F401  (the EXR writer's module; OpenEXR itself on write)
    import brdf.render.scene as S
    import brdf.render._integrator  # noqa: F401  (the kernels' module, its dispatchers made)
    t = {"import": time.perf_counter() - start, "scene compile": 0.0, "write": 0.0,
         "import CPU": time.process_time() - cpu_start}
    marks = {}

    def around(owner, name, stage):
        inner = getattr(owner, name)

        def timed_call(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return inner(*args, **kwargs)
            finally:
                t[stage] += time.perf_counter() - t0
        setattr(owner, name, timed_call)

    handler = cli_render.render

    def entered(args, output):
        marks["handler"] = time.perf_counter()
        return handler(args, output)
    cli_render.render = entered
    around(S.Scene, "compile", "scene compile")
    around(cli_render, "load_subject", "scene compile")
    around(cli_render, "_scene", "scene compile")
    around(R.RenderResult, "save", "write")
    render = R.render

    def rendering(*args, **kwargs):
        cpu = time.process_time()
        result = render(*args, **kwargs)
        marks["result"], marks["render CPU"] = result, time.process_time() - cpu
        return result
    R.render = rendering
    parse_start = time.perf_counter()
    status = cli_main.main(["-q", *RENDER, "-o", out])
    end = time.perf_counter()
    assert status == 0, status
    result = marks["result"]
    t["argument parsing"] = marks["handler"] - parse_start
    t["kernel load"] = result.compile_seconds
    t["render"] = result.seconds
    t["other"] = (end - start) - sum(v for k, v in t.items() if k in STAGES)
    # CPU of every thread but the render call's (which runs on all cores), plus its kernel
    # load (one thread, so its wall seconds are its CPU seconds)
    t["CPU"] = (time.process_time() - cpu_start - marks["render CPU"]
                + result.compile_seconds)
    print(json.dumps(t))
    del brdf


def render_alone(repeats):
    """Best seconds of the Cornell render alone (``render(...).seconds``) in a warm process."""
    from brdf import render as R
    scene = R.builtin("cornell")
    best = float("inf")
    for _ in range(repeats + 1):  # the first loads the kernels
        r = R.render(scene, spp=64, size=(256, 256), seed=0, progress=False)
        best = min(best, r.seconds)
    print(json.dumps({"render alone": best}))


def _child(*argv, env=None):
    done = subprocess.run([sys.executable, __file__, *argv], capture_output=True, text=True,
                          env=env, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def warm(repeats):
    cli = _cli()
    if not compile_bytecode():
        print("bytecode of brdf and brdf_cli compiled first (PYTHONDONTWRITEBYTECODE is set; "
              "pip install compiles it)\n")
    py = timed([sys.executable, "-c", "pass"], repeats)
    rows = [("python -c pass (baseline)", py),
            ("python -c 'import numpy, numba' (floor)",
             timed([sys.executable, "-c", "import numpy, numba"], repeats)),
            ("python -c 'import brdf'", timed([sys.executable, "-c", "import brdf"], repeats)),
            ("brdf-fit --help", timed([cli, "--help"], repeats))]
    check = timed([cli, "check", SPEC], repeats)
    rows.append((f"brdf-fit check (1 model)", check))
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "cornell.exr")
        timed([cli, *RENDER, "-o", out], 1)  # warm the page cache
        rend = timed([cli, *RENDER, "-o", out], repeats)
        rows.append(("brdf-fit render (Cornell 256^2 x 64)", rend))
        own = timed([cli, *RENDER, "--json", "-o", out], repeats, overhead=True)
        runs = [_child("--stages", out) for _ in range(repeats)]
    alone = _child("--render-alone", str(repeats))["render alone"]
    print(f"load average {os.getloadavg()[0]:.1f} ({os.cpu_count()} cores)")
    print(f"{'warm, fresh process each':40s} {'best s':>7s} {'median':>7s} {'- python':>9s} "
          f"{'CPU s':>7s} {'median':>7s} {'- python':>9s}")
    for name, (best, med, cbest, cmed) in rows:
        print(f"{name:40s} {best:7.3f} {med:7.3f} {best - py[0]:9.3f} "
              f"{cbest:7.3f} {cmed:7.3f} {cbest - py[2]:9.3f}")
    print(f"check: {check[0]:.3f}-{check[1]:.3f} s wall, {check[2]:.3f}-{check[3]:.3f} s CPU, "
          f"against the 0.5 s target ({check[2] / 0.5:.2f}x of it in CPU); "
          f"{check[2] / rows[1][1][2]:.2f}x the numpy + numba floor's CPU")
    print(f"render alone (warm process, best): {alone:.3f} s; the command's overhead: "
          f"{rend[0] - alone:.3f} s best, {rend[1] - alone:.3f} s median (target 0.3 s)")
    print(f"the command's overhead against its own render (wall - its render's seconds): "
          f"{own[0]:.3f} s best, {own[1]:.3f} s median (steadier on a busy host)")
    print(f"\nstages of 'brdf-fit {' '.join(RENDER[:3])} ...' ({repeats} runs: best, median)")
    total_best = 0.0
    for stage in STAGES:
        vals = [py[0]] * repeats if stage == "python start" else [r[stage] for r in runs]
        total_best += min(vals)
        print(f"  {stage:20s} {min(vals):7.3f} {statistics.median(vals):7.3f}")
    overhead = total_best - min(r["render"] for r in runs)
    print(f"  {'sum (best of each)':20s} {total_best:7.3f}; without the render: "
          f"{overhead:.3f} s")
    cpu = [r["CPU"] for r in runs]
    print(f"  CPU seconds of all but the render (best, median; python start not included): "
          f"{min(cpu):.3f} {statistics.median(cpu):.3f}; of the imports: "
          f"{min(r['import CPU'] for r in runs):.3f}")


# --- cold: the first run after pip install ---------------------------------------------------

def _cold_env(cache):
    """Environment whose kernels compile into (and load from) the empty folder ``cache`` only."""
    return {**os.environ, "NUMBA_CACHE_LOCATOR_CLASSES": "UserProvidedCacheLocator",
            "NUMBA_CACHE_DIR": cache}


def _run_cold(cmd, cache):
    """Wall seconds, CPU seconds (children) and stderr of ``cmd`` on the cache ``cache``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                          env=_cold_env(cache))
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode not in (0, 1):
        raise SystemExit(f"{' '.join(cmd)}: exit {done.returncode}\n{done.stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, done.stderr


def cold():
    cli = _cli()
    print(f"\ncold kernel cache (a throwaway NUMBA_CACHE_DIR each; {os.cpu_count()} cores, "
          f"load average {os.getloadavg()[0]:.1f} at start)")
    print(f"{'first run':44s} {'wall s':>7s} {'CPU s':>7s}  notices")
    with tempfile.TemporaryDirectory() as tmp:
        runs = [("python -m brdf.precompile (2 processes)",
                 [sys.executable, "-m", "brdf.precompile"], "a"),
                ("brdf-fit precompile --processes 1",
                 [cli, "precompile", "--processes", "1"], "b"),
                ("brdf-fit check (1 model)", [cli, "check", SPEC], "c"),
                ("then brdf-fit render (Cornell)", [cli, *RENDER, "-o",
                                                    os.path.join(tmp, "c.exr")], "c")]
        for name, cmd, cache in runs:
            wall, cpu, err = _run_cold(cmd, os.path.join(tmp, cache))
            notices = [line for line in err.splitlines() if "compiling" in line]
            print(f"{name:44s} {wall:7.1f} {cpu:7.1f}  {len(notices)}", flush=True)
            for line in notices:
                print(f"{'':62s}{line}")
    print("targets: all kernels in one process under 60 s; the first check under 10 s")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--cold", action="store_true",
                        help="also time the first runs on an empty kernel cache (minutes)")
    parser.add_argument("--stages", metavar="OUT", help=argparse.SUPPRESS)
    parser.add_argument("--render-alone", type=int, metavar="N", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.stages:
        return stages(args.stages)
    if args.render_alone:
        return render_alone(args.render_alone)
    warm(args.repeats)
    if args.cold:
        cold()


if __name__ == "__main__":
    main()
