"""Compile the library's numba kernels ahead of use, several groups at once.

numba compiles a kernel the first time it is called and keeps the machine code in its disk
cache; on a cold cache that is minutes of work on one core. :func:`precompile` runs small calls
of every kernel group, in parts, in separate processes, so the parts compile side by side, and
later processes (a test suite's workers, the demo's renders, a batch of fits) load them from the
cache.
On a warm cache it costs the processes' start-up only.

Without it, a model's kernels compile for the families the model holds (a quick first command);
with it, the kernels over every family are cached, and once it has compiled the models group
it records so in the cache (:func:`brdf.models._kernels.record_every_family`): from then on
every model shares them.

    python -m brdf.precompile [GROUP ...]      (or: brdf-fit precompile [GROUP ...])

Without it, the first call of a group's kernels compiles them, after one line on stderr
(:mod:`brdf.kernel_groups`).
"""

import sys
import time

import numpy as np

from .kernel_groups import announce_first_compiles

__all__ = ["GROUPS", "PROCESSES", "check_groups", "precompile", "compile_groups", "processes_used", "starting",
           "describe", "main"]

_SPEC = "lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.3, fresnel=schlick(f0=0.04))"


def _pairs(n=64):
    from .geometry import directions_from_degrees
    t = np.linspace(0.0, 80.0, n)
    return directions_from_degrees(t, 0.0 * t), directions_from_degrees(t[::-1], 180.0 + t)


def _model_eval():
    """Evaluation of parametric models, their physical checks (albedo, reciprocity) and the
    albedo's gradient (energy-constrained fits), a compilation of its own."""
    import brdf
    model = brdf.parse(_SPEC)
    wi, wo = _pairs()
    model.eval(wi, wo)
    brdf.check(model)
    model.albedo_gradient(wi[:2])


def _model_sampling():
    """Sampling of parametric models and the densities of what they sample."""
    import brdf
    model = brdf.parse(_SPEC)
    wi, wo = _pairs()
    model.pdf(wi, wo), model.sample(wi, np.full((len(wi), 2), 0.3))


def _fitting_problem():
    from .fitting.problem import Problem
    from .table import Table
    wi, wo = _pairs()
    table = Table(wi, wo, np.full((len(wi), 3), 0.2))
    return table, Problem(table, "lambert + ggx(alpha=0.5)")


def _fitting_gradient():
    """The fits' loss with its gradient (gradient-based nlopt). The table is made by hand and
    no fit runs, so the models' kernels (the ``models`` group) are not compiled here a second
    time."""
    _, problem = _fitting_problem()
    problem.loss_and_gradient(problem.x0)


def _fitting_losses():
    """The loss of many parameter rows (derivative-free nlopt, emcee's walkers) and the
    metrics' scores."""
    table, problem = _fitting_problem()
    problem.channel_losses(np.stack([problem.x0, problem.x0]))
    problem.score(np.zeros_like(table.values), problem.terms)


def _merl_table():
    """A constant MERL table: the MERL kernels compile the same for any values."""
    from .io.merl import SHAPE, MerlTable
    return MerlTable(np.full((3, *SHAPE), 0.1))


def _tables():
    """Measured tables: the MERL grid, scattered interpolation and checks of a table. The MERL
    table is :func:`_merl_table`'s: measuring a model on the whole grid (1.5 million
    directions) compiled the same kernels and took a second more of NumPy."""
    import brdf
    wi, wo = _pairs()
    _merl_table().eval(wi, wo)
    table = brdf.measure(_SPEC, "random:400")
    table.eval(wi, wo)
    brdf.check(table, theta_steps=6, anisotropic_steps=(4, 2))


def _render():
    """The path tracer with a parametric and a measured material, the Cornell box, and the
    white furnace (traced in blocks)."""
    import brdf
    from .render import builtin, render
    for material in (brdf.parse(_SPEC), _merl_table()):
        render(builtin("sphere", material), spp=1, size=(4, 4), seed=0)
    render(builtin("cornell"), spp=1, size=(4, 4), seed=0)
    render(builtin("furnace", brdf.parse("lambert + ggx(alpha=0.3)")), spp=1, size=(4, 4),
           seed=0)


def _render_derivatives():
    """The path tracer's specialisation with derivative images (the path method of
    ``fit_images``)."""
    import brdf
    from .render import Derivatives, builtin, render
    model = brdf.parse(_SPEC)
    render(builtin("sphere", model), spp=1, size=(4, 4), seed=0,
           derivatives=Derivatives(model, ["ggx.alpha"]))


#: Kernel groups by name (the names of :data:`brdf.kernel_groups.KERNELS`), each compiled by
#: small calls of the public functions that use them, in parts that compile apart (their own
#: top-level kernels; callees they share come from whichever part compiled them first, through
#: the disk cache, or compile twice). Each part with the CPU seconds it took on an empty cache,
#: rounded up to 5 s, so the longest start first: all parts in one process, longest first, on
#: the 2-core Intel development host (2026-12-06, 64.8 s in all): render 28.8 s, model eval
#: 11.3 s, fitting gradient 8.4 s, render derivatives 5.5 s, fitting losses 5.0 s, model
#: sampling 4.1 s, tables 1.7 s. Their sums set the notice's estimate (40 s on two processes,
#: where two took 39.8 s; 80 s on one, where one took 68.1 s).
GROUPS = {"models": ((_model_eval, 15), (_model_sampling, 5)),
          "fitting": ((_fitting_gradient, 10), (_fitting_losses, 5)),
          "tables": ((_tables, 5),),
          "render": ((_render, 30), (_render_derivatives, 10))}
#: Processes the parts are dealt out to by default (one per core of a 2-core machine).
PROCESSES = 2


def _run(parts):
    """Run ``parts`` (``(group, index)`` pairs of :data:`GROUPS`) in this process, without
    compile notices (the caller reports), over every family (``every_family``, which records
    so in the cache when the parts are done, if they include the models group: without its
    kernels over every family, a later model does better with its own families'): for each,
    ``(seconds, kernels numba compiled)``."""
    from .models._kernels import every_family
    from .progress import reporting
    notice = announce_first_compiles()
    out = []
    with reporting(quiet=True), every_family(record=any(g == "models" for g, _ in parts)):
        for group, index in parts:
            start, before = time.perf_counter(), notice.compiled
            GROUPS[group][index][0]()
            out.append((time.perf_counter() - start, notice.compiled - before))
    return out


def _totals(names, done):
    """Per group in ``names`` order, the sums of its parts' ``(seconds, compiled)`` in
    ``done`` (a dict from ``(group, index)``)."""
    took = {name: {"seconds": 0.0, "compiled": 0} for name in names}
    for (group, _), (seconds, compiled) in done.items():
        took[group]["seconds"] += seconds
        took[group]["compiled"] += compiled
    return took


def compile_groups(names):
    """Run the groups ``names`` in this process, without compile notices (the caller
    reports): for each, ``{"seconds": ..., "compiled": ...}``, the seconds it took and the
    kernels numba compiled (0: all came from the disk cache)."""
    parts = _parts(names)
    return _totals(names, dict(zip(parts, _run(parts))))


def _parts(names):
    """The ``(group, index)`` parts of the groups ``names``, the longest (cold) first."""
    parts = [(g, i) for g in names for i in range(len(GROUPS[g]))]
    return sorted(parts, key=lambda part: -GROUPS[part[0]][part[1]][1])


def _cold_wall(names, processes):
    """Seconds a cold cache takes: the parts, longest first, each to the first free process."""
    ends = [0.0] * processes_used(names, processes)
    for group, index in _parts(names):
        k = ends.index(min(ends))
        ends[k] += GROUPS[group][index][1]
    return max(ends)


def processes_used(names, processes):
    """How many of ``processes`` worker processes :func:`precompile` starts for the groups
    ``names``: no more than they have parts."""
    return max(1, min(int(processes), len(_parts(names))))


def starting(names, processes):
    """What :func:`precompile` is about to do, in a line: the groups, the processes and the
    time a cold cache takes (a warm one takes seconds)."""
    n = processes_used(names, processes)
    return (f"compiling {', '.join(names)} in {n} process{'es' * (n > 1)} (about "
            f"{round(_cold_wall(names, n) / 5) * 5:.0f} s on a cold cache, seconds on a warm "
            "one) ...")


def describe(name, took):
    """One line for a group :func:`compile_groups` ran: ``models: compiled 41 kernels in
    38.2 s`` or ``models: loaded from the cache in 1.1 s``."""
    done = (f"compiled {took['compiled']} kernel{'s' * (took['compiled'] != 1)}"
            if took["compiled"] else "loaded from the cache")
    return f"{name}: {done} in {took['seconds']:.1f} s"


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
        Worker processes; the groups' parts go to them longest first, each to the first
        process that is free.

    Returns
    -------
    dict
        For each group, as :func:`compile_groups` gives it: the seconds its parts took
        (compiling, or loading from the cache; summed over the processes) and how many kernels
        numba compiled.

    Raises
    ------
    MainGuardError
        When the workers die as they start because the calling script makes this call at its
        top level: spawned workers import the script again, so the call belongs under
        ``if __name__ == "__main__":``.
    """
    from . import spawned
    spawned.stop_if_starting()
    check_groups(groups)
    parts = _parts(groups)
    workers, started = spawned.pool(processes_used(groups, processes))
    with spawned.main_guarded(started, "brdf.precompile.precompile"), workers:
        futures = {part: workers.submit(_run, [part]) for part in parts}
        done = {part: future.result()[0] for part, future in futures.items()}
    return _totals(groups, done)


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
