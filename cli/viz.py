"""``brdf-fit lobe`` and ``brdf-fit plot KIND``: pictures of models, tables and fits
(:mod:`brdf.viz`). Registered from :mod:`brdf_cli.main` by :func:`add_parsers`."""

from . import arguments
from .commands import EXIT_OK, refuse_existing, load_subject, read_table

MATERIAL_HELP = ("a model spec, a JSON fit report (its measured input, when the file is "
                 "still there, is drawn too) or a measured table file")
PNG_HELP = "the PNG file to write"


# --- parsers ---------------------------------------------------------------------------------

def _output(p, required=True):
    p.add_argument("-o", "--output", required=required, metavar="PNG",
                   help=PNG_HELP + ("" if required else
                                    " (default: an interactive window, if there is a display)"))
    p.add_argument("--force", action="store_true", help="replace PNG if it exists")


def _channel(p):
    p.add_argument("--channel", type=arguments.channel, metavar="C",
                   help="the channel to draw, 0-based (default: the mean over channels)")


def _material(p, nargs=None):
    p.add_argument("material", metavar="MATERIAL", nargs=nargs, help=MATERIAL_HELP)
    p.add_argument("--sample", type=arguments.count, default=None, metavar="N",
                   help="for a file holding several materials (CUReT), the one to use")


def _data(p):
    p.add_argument("--data", metavar="TABLE",
                   help="measured samples to draw over MATERIAL (default: MATERIAL itself "
                        "when it is a table, or the input of a fit report)")


def _posterior(p):
    p.add_argument("data", metavar="DATA", help="the measured table")
    p.add_argument("model", metavar="MODEL", help="a spec or a JSON fit report to start from "
                   "(a report's loss, cutoff, shared and fixed parameters are reused)")
    arguments.add_chain_options(p)
    p.add_argument("--seed", type=arguments.seed, default=0, help="seed (default: 0)")


def add_parsers(sub, subcommand):
    """Add ``lobe`` and ``plot`` to the subparsers ``sub``; ``subcommand(sub, name, handler,
    help, description, json_help)`` makes one the way :mod:`brdf_cli.main` does."""
    p = subcommand(sub, "lobe", lobe, "draw 3-D reflection lobes (pyvista)",
                   "Draw the lobe r(wo) = f(wi, wo) cos(theta_o) over the outgoing hemisphere "
                   "for each incidence angle, coloured by value, with the incident and mirror "
                   "directions, the normal and the surface; measured samples near the "
                   "incidence as points. Written off screen to PNG with -o (needs EGL on a "
                   "machine without a display), otherwise shown in a window.",
                   "print a JSON summary")
    _material(p)
    _data(p)
    p.add_argument("--theta-i", type=arguments.theta_list_below_horizon, default=[30.0],
                   metavar="LIST",
                   help="incidence polar angles, degrees below 90, one view each (default: 30)")
    p.add_argument("--phi-i", type=arguments.phi, default=0.0, metavar="DEG",
                   help="incidence azimuth, degrees (default: 0)")
    p.add_argument("--log", action="store_true",
                   help="log radius and colour over three decades below the peak")
    p.add_argument("--no-cosine", dest="cosine", action="store_false",
                   help="draw f_r alone, without the cos(theta_o) factor")
    _channel(p)
    p.add_argument("--resolution", type=arguments.integer(4, 1024, "polar steps"), default=48,
                   metavar="N",
                   help="polar steps of the hemisphere mesh (default: 48)")
    _output(p, required=False)

    plot = subcommand(sub, "plot", None, "2-D plots: in-plane, slice, albedo, residuals, "
                      "posterior (matplotlib)",
                      "Write a 2-D plot as PNG. KIND is one of: inplane (polar plot in the "
                      "plane of incidence, measurements over the model), slice (theta_h / "
                      "theta_d image, MERL layout), albedo (directional albedo against "
                      "theta_i with the limit 1), residuals (a model against a table's "
                      "samples), corner and predictive (posterior from emcee). Run "
                      "'brdf-fit plot KIND --help' for each.", "print a JSON summary")
    kinds = plot.add_subparsers(dest="kind", metavar="KIND", required=True)

    p = subcommand(kinds, "inplane", plot_inplane, "in-plane polar plot",
                   "Polar plot of f_r in the plane of incidence for several incidence angles: "
                   "MATERIAL's curves, measured samples taken at each incidence and in its "
                   "plane (within 0.25, 1 or 2.5 degrees: the tightest that finds 30) as "
                   "markers.", "print a JSON summary")
    _material(p)
    _data(p)
    p.add_argument("--theta-i", type=arguments.theta_list, default=[0.0, 30.0, 60.0],
                   metavar="LIST", help="incidence angles, degrees (default: 0,30,60)")
    p.add_argument("--phi-i", type=arguments.phi, default=0.0, metavar="DEG",
                   help="azimuth of the plane of incidence, degrees (default: 0)")
    p.add_argument("--linear", action="store_true", help="linear radius (default: log)")
    p.add_argument("--cosine", action="store_true", help="plot f_r cos(theta_o)")
    _channel(p)
    _output(p)

    p = subcommand(kinds, "slice", plot_slice, "theta_h / theta_d image (MERL layout)",
                   "Image of f_r over theta_h (square-root spacing, as the MERL table) and "
                   "theta_d at one phi_d, log colour.", "print a JSON summary")
    _material(p)
    p.add_argument("--phi-d", type=arguments.phi, default=90.0, metavar="DEG",
                   help="difference azimuth, degrees (default: 90)")
    _channel(p)
    _output(p)

    p = subcommand(kinds, "albedo", plot_albedo, "directional albedo against theta_i",
                   "Directional albedo of each MATERIAL against theta_i with the energy "
                   "conservation limit 1: the mean over channels with their range shaded.",
                   "print a JSON summary")
    _material(p, nargs="+")
    _channel(p)
    _output(p)

    p = subcommand(kinds, "residuals", plot_residuals, "a model against a table's samples",
                   "Model against measured values (log-log) and the map of log10(model / "
                   "measured) over theta_h and theta_d, for the samples within the cutoff.",
                   "print a JSON summary")
    p.add_argument("model", metavar="MODEL", help="a spec or a JSON fit report")
    p.add_argument("data", metavar="DATA", nargs="?",
                   help="the measured table (default: the input of a fit report)")
    p.add_argument("--cutoff", type=arguments.cutoff, default=80.0, metavar="DEG",
                   help="leave out samples with theta_i or theta_o above DEG (default: 80)")
    _channel(p)
    _output(p)

    p = subcommand(kinds, "corner", plot_corner, "posterior corner plot (emcee)",
                   "Sample the posterior of MODEL's parameters given DATA (as 'brdf-fit fit "
                   "--mcmc') and write its corner plot, the optimum marked.",
                   "print a JSON summary")
    _posterior(p)
    _output(p)

    p = subcommand(kinds, "predictive", plot_predictive, "posterior predictive bands (emcee)",
                   "Sample the posterior of MODEL's parameters given DATA and plot the "
                   "predictive bands (median, 68 and 95 percent) of the in-plane BRDF at "
                   "--theta-i with DATA's in-plane samples, and of the directional albedo.",
                   "print a JSON summary")
    _posterior(p)
    p.add_argument("--theta-i", type=arguments.theta, default=30.0, metavar="DEG",
                   help="incidence of the in-plane band, degrees (default: 30)")
    p.add_argument("--draws", type=arguments.integer(1, 100_000, "a draw count"), default=100,
                   metavar="N",
                   help="posterior models drawn for the bands (default: 100)")
    _channel(p)
    _output(p)


# --- handlers --------------------------------------------------------------------------------

def _check_png(args):
    from brdf.errors import InputError
    if args.output is not None and not args.output.lower().endswith(".png"):
        raise InputError(f"{args.output}: the output is a PNG image; name it ....png")
    refuse_existing(args, args.output)


def _subject(text, sample=None):
    """``(subject, data)``: what MATERIAL names, and the measured table that goes with it (a
    table itself, or the input file of a fit report when it still exists)."""
    import os
    import brdf
    if text.lower().endswith(".json"):
        report = brdf.load_report(text)
        path = report.provenance.get("input", {}).get("path")
        return report.model, (read_table(path) if path and os.path.isfile(path) else None)
    from brdf.viz.samples import is_table
    subject = load_subject(text, sample)
    return subject, (subject if is_table(subject) else None)


def _with_data(args):
    subject, data = _subject(args.material, args.sample)
    if args.data:
        data = read_table(args.data)
    return subject, data


def _done(args, out, kind, **facts):
    if args.json:
        out.json({"kind": kind, "output": args.output, **facts})
    elif args.output:
        drawn = f", measured samples from {facts['data']}" if facts.get("data") else ""
        out.text(f"wrote {args.output} ({kind}{drawn})")
    return EXIT_OK


def lobe(args, out):
    """Draw 3-D lobes to PNG (-o) or in a window."""
    from brdf.viz import plot_lobes
    _check_png(args)
    subject, data = _with_data(args)
    plot_lobes(subject, args.theta_i, args.phi_i, data=data, cosine=args.cosine, log=args.log,
               channel=args.channel, resolution=args.resolution, path=args.output,
               force=args.force)
    return _done(args, out, "lobe", material=str(subject), theta_i=args.theta_i,
                 phi_i=args.phi_i, log=args.log, cosine=args.cosine,
                 data=None if data is None else str(data))


def _save(args, out, kind, fig, **facts):
    from brdf.viz import save_figure
    save_figure(fig, args.output, force=args.force)
    return _done(args, out, kind, **facts)


def plot_inplane(args, out):
    from brdf.viz import inplane_plot
    _check_png(args)
    subject, data = _with_data(args)
    fig = inplane_plot(subject, args.theta_i, args.phi_i, data=data, log=not args.linear,
                       cosine=args.cosine, channel=args.channel)
    return _save(args, out, "inplane", fig, material=str(subject), theta_i=args.theta_i,
                 data=None if data is None else str(data))


def plot_slice(args, out):
    from brdf.viz import slice_plot
    _check_png(args)
    subject, _ = _subject(args.material, args.sample)
    return _save(args, out, "slice", slice_plot(subject, args.phi_d, channel=args.channel),
                 material=str(subject), phi_d=args.phi_d)


def plot_albedo(args, out):
    from brdf.viz import albedo_plot
    _check_png(args)
    subjects = [_subject(m, args.sample)[0] for m in args.material]
    return _save(args, out, "albedo", albedo_plot(*subjects, channel=args.channel),
                 materials=[str(s) for s in subjects])


def plot_residuals(args, out):
    from brdf.errors import InputError
    from brdf.viz import residual_plot
    _check_png(args)
    model, data = _subject(args.model)
    if args.data:
        data = read_table(args.data)
    if data is None:
        raise InputError(f"{args.model}: give the measured table DATA (a spec, or a report "
                         "whose input file is gone, names none)")
    fig = residual_plot(model, data, channel=args.channel, cutoff=args.cutoff)
    return _save(args, out, "residuals", fig, model=str(model), data=str(data))


def _posterior_of(args):
    """Run brdf.mcmc for DATA and MODEL (a report's fit options reused)."""
    import brdf
    table = read_table(args.data)
    options = {}
    start = args.model
    if args.model.lower().endswith(".json"):
        report = brdf.load_report(args.model)
        start = report.spec
        saved = report.provenance.get("options", {})
        options = {"loss": saved.get("loss", "cosine-l2"),
                   "cutoff": saved.get("cutoff_deg", 80.0),
                   "shared": saved.get("shared", []), "fix": saved.get("fix", {})}
    return table, brdf.mcmc(table, start, seed=args.seed, **arguments.chain_options(args),
                            **options)


def _posterior_facts(post):
    return {"converged": post.converged, "draws": len(post.samples),
            "parameters": list(post.names)}


def plot_corner(args, out):
    from brdf.viz import corner_plot
    _check_png(args)
    _, post = _posterior_of(args)
    corner_plot(post, args.output, force=args.force)
    return _done(args, out, "corner", **_posterior_facts(post))


def plot_predictive(args, out):
    from brdf.viz import predictive_plot
    _check_png(args)
    table, post = _posterior_of(args)
    fig = predictive_plot(post, table, theta_i=args.theta_i, draws=args.draws,
                          seed=args.seed, channel=args.channel)
    return _save(args, out, "predictive", fig, **_posterior_facts(post))
