"""``brdf-fit``: argument parsing, dispatch and error reporting (docs/conventions.md §4).

Exit status: 0 success, 1 the work ran but a check failed, 2 usage error or bad input, 3 an
internal error (a bug), 128 + N when ended by signal N (130 SIGINT, 143 SIGTERM, 129 SIGHUP):
SIGTERM and SIGHUP are handled like SIGINT, so outputs being written are removed. Errors are
one line on stderr, ``brdf-fit: error: ...``; ``--debug`` prints the traceback before it.
"""

import argparse
import contextlib
import gc
import os
import signal
import sys
import textwrap
import threading

from . import (arguments, commands, demo, explore, export, fit_images, precompile,
               process_exit, render)
from . import viz as viz_commands
from .output import Output

PROG = "brdf-fit"
EXIT_USAGE, EXIT_INTERNAL = 2, 3
# the statuses a shell reports for a process ended by SIGINT or SIGPIPE (128 + signal number)
EXIT_INTERRUPTED, EXIT_BROKEN_PIPE = 130, 141

EPILOG = """exit status: 0 success, 1 a check failed, 2 usage error or bad input, 3 internal error.
Angles are in degrees: theta from the normal (0 to 90), phi from the tangent x towards y.
Run 'brdf-fit SUBCOMMAND --help' for the options of a subcommand."""

SUBJECT_HELP = ("model spec, e.g. \"lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.2)\" "
                "(see 'brdf-fit models'), a measured table file (MERL .binary, .csv, "
                ".npz, ...; see 'brdf-fit info') or a JSON fit report (brdf-fit fit -o)")
DATA_HELP = ("a measured table (MERL .binary, .csv, .npz, RGL .bsdf, ...; see 'brdf-fit "
             "info')")
GEOMETRY_HELP = ("merl (the full MERL grid), inplane:STEP, grid:DTHETA,DPHI, random:N or "
                 "random:N:cosine, or a CSV of angles theta_i,phi_i,theta_o,phi_o (degrees)")


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised where the main thread is when it arrives (as SIGINT raises
    KeyboardInterrupt), so that ``with`` blocks writing outputs remove their temporary files."""

    def __init__(self, signum):
        super().__init__(signum)
        self.signum = signum


def _raise_terminated(signum, frame):
    raise Terminated(signum)


@contextlib.contextmanager
def _terminate_like_interrupt():
    """SIGTERM and SIGHUP raise :class:`Terminated` while the block runs (main thread only:
    elsewhere, as under a test runner's threads, the handlers stay as they are)."""
    import threading
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.signal(s, _raise_terminated) for s in (signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


class UsageError(Exception):
    """A command line argparse rejected; reported as one line, exit status 2."""


class Parser(argparse.ArgumentParser):
    """argparse without the usage block on errors: the message alone, raised to :func:`main`."""

    def error(self, message):
        raise UsageError(message)


class Version(argparse.Action):
    """``--version``, read from the installed distribution's metadata (no library import)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest=dest, default=argparse.SUPPRESS, nargs=0,
                         help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from importlib.metadata import version
        print(f"{PROG} {version('brdf')}")
        parser.exit()


def _common(suppress):
    """--debug and --quiet, accepted before and after the subcommand."""
    p = argparse.ArgumentParser(add_help=False)
    default = argparse.SUPPRESS if suppress else False
    p.add_argument("--debug", action="store_true", default=default,
                   help="show the traceback of errors")
    p.add_argument("-q", "--quiet", action="store_true", default=default,
                   help="print nothing but --json output and errors (the exit status tells): "
                        "no progress bars or lines, no compile notices")
    p.add_argument("--plugin", action="append", default=argparse.SUPPRESS if suppress else [],
                   metavar="FILE.py|MODULE",
                   help="import a Python file or module that registers custom model families "
                        "(brdf.register_model) before running; repeatable")
    return p


def _sample_option(p):
    p.add_argument("--sample", type=arguments.count, default=None, metavar="N",
                   help="for a file holding several materials (CUReT abrdf.dat: 1 to 61), "
                        "the one to use (default: the first)")


class _Unbuilt:
    """Stands in for the parser of a subcommand the command line did not name: whatever is
    added to it is dropped."""

    def __getattr__(self, name):
        return lambda *args, **kwargs: self


def _subcommand(sub, name, handler, help, description, json_help):
    if isinstance(sub, _Unbuilt):  # a subcommand of one that is not built (plot KIND)
        return sub
    only = getattr(sub, "brdf_only", None)
    if only is not None:
        if name != only:
            return _Unbuilt()
        sub.brdf_found = True
    p = sub.add_parser(name, help=help, description=textwrap.fill(description, 79),
                       epilog=EPILOG,
                       parents=[_common(suppress=True)],
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--json", action="store_true", help=json_help)
    p.set_defaults(handler=handler)
    return p


def _named_subcommand(argv):
    """The word of ``argv`` in the subcommand's place (None if there is none): the first that
    is neither an option nor the file of a ``--plugin`` before it."""
    words = iter(argv)
    for word in words:
        if word == "--plugin":
            next(words, None)
        elif not word.startswith("-"):
            return word
    return None


def build_parser(argv=None):
    """The ``brdf-fit`` parser. Given the command line ``argv``, only the subcommand it names
    gets its options (building all 25 took 0.025 s, most of it argparse's look-ups of
    translations); with none named, or a name that is no subcommand, all of them do."""
    only = None if argv is None else _named_subcommand(argv)
    parser = Parser(prog=PROG, parents=[_common(suppress=False)], epilog=EPILOG,
                    formatter_class=argparse.RawDescriptionHelpFormatter,
                    description="Measure, check, fit and render BRDFs.")
    parser.add_argument("--version", action=Version, help="print the version and exit")
    sub = parser.add_subparsers(dest="command", metavar="SUBCOMMAND", required=True)
    sub.brdf_only, sub.brdf_found = only, False

    _subcommand(sub, "models", commands.models, "list model families and their parameters",
                "List every model family and Fresnel term: aliases, summary, citation, and "
                "parameters with defaults, bounds, units and choices.",
                "print the list as JSON (unbounded limits are null)")

    p = _subcommand(sub, "check", commands.check,
                    "check non-negativity, reciprocity and energy conservation",
                    "Check a model: non-negativity and Helmholtz reciprocity over a grid plus "
                    "random direction pairs, and energy conservation (directional albedo <= 1 "
                    "up to the quadrature error). Exit status 1 when a check fails.",
                    "print the report as JSON, with the albedo curve")
    p.add_argument("spec", metavar="SPEC|FILE", help=SUBJECT_HELP)
    _sample_option(p)
    p.add_argument("--seed", type=arguments.seed, default=0,
                   help="seed of the random direction pairs (default: 0)")

    p = _subcommand(sub, "eval", commands.evaluate, "evaluate f_r(wi, wo) in 1/sr",
                    "Evaluate the BRDF (without the cosine) for one pair of directions, per "
                    "channel, in 1/sr.", "print the values as JSON")
    p.add_argument("spec", metavar="SPEC|FILE", help=SUBJECT_HELP)
    _sample_option(p)
    p.add_argument("--wi", type=arguments.direction, required=True, metavar="THETA,PHI",
                   help="incident direction (towards the light), degrees")
    p.add_argument("--wo", type=arguments.direction, required=True, metavar="THETA,PHI",
                   help="outgoing direction (towards the viewer), degrees")

    p = _subcommand(sub, "albedo", commands.albedo,
                    "directional albedo with its quadrature error",
                    "Directional albedo a(wi) = integral of f cos(theta_o) over the hemisphere, "
                    "for every combination of the given incidence angles, with the quadrature "
                    "error estimate.", "print the albedos as JSON")
    p.add_argument("spec", metavar="SPEC|FILE", help=SUBJECT_HELP)
    _sample_option(p)
    p.add_argument("--theta-i", type=arguments.theta_list, default=[0.0, 30.0, 60.0, 89.0],
                   metavar="LIST", help="incidence polar angles, degrees (default: 0,30,60,89)")
    p.add_argument("--phi-i", type=arguments.phi_list, default=[0.0], metavar="LIST",
                   help="incidence azimuths, degrees (default: 0)")

    p = _subcommand(sub, "info", commands.info, "describe a measured table",
                    "Describe a measured table: format, channels or wavelengths, sample count, "
                    "angle coverage, value range, missing and negative samples, SHA-256.",
                    "print the description as JSON")
    p.add_argument("file", metavar="FILE", help="a measured table (MERL .binary, .csv, .npz, "
                   "RGL .bsdf, Cornell .brdf, NIST PTFE .csv, CUReT .dat, ALTA text or "
                   "binary .alta/.dat/.txt)")
    _sample_option(p)

    p = _subcommand(sub, "convert", commands.convert, "convert a table to another format",
                    "Read a measured table (or a model: a spec or a JSON fit report) and write "
                    "it in the format the output's extension names (.binary MERL, .csv "
                    "gonioreflectometer CSV, .npz native, .alta ALTA text, .bsdf RGL tensor). Grid formats are "
                    "filled by evaluating the input; a model can be written to .binary and "
                    ".bsdf only.", "print a JSON summary")
    p.add_argument("input", metavar="IN", help="the table file, model spec or fit report to "
                                              "read")
    _sample_option(p)
    p.add_argument("output", metavar="OUT", help="the file to write")
    p.add_argument("--force", action="store_true", help="replace OUT if it exists")

    p = _subcommand(sub, "synth", commands.synth,
                    "measure a model with the virtual gonioreflectometer",
                    "Sample a model (or resample a measured table) at a measurement geometry, "
                    "add noise from a stated model and write the table (format from the "
                    "output's extension). Same seed, same bytes.", "print a JSON summary")
    p.add_argument("spec", metavar="SPEC|FILE", help=SUBJECT_HELP)
    _sample_option(p)
    p.add_argument("--geometry", default="inplane:5", metavar="GEOMETRY",
                   help=GEOMETRY_HELP + " (default: inplane:5)")
    p.add_argument("--noise", default="none", metavar="NOISE",
                   help="none, relative:S (sigma = S f), additive:S (sigma = S 1/sr) or "
                        "poisson:S (sigma = S sqrt(f)) (default: none)")
    p.add_argument("--seed", type=arguments.seed, default=0, help="seed (default: 0)")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="the file to write")
    p.add_argument("--force", action="store_true", help="replace OUT if it exists")
    _fit_parser(sub)
    fit_images.add_parser(sub, _subcommand, _fit_options, arguments)
    _compare_parser(sub)
    _batch_parser(sub)
    export.add_parser(sub, _subcommand)
    render.add_parsers(sub, _subcommand, arguments, SUBJECT_HELP, DATA_HELP)
    viz_commands.add_parsers(sub, _subcommand)
    explore.add_parser(sub, _subcommand)
    demo.add_parser(sub, _subcommand)
    precompile.add_parser(sub, _subcommand)
    if only is not None and not sub.brdf_found:
        return build_parser()
    return parser


def _fit_options(p):
    """The options of a fit, shared by fit and compare (names and defaults as in brdf.fit)."""
    p.add_argument("--loss", default="cosine-l2", metavar="LOSS",
                   help="cosine-l2 (Ngan et al. 2005), l2, relative-l2, log (Loew et al. 2012 "
                        "E2) or chi-square (tables with sigma) (default: cosine-l2)")
    p.add_argument("--optimizer", default="LD_LBFGS", metavar="NAME",
                   help="local: LD_LBFGS, LD_SLSQP, LN_BOBYQA, LN_NELDERMEAD, LN_COBYLA; "
                        "global (then polished): GN_DIRECT_L, GN_CRS2_LM, GN_ISRES, MLSL "
                        "(default: LD_LBFGS)")
    p.add_argument("--starts", type=arguments.starts, default=None, metavar="N",
                   help="local optimizers: N runs, from the data-driven start, the spec's "
                        "values and the best seeded Sobol points of the box; 1: one run from "
                        "the better of the first two (default: 8, brdf.fitting.DEFAULT_STARTS)")
    p.add_argument("--energy-constraint", action="store_true",
                   help="constrain the directional albedo to at most 1 (cheapest with "
                        "--optimizer LD_SLSQP)")
    p.add_argument("--cutoff", type=arguments.cutoff, default=80.0, metavar="DEG",
                   help="leave out samples with theta_i or theta_o above DEG degrees "
                        "(default: 80)")
    p.add_argument("--shared", nargs="+", action="extend", default=[], metavar="NAME",
                   help="per-channel parameters fitted as one value, e.g. ggx.ks")
    p.add_argument("--fix", nargs="+", action="extend", default=[], metavar="NAME=VALUE",
                   help="parameters held fixed, e.g. ggx.alpha=0.2 or lambert.albedo[1]=0.4")
    p.add_argument("--max-evals", type=arguments.integer(1, 10**9, "an evaluation count"),
                   default=2000, metavar="N",
                   help="objective evaluations per run (default: 2000)")
    p.add_argument("--seed", type=arguments.seed, default=0,
                   help="seed of random starts and global optimizers (default: 0)")


def _fit_parser(sub):
    # names and defaults as in brdf.fitting (not imported here: --help stays fast)
    p = _subcommand(sub, "fit", commands.fit, "fit a model to a measured table (nlopt)",
                    "Fit a model spec to a measured table: minimise a loss over the samples "
                    "within the grazing cutoff, starting from the spec's parameter values. "
                    "Prints the fitted parameters, every metric, the optimizer's status and the "
                    "physical checks of the result. Exit status 1 when the fit did not "
                    "converge (or, with --energy-constraint, the energy check still fails).",
                    "print the fit report as JSON")
    p.add_argument("data", metavar="DATA", help=DATA_HELP)
    p.add_argument("spec", metavar="SPEC", help="the model to fit, e.g. \"lambert + "
                   "ggx(alpha=0.3)\"; its values are the starting point")
    _fit_options(p)
    p.add_argument("-o", "--output", metavar="REPORT", help="write the JSON report here")
    p.add_argument("--force", action="store_true", help="replace existing output files")
    m = p.add_argument_group("posterior (emcee)")
    m.add_argument("--mcmc", action="store_true",
                   help="after the fit, sample the posterior: medians, 68%% and 95%% intervals, "
                        "correlations; exit 1 if the chain did not converge")
    arguments.add_chain_options(m)
    m.add_argument("--chain", metavar="PATH", help="save the chain (.npz, or .h5 with h5py)")
    m.add_argument("--corner", metavar="PNG", type=arguments.suffixed(".png", what="a PNG"),
                   help="write a corner plot of the posterior")
    export.add_fit_options(p.add_argument_group("export"))


def _compare_parser(sub):
    p = _subcommand(sub, "compare", commands.compare, "fit several models and rank them (AIC/BIC)",
                    "Fit each SPEC to DATA with the same options and print one table: loss, "
                    "parameter count, AIC, BIC, their difference to the best, Akaike weights, "
                    "convergence and physical checks, best first. Exit status 1 when a fit did "
                    "not converge.", "print the comparison as JSON")
    p.add_argument("data", metavar="DATA", help=DATA_HELP)
    p.add_argument("specs", metavar="SPEC", nargs="+", help="two or more models to fit")
    p.add_argument("--by", choices=("aic", "bic"), default="aic",
                   help="the criterion that orders the table (default: aic)")
    _fit_options(p)
    p.add_argument("-o", "--output", metavar="JSON", help="write the comparison here")
    p.add_argument("--force", action="store_true", help="replace JSON if it exists")


def _batch_parser(sub):
    p = _subcommand(sub, "batch", commands.batch, "fit one model to many tables",
                    "Fit SPEC to every file GLOB matches (quote it: the command expands it, "
                    "recursive patterns included) and write OUTDIR/<stem>.json per file plus OUTDIR/summary.csv "
                    "and summary.json. Runs resume: files whose report matches (input SHA-256, "
                    "spec, options) are skipped; one file's failure does not stop the others. "
                    "Exit status 1 when a file failed or did not converge.",
                    "print the summary as JSON")
    p.add_argument("inputs", metavar="GLOB", help="input files: paths or a quoted glob pattern")
    p.add_argument("spec", metavar="SPEC", help="the model to fit to each file")
    p.add_argument("-o", "--output", metavar="OUTDIR", required=True,
                   help="folder for the reports and the summary (created if missing)")
    p.add_argument("--jobs", type=arguments.integer(1, 1024, "a process count"), metavar="N",
                   help="local worker processes (default: one per core)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the fits on a Dask distributed cluster, e.g. tcp://host:8786 "
                        "(its workers must see the input paths); needs brdf[dask]")
    _fit_options(p)
    p.add_argument("--force", action="store_true", help="refit files that have a report")


def _error(message):
    print(f"{PROG}: error: {' '.join(str(message).split())}", file=sys.stderr)


def _failure(exc, debug):
    """Exit status for an exception raised by a subcommand, after its one-line report."""
    from brdf.errors import BRDFError
    if debug:
        import traceback
        traceback.print_exception(exc)
    if isinstance(exc, BRDFError):
        _error(exc)
        return EXIT_USAGE
    if isinstance(exc, OSError):
        _error(f"{exc.filename}: {exc.strerror}" if exc.filename else exc)
        return EXIT_USAGE
    hint = "" if debug else " (rerun with --debug for the traceback)"
    _error(f"internal error: {type(exc).__name__}: {exc}{hint}")
    return EXIT_INTERNAL


def _load_plugins(args):
    """Import the ``--plugin`` files and modules; 0, or exit status 2 after a one-line error
    naming the plugin (a plugin is the user's input, like a spec)."""
    for source in args.plugin:
        try:
            from brdf.models.custom import load_plugin
            load_plugin(source)
        except Exception as exc:  # noqa: BLE001  (whatever the plugin raises)
            if args.debug:
                import traceback
                traceback.print_exception(exc)
            from brdf.errors import BRDFError
            text = str(exc) if isinstance(exc, BRDFError) else f"{type(exc).__name__}: {exc}"
            _error(text if text.startswith("plugin ") else f"plugin {source}: {text}")
            return EXIT_USAGE
    return 0


#: Seconds from a command's start with Python's cyclic garbage collector off (see :func:`run`).
GC_AFTER = 1.0


def run():
    """The ``brdf-fit`` console script: :func:`main` on the process arguments; the process then
    ends without the interpreter's teardown of its modules (:mod:`brdf_cli.process_exit`).

    OpenBLAS, numpy's BLAS, starts a thread per core when numpy is imported, and each of them
    busy-waits 2^28 cycles for work before it sleeps (0.09-0.1 s of a core in every command,
    which makes only small BLAS calls, if any). Unless the environment says otherwise, the
    command's threads wait 2^4 cycles (``OPENBLAS_THREAD_TIMEOUT``, read when numpy loads
    OpenBLAS), and a BLAS call wakes them.

    Python's cyclic garbage collector is off for the command's first :data:`GC_AFTER` seconds:
    importing numpy, numba and the package makes some 100,000 objects, and the collections
    they set off (one of them over every generation) took 24-32 ms of the imports, where
    reference counting frees what a short command discards. A command still running then (a
    fit, a batch, a first compile) collects as usual from there on, and so does a forked child
    at once (the package's own workers are spawned)."""
    os.environ.setdefault("OPENBLAS_THREAD_TIMEOUT", "4")
    gc.disable()
    timer = threading.Timer(GC_AFTER, gc.enable)
    timer.daemon = True
    timer.start()
    os.register_at_fork(after_in_child=gc.enable)  # a forked child has no timer
    status = main()
    process_exit.arm(status)
    return status


def main(argv=None):
    """Run ``brdf-fit`` with ``argv`` (default: the process arguments); return the exit status."""
    try:
        args = build_parser(sys.argv[1:] if argv is None else argv).parse_args(argv)
    except UsageError as exc:
        _error(exc)
        return EXIT_USAGE
    except SystemExit as exc:  # --help and --version
        return exc.code or 0
    status = _load_plugins(args)
    if status:
        return status
    from brdf.progress import reporting
    try:
        with _terminate_like_interrupt(), reporting(prog=PROG, quiet=args.quiet):
            return args.handler(args, Output(sys.stdout, args.quiet))
    except Terminated as exc:
        _error(f"terminated by {signal.Signals(exc.signum).name}")
        return 128 + exc.signum
    except KeyboardInterrupt:
        _error("interrupted")
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # the reader went away (e.g. `| head`); send the rest to /dev/null so the final flush
        # does not raise again (Python docs, "Note on SIGPIPE")
        import os
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except Exception as exc:  # noqa: BLE001  (every error becomes one line and a status)
        return _failure(exc, args.debug)
