"""``brdf-fit export`` and the ``--export`` option of ``brdf-fit fit``: a fitted model as a
Mitsuba 3 BSDF, a glTF 2.0 material or a MaterialX OpenPBR Surface (the conversion is
:func:`brdf.export`)."""

#: Formats and their file extensions, as in brdf.io.export.FORMATS (not imported here:
#: --help stays fast; a test keeps the two equal).
FORMATS = {"mitsuba": ".xml", "gltf": ".gltf", "materialx": ".mtlx",
           "materialx-standard-surface": ".mtlx"}
FORMAT_HELP = ("mitsuba (a Mitsuba 3 scene holding <bsdf id=\"material\">), gltf (a glTF 2.0 "
               "file with one metallic-roughness material), materialx (a MaterialX document "
               "with an open_pbr_surface and its surfacematerial) or "
               "materialx-standard-surface (the same with a standard_surface)")


def add_parser(sub, subcommand):
    """Register ``export`` with ``subcommand`` (cli.main's helper for common options)."""
    p = subcommand(sub, "export", run,
                   "write a fitted model for Mitsuba 3, glTF 2.0 or MaterialX",
                   "Convert the model of a JSON fit report (or a model spec) to a Mitsuba 3 "
                   "BSDF, a glTF 2.0 metallic-roughness material or a MaterialX OpenPBR "
                   "Surface. The file says, line by line, what "
                   "maps to what and which parts are exact or approximate, with the largest "
                   "relative difference between the two BRDFs. A model the format has no "
                   "counterpart for (phong, ward, oren-nayar, a glTF base colour above 1, ...) "
                   "is written as the closest material of the format's family, fitted to it, "
                   "with its relative RMS difference; beyond --max-error it is refused.",
                   "print what was written as JSON")
    p.add_argument("subject", metavar="REPORT|SPEC",
                   help="a JSON fit report (brdf-fit fit -o) or a model spec")
    p.add_argument("--format", required=True, choices=tuple(FORMATS), help=FORMAT_HELP)
    p.add_argument("-o", "--output", required=True, metavar="PATH", help="the file to write")
    p.add_argument("--force", action="store_true", help="replace PATH if it exists")
    p.add_argument("--exact", action="store_true",
                   help="write only an exact conversion: exit status 1, nothing written, when "
                        "it would be approximate")
    p.add_argument("--measured", action="store_true",
                   help="mitsuba: tabulate the model as an RGL tensor beside PATH (.bsdf) and "
                        "write a measured BSDF reading it (any isotropic model)")
    p.add_argument("--max-error", type=float, default=None, metavar="E",
                   help="largest relative RMS difference of a closest material that is "
                        "written (default 0.75)")


def add_fit_options(p):
    """``--export`` and ``--export-to`` of ``brdf-fit fit``."""
    p.add_argument("--export", choices=tuple(FORMATS), metavar="FORMAT",
                   help=f"also write the fitted model: {FORMAT_HELP}; to --export-to, or "
                        "beside the -o report with the format's extension (.xml, .gltf, "
                        ".mtlx); "
                        "with --json its summary is under the key \"export\"")
    p.add_argument("--export-to", metavar="PATH", help="where --export writes")


def export_path(args):
    """Where ``fit --export`` writes: ``--export-to``, or the report's path with the format's
    extension; None without ``--export``."""
    from pathlib import Path
    from brdf.errors import InputError
    if not args.export:
        if args.export_to:
            raise InputError("--export-to needs --export FORMAT")
        return None
    if args.export_to:
        return args.export_to
    if not args.output:
        raise InputError("--export needs -o REPORT (the export goes beside it) or --export-to "
                         "PATH")
    return str(Path(args.output).with_suffix(FORMATS[args.export]))


def run(args, out):
    """Convert and write; with ``--exact``, exit 1 without writing an approximate one."""
    import brdf
    from .commands import EXIT_CHECK_FAILED, EXIT_OK, load_subject, refuse_existing
    refuse_existing(args, args.output)
    model = load_subject(args.subject)
    if not isinstance(model, brdf.models.Model):
        raise brdf.InputError(f"{args.subject}: a measured table; export takes a fit report or "
                              "a model spec (fit the table first: brdf-fit fit ... -o)")
    if args.measured:
        from pathlib import Path
        refuse_existing(args, str(Path(args.output).with_suffix(".bsdf")))
    if args.exact:
        result = brdf.export(model, args.format, max_error=args.max_error)
        if not result.exact:
            if args.json:
                out.json(result.to_dict())
            else:
                out.text(f"{result}\n{args.output} not written: the conversion is approximate "
                         "and --exact was given")
            return EXIT_CHECK_FAILED
    result = brdf.export(model, args.format, args.output, force=args.force,
                         max_error=args.max_error, measured=args.measured)
    report(result, out, args.json)
    return EXIT_OK


def report(result, out, as_json):
    if as_json:
        out.json(result.to_dict())
    else:
        out.text(str(result))
