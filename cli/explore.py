"""``brdf-fit explore``: the interactive explorer (:mod:`brdf.viz.explorer`) served on
localhost until interrupted. Registered from :mod:`brdf_cli.main` by :func:`add_parser`."""

from . import arguments
from .commands import EXIT_OK, load_subject

MATERIAL_HELP = ("model specs, JSON fit reports (brdf-fit fit -o) or measured table files, "
                 "each shown in its own colour; more can be added in the page")


def add_parser(sub, subcommand):
    """Register ``explore`` with ``subcommand`` (cli.main's helper for common options)."""
    p = subcommand(sub, "explore", run, "the interactive BRDF explorer in the browser",
                   "Serve a local web page with sliders for every parameter of every material "
                   "(from the families' declarations) and linked views that follow them live: "
                   "the 3-D lobe, the in-plane polar plot, the directional albedo with the "
                   "limit 1 and a lit sphere, at an incident direction set by sliders. "
                   "Materials typed into the page are added. Runs until interrupted (Ctrl-C). "
                   'Needs the optional extra: pip install "brdf[explore]".',
                   "print the page's address as JSON")
    p.add_argument("materials", metavar="MATERIAL", nargs="*", help=MATERIAL_HELP)
    p.add_argument("--port", type=arguments.integer(1, 65535, "a TCP port"), default=None,
                   metavar="N", help="serve on localhost:N (default: a free port)")
    p.add_argument("--environment", metavar="FILE.exr", default=None,
                   help="light the previews with this environment map (lat-long OpenEXR, "
                        "Mitsuba 3's envmap layout, as brdf-fit render reads it); another "
                        "can be uploaded in the page")
    p.add_argument("--no-browser", action="store_true",
                   help="do not open the page in a browser; print its address only")


def run(args, out):
    """Load the materials (bad input is refused before anything is served), serve the page and
    wait; Ctrl-C stops it with exit status 0."""
    import time
    from brdf.viz.explorer import explore, require_panel
    require_panel()
    materials = [load_subject(text) for text in args.materials]
    # a bad map is refused (exit 2) before anything is served
    server = explore(*materials, port=args.port, show=not args.no_browser,
                     environment=args.environment)
    if args.json:
        out.json({"url": server.url, "port": server.port})
    else:
        out.text(f"serving the explorer at {server.url} (Ctrl-C stops it)")
    out.stream.flush()
    try:
        while True:
            time.sleep(0.5)
    except KeyboardInterrupt as exc:
        server.stop()
        if type(exc) is not KeyboardInterrupt:  # SIGTERM or SIGHUP: brdf_cli.main says so
            raise
    return EXIT_OK
