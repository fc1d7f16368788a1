"""Compile the library's numba kernels ahead of use, several groups at once.

numba compiles a kernel the first time it is called and keeps the machine code in its disk
cache; on a cold cache that is minutes of work on one core. :func:`precompile` runs small calls
of every kernel group in separate processes, so the groups compile side by side, and later
processes (a test suite's workers, the demo's renders, a batch of fits) load them from the cache.
On a warm cache it costs the processes' start-up only.

    python -m brdf.precompile [GROUP ...]      (or: brdf-fit precompile [GROUP ...])

Without it, the first call of a group's kernels compiles them, after one line on stderr
(:mod:`brdf.kernel_groups`).
"""

import sys
import time

import numpy as np

from .kernel_groups import COLD_SECONDS, announce_first_compiles

__all__ = ["GROUPS", "PROCESSES", "check_groups", "precompile", "compile_groups", "starting", "describe",
           "main"]

_SPEC = "lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.3, fresnel=schlick(f0=0.04))"


def _pairs(n=64):
    from .geometry import directions_from_degrees
    t = np.linspace(0.0, 80.0, n)
    return directions_from_degrees(t, 0.0 * t), directions_from_degrees(t[::-1], 180.0 + t)


def _models():
    """Evaluation, sampling, albedo and the physical checks of parametric models."""
    import brdf
    model = brdf.parse(_SPEC)
    wi, wo = _pairs()
    model.eval(wi, wo), model.pdf(wi, wo), model.sample(wi, np.full((len(wi), 2), 0.3))
    brdf.check(model)


def _fitting():
    """The fits' own kernels: the loss with its gradient (gradient-based nlopt), the loss of
    many parameter rows (derivative-free nlopt, emcee's walkers) and the metrics' scores. The
    table is made by hand and no fit runs, so the models' kernels (the ``models`` group) are
    not compiled here a second time."""
    from .fitting.problem import Problem
    from .table import Table
    wi, wo = _pairs()
    table = Table(wi, wo, np.full((len(wi), 3), 0.2))
    problem = Problem(table, "lambert + ggx(alpha=0.5)")
    problem.loss_and_gradient(problem.x0)
    problem.channel_losses(np.stack([problem.x0, problem.x0]))
    problem.score(np.zeros_like(table.values), problem.terms)


def _tables():
    """Measured tables: the MERL grid, scattered interpolation and checks of a table."""
    import brdf
    wi, wo = _pairs()
    for geometry in ("merl", "random:400"):
        table = brdf.measure(_SPEC, geometry)
        table.eval(wi, wo)
    brdf.check(table, theta_steps=6, anisotropic_steps=(4, 2))


def _render():
    """The path tracer with a parametric and a measured material, and the Cornell box."""
    import brdf
    from .io.merl import MerlTable
    from .render import builtin, render
    for material in (brdf.parse(_SPEC), MerlTable(np.full((3, 90, 90, 180), 0.1))):
        render(builtin("sphere", material), spp=1, size=(4, 4), seed=0)
    render(builtin("cornell"), spp=1, size=(4, 4), seed=0)


#: Kernel groups by name, each compiled by small calls of the public functions that use them
#: (the same names as :data:`brdf.kernel_groups.KERNELS`).
GROUPS = {"models": _models, "fitting": _fitting, "tables": _tables, "render": _render}
#: Processes the groups are dealt out to by default (one per core of a 2-core machine).
PROCESSES = 2


def compile_groups(names):
    """Run the groups ``names`` in this process, without compile notices (the caller
    reports): for each, ``{"seconds": ..., "compiled": ...}``, the seconds it took and the
    kernels numba compiled (0: all came from the disk cache)."""
    from .progress import reporting
    notice = announce_first_compiles()
    out = {}
    with reporting(quiet=True):
        for name in names:
            start, before = time.perf_counter(), notice.compiled
            GROUPS[name]()
            out[name] = {"seconds": time.perf_counter() - start,
                         "compiled": notice.compiled - before}
    return out


def starting(names, processes):
    """What :func:`precompile` is about to do, in a line: the groups, the processes and the
    time a cold cache takes (a warm one takes seconds)."""
    batches = _batches(names, processes)
    cold = max(sum(COLD_SECONDS[g] for g in batch) for batch in batches)
    return (f"compiling {', '.join(names)} in {len(batches)} "
            f"process{'es' * (len(batches) > 1)} (about {cold} s on a cold cache, seconds on "
            "a warm one) ...")


def describe(name, took):
    """One line for a group :func:`compile_groups` ran: ``models: compiled 41 kernels in
    38.2 s`` or ``models: loaded from the cache in 1.1 s``."""
    done = (f"compiled {took['compiled']} kernel{'s' * (took['compiled'] != 1)}"
            if took["compiled"] else "loaded from the cache")
    return f"{name}: {done} in {took['seconds']:.1f} s"


def _batches(groups, processes):
    """``groups`` dealt out to at most ``processes`` processes in order, in equal shares."""
    processes = max(1, min(int(processes), len(groups)))
    share = -(-len(groups) // processes)
    return [list(groups[i:i + share]) for i in range(0, len(groups), share)]


def check_groups(groups):
    """InputError naming any of ``groups`` that is not a key of :data:`GROUPS`."""
    from .errors import InputError
    unknown = [g for g in groups if g not in GROUPS]
    if unknown:
        raise InputError(f"unknown kernel group(s) {', '.join(unknown)}; groups: "
                         f"{', '.join(GROUPS)}")


def precompile(groups=tuple(GROUPS), processes=PROCESSES):
    """Compile the kernels of ``groups`` into numba's disk cache, in ``processes`` processes.

    Parameters
    ----------
    groups : sequence of str
        Keys of :data:`GROUPS`.
    processes : int
        Worker processes; the groups are dealt out to them in order, in equal shares.

    Returns
    -------
    dict
        For each group, as :func:`compile_groups` gives it: the seconds it took (compiling,
        or loading from the cache) and how many kernels numba compiled.
    """
    from concurrent.futures import ProcessPoolExecutor
    import multiprocessing
    check_groups(groups)
    batches = _batches(groups, processes)
    took = {}
    with ProcessPoolExecutor(len(batches), mp_context=multiprocessing.get_context("spawn")) as pool:
        for done in pool.map(compile_groups, batches):
            took.update(done)
    return took


def main(argv=None):
    """``python -m brdf.precompile [GROUP ...]``: one line per group on stdout and 0, or 2
    with one line for an unknown group."""
    from .errors import InputError
    names = tuple(sys.argv[1:] if argv is None else argv) or tuple(GROUPS)
    try:
        check_groups(names)
    except InputError as exc:
        print(f"brdf.precompile: error: {exc}", file=sys.stderr)
        return 2
    print(f"brdf.precompile: {starting(names, PROCESSES)}", file=sys.stderr, flush=True)
    took = precompile(names)
    for name, done in took.items():
        print(describe(name, done))
    return 0


if __name__ == "__main__":
    sys.exit(main())
