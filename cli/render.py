"""``brdf-fit render`` and ``brdf-fit validate``: the validation renders of :mod:`brdf.render`."""

from .commands import EXIT_OK, refuse_existing, load_subject

SCENE_HELP = ("a built-in scene (cornell, sphere, furnace, plane-point) or a .json/.toml scene "
              "file whose shapes use \"@material\" (default: sphere)")


def _size(text):
    import argparse
    from .arguments import parse_int
    try:
        w, _, h = text.lower().partition("x")
        w, h = parse_int(w), parse_int(h or w)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WxH in pixels, e.g. 256x256, got {text!r}")
    if not (1 <= w <= 16384 and 1 <= h <= 16384):
        raise argparse.ArgumentTypeError(f"expected 1 to 16384 pixels a side, got {text!r}")
    return w, h


def _depth(text):
    """--max-depth: a path length of at least 1 segment, or -1 for no limit."""
    import argparse
    from .arguments import parse_int
    try:
        value = parse_int(text)
    except ValueError:
        value = 0
    if value != -1 and not 1 <= value <= 1 << 20:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a path length from 1 to "
                                          f"{1 << 20} segments, or -1 for no limit")
    return value


def _render_options(p, arguments):
    p.add_argument("--scene", default="sphere", metavar="SCENE", help=SCENE_HELP)
    p.add_argument("--spp", type=arguments.integer(1, 1 << 24, "samples per pixel"), default=64,
                   metavar="N",
                   help="samples per pixel (default: 64)")
    p.add_argument("--size", type=_size, default=(256, 256), metavar="WxH",
                   help="image size in pixels (default: 256x256)")
    p.add_argument("--seed", type=arguments.seed, default=0, help="seed (default: 0)")
    p.add_argument("--max-depth", type=_depth, default=8, metavar="N",
                   help="longest path in segments, as Mitsuba counts it; -1: no limit "
                        "(default: 8)")
    p.add_argument("--strategy", choices=("mis", "bsdf", "light"), default="mis",
                   help="emitter sampling: multiple importance sampling (default), BSDF or "
                        "light sampling only")
    p.add_argument("--threads", type=arguments.integer(1, 1024, "a thread count"), metavar="N",
                   help="threads (default: all cores)")
    p.add_argument("--force", action="store_true", help="replace existing outputs")


def add_parsers(sub, subcommand, arguments, subject_help, data_help):
    """Register the render and validate subcommands."""
    p = subcommand(sub, "render", render, "render a material in a scene (path tracer, OpenEXR)",
                   "Render MATERIAL with the bundled path tracer (next-event estimation, "
                   "multiple importance sampling) in a built-in scene or a scene file. Writes "
                   "OpenEXR (float32 RGB with albedo, normal and variance layers), or an sRGB "
                   "PNG when OUT ends in .png; --preview adds a PNG beside the EXR.",
                   "print the render's statistics as JSON")
    p.add_argument("material", metavar="MATERIAL", help=subject_help)
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   type=arguments.suffixed(".exr", ".png", what="an OpenEXR or PNG image"),
                   help="image.exr or image.png")
    p.add_argument("--preview", metavar="PNG", type=arguments.suffixed(".png", what="a PNG"),
                   help="also write a tone-mapped sRGB PNG")
    p.add_argument("--exposure", type=arguments.number(-64.0, 64.0, "stops"), default=0.0,
                   metavar="STOPS",
                   help="exposure of PNG output in stops (default: 0)")
    p.add_argument("--no-layers", dest="layers", action="store_false",
                   help="write RGB only, without the albedo, normal and variance layers "
                        "(renders a few per cent faster)")
    p.add_argument("--stats", action="store_true",
                   help="also print where the render's time went, stage by stage of the "
                        "path tracer (x86-64 CPUs)")
    _render_options(p, arguments)

    p = subcommand(sub, "validate", validate, "render measured data and its fit side by side",
                   "Render the measured table DATA and the fitted model REPORT (a fit report, "
                   "or a spec) in the same scene with the same seed; write both images (EXR "
                   "and PNG), a false-colour difference, the FLIP error map, comparison.png "
                   "(the four side by side with their colour bars) and metrics.json (RMSE, "
                   "relative MSE, mean FLIP) into OUTDIR.",
                   "print the metrics as JSON")
    p.add_argument("data", metavar="DATA", help=data_help)
    p.add_argument("report", metavar="REPORT", help="a JSON fit report (brdf-fit fit -o) or a "
                                                    "model spec")
    p.add_argument("-o", "--output", required=True, metavar="OUTDIR",
                   help="folder for the images and metrics.json (created if missing)")
    _render_options(p, arguments)


def _scene(name, material):
    from brdf.render import builtin, load
    if name.lower().endswith((".json", ".toml")):
        return load(name, material)
    return builtin(name, material)


def render(args, out):
    """Render a material; write the image (and preview) atomically."""
    from brdf import render as R
    refuse_existing(args, args.output, args.preview)
    png = args.output.lower().endswith(".png")
    scene = _scene(args.scene, load_subject(args.material))
    result = R.render(scene, spp=args.spp, size=args.size,
                      seed=args.seed, max_depth=args.max_depth, strategy=args.strategy,
                      threads=args.threads, stats=args.stats,
                      layers=args.layers and not png)  # a PNG has no layers to write
    if png:
        result.preview(args.output, args.exposure, force=args.force)
    else:
        result.save(args.output, force=args.force)
    if args.preview:
        result.preview(args.preview, args.exposure, force=args.force)
    stats = {"output": args.output, "scene": args.scene, "size": list(args.size),
             "spp": args.spp, "seed": args.seed, "seconds": result.seconds,
             "compile_seconds": result.compile_seconds, "tracer": result.tracer,
             "samples_per_second": result.samples_per_second,
             "mean": [float(x) for x in result.image.mean(axis=(0, 1))]}
    if result.stats is not None:
        stats["stages"] = result.stats.to_dict()
    if args.json:
        out.json(stats)
    else:
        out.text(f"{args.output}: {args.size[0]} x {args.size[1]}, {args.spp} spp, "
                 f"{result.seconds:.2f} s ({result.samples_per_second / 1e6:.2f} M samples/s, "
                 f"traced in {'blocks' if result.tracer == 'blocks' else 'the packet'}), "
                 f"mean RGB {', '.join(f'{x:.4g}' for x in stats['mean'])}")
        if result.stats is not None:
            out.text(result.stats.table())
            if R.traced_in_blocks(scene, args.strategy):
                out.text("(the packet's stages: without --stats this scene is traced in "
                         "blocks, the same image to rounding)")
    return EXIT_OK


def validate(args, out):
    """Measured versus fitted renders and their difference metrics."""
    from brdf.render.validate import validate as run
    from .commands import read_table
    data = read_table(args.data)
    fitted = load_subject(args.report)
    metrics = run(data, fitted, args.output, scene=args.scene, spp=args.spp, size=args.size,
                  seed=args.seed, force=args.force, max_depth=args.max_depth,
                  strategy=args.strategy, threads=args.threads)
    if args.json:
        out.json(metrics)
    else:
        out.table(["metric", "fitted vs measured"],
                  [["RMSE", f"{metrics['rmse']:.4g}"], ["relative MSE", f"{metrics['relmse']:.4g}"],
                   ["FLIP (mean)", f"{metrics['flip']:.4g}"]])
        out.text(f"images and metrics.json in {args.output}")
    return EXIT_OK
