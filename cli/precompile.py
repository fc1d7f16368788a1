"""``brdf-fit precompile``: compile the kernel groups ahead of use (:mod:`brdf.precompile`,
the same code as ``python -m brdf.precompile``)."""

from . import arguments
from .commands import EXIT_OK

# the groups as brdf.precompile.GROUPS names them, for --help (importing it imports numba)
GROUPS_HELP = "models, fitting, tables, render"


def add_parser(sub, subcommand):
    p = subcommand(sub, "precompile", precompile,
                   "compile the numba kernels once, ahead of use",
                   "Compile the library's numba kernels into the disk cache, the kernel groups' "
                   "parts side by side in worker processes, so that later commands start at once "
                   "instead of compiling on first use (minutes on a cold cache; on a warm one "
                   "it only loads them). Prints, per group, whether it compiled or loaded and "
                   "how long it took.",
                   "print the groups, seconds and kernels compiled as JSON")
    p.add_argument("groups", nargs="*", metavar="GROUP",
                   help=f"kernel groups to compile: {GROUPS_HELP} (default: all)")
    p.add_argument("--processes", type=arguments.integer(1, 64, "a process count"), default=2,
                   metavar="N",
                   help="worker processes the groups' parts are dealt out to (default: 2)")


def precompile(args, out):
    """Compile (or load) the kernel groups; one line per group."""
    import time
    from brdf.precompile import (GROUPS, check_groups, describe, precompile as run,
                                 processes_used, starting)
    from brdf.progress import note
    names = tuple(args.groups) or tuple(GROUPS)
    check_groups(names)
    note(f"precompile: {starting(names, args.processes)}")
    start = time.perf_counter()
    took = run(names, processes=args.processes)
    if args.json:
        out.json({"processes": processes_used(names, args.processes),
                  "seconds": time.perf_counter() - start, "groups": took})
    else:
        for name, done in took.items():
            out.text(describe(name, done))
    return EXIT_OK
