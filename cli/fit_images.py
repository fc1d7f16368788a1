"""``brdf-fit fit-images``: a BRDF from photographs of known scenes (:func:`brdf.fit_images`)."""

#: As brdf.capture.METHODS and RESPONSES (not imported here: --help stays fast).
METHODS = ("direct", "path")
RESPONSE_HELP = ("inverse response of PNG/TIFF photographs: linear, srgb (IEC 61966-2-1) or "
                 "gamma:G (default: linear; OpenEXR images are linear)")


def add_parser(sub, subcommand, fit_options, arguments):
    """Register ``fit-images`` (cli.main passes its helpers for common and fit options)."""
    p = subcommand(sub, "fit-images", run, "fit a model to photographs of known scenes",
                   "Estimate a BRDF from photographs: each --view is a scene file (JSON or "
                   "TOML, as brdf-fit render takes; the unknown BRDF on the shapes whose "
                   "material is \"@material\") and a linear HDR image of it (OpenEXR RGB, its "
                   "size the render size), or an 8-bit PNG/TIFF with --response. The direct "
                   "method (Marschner et al. 1999) turns every masked pixel on the material "
                   "into a BRDF sample from the known geometry and direct light, and fits them "
                   "as brdf-fit fit does (the loss: chi-square when the noise is stated by "
                   "--gain, --sigma or an 8-bit file, else cosine-l2). The report (-o) is a "
                   "fit report with a capture section. Exit status 1 when the fit did not "
                   "converge.",
                   "print the fit report as JSON")
    p.add_argument("spec", metavar="SPEC", help="the model to fit, e.g. \"lambert + ggx\"")
    p.add_argument("--view", nargs=2, action="append", required=True, metavar=("SCENE", "IMAGE"),
                   help="a scene file and its photograph; repeat for more views")
    p.add_argument("--mask", action="append", default=None, metavar="MASK",
                   help="a PNG mask (non-zero: use the pixel), once for all views or once per "
                        "view in order (default: the EXR's alpha, else every pixel)")
    p.add_argument("--method", choices=METHODS, default="direct",
                   help="direct (pixels to samples under direct light) or path (renders "
                        "of the scene through the path tracer, interreflection included, "
                        "started from the direct fit) (default: direct)")
    p.add_argument("--response", default="linear", metavar="RESPONSE", help=RESPONSE_HELP)
    p.add_argument("--gain", type=arguments.number(0.0, None, "photons per unit value",
                                                   low_open=True), metavar="PHOTONS",
                   help="photons per unit of linear pixel value: Poisson noise, and a "
                        "chi-square fit")
    p.add_argument("--sigma", type=arguments.number(0.0, None, "a noise level", low_open=True),
                   metavar="S", help="absolute noise per linear pixel value")
    p.add_argument("--free-scale", action="store_true",
                   help="fit one overall scale (uncalibrated exposure or light power) from "
                        "pixels of known materials in view (a reference target)")
    p.add_argument("--spp", type=arguments.integer(1, 1 << 31, "a sample count"), metavar="N",
                   help="samples per pixel of the path method's renders (default: about a "
                        "million paths per view)")
    p.add_argument("--max-depth", type=arguments.integer(-1, 1 << 20, "a path depth"),
                   metavar="N", help="longest path of the path method (default: 8)")
    p.add_argument("--iterations", type=arguments.integer(1, 100, "a pass count"), default=8,
                   metavar="N", help="passes of the direct method's correction at most "
                                     "(default: 8)")
    fit_options(p)
    # the library picks the loss: chi-square when the noise is stated (--gain, --sigma, 8-bit
    # quantisation), else brdf.fit's cosine-l2; --loss still overrides it
    p.set_defaults(loss=None)
    p.add_argument("-o", "--output", metavar="REPORT", help="write the JSON report here")
    p.add_argument("--residuals", metavar="DIR",
                   help="write DIR/view<k>.exr per view: photograph minus the fit's prediction "
                        "on the pixels used, with prediction and used layers")
    p.add_argument("--force", action="store_true",
                   help="replace an existing report or residual images")
    m = p.add_argument_group("posterior (emcee)")
    m.add_argument("--mcmc", action="store_true",
                   help="sample the posterior: medians and 95%% intervals in the report "
                        "(with --free-scale, the amplitudes carry the scale's uncertainty); "
                        "exit 1 if the chain did not converge")
    m.add_argument("--walkers", type=arguments.integer(2, 100_000, "a walker count"),
                   metavar="N", help="emcee walkers (default: max(32, 4 x parameters))")
    m.add_argument("--max-steps", type=arguments.integer(200, 10_000_000, "a step count"),
                   metavar="N", help="cap on the chain length (default: brdf.mcmc's, 20000)")


def run(args, out):
    """Fit, write the report atomically, print it; exit 1 unless converged."""
    import brdf
    from .commands import EXIT_CHECK_FAILED, EXIT_OK, assignments, emit_report, refuse_existing
    refuse_existing(args, args.output)
    mask = None
    if args.mask:
        if len(args.mask) not in (1, len(args.view)):
            raise brdf.InputError(f"--mask: {len(args.mask)} masks for {len(args.view)} views; "
                                  "give one for all views or one per view")
        mask = args.mask[0] if len(args.mask) == 1 else list(args.mask)
    result = brdf.fit_images(
        args.spec, [tuple(v) for v in args.view], method=args.method,
        free_scale=args.free_scale, mcmc=args.mcmc, seed=args.seed, response=args.response,
        mask=mask, gain=args.gain, sigma=args.sigma, iterations=args.iterations,
        spp=args.spp, max_depth=args.max_depth, walkers=args.walkers,
        max_steps=args.max_steps, residuals=args.residuals, force=args.force,
        **({} if args.loss is None else {"loss": args.loss}),
        optimizer=args.optimizer,
        starts=args.starts, energy_constraint=args.energy_constraint, cutoff=args.cutoff,
        shared=args.shared, fix=assignments(args.fix), max_evals=args.max_evals)
    emit_report(result.to_dict(), result, args, out)
    if result.posterior is not None and not result.posterior.converged:
        return EXIT_CHECK_FAILED
    failed = not result.converged or (args.energy_constraint and not result.energy["holds"])
    return EXIT_CHECK_FAILED if failed else EXIT_OK
