"""``brdf-fit demo``: the main job end to end (:mod:`brdf.demo`)."""

from . import arguments
from .commands import EXIT_OK


def add_parser(sub, subcommand):
    p = subcommand(sub, "demo", demo, "run the whole pipeline on bundled real data",
                   "On the bundled RGL white paper and a MERL-size synthetic table made on the "
                   "fly: info, physical checks, energy-constrained nlopt fits of lambert, "
                   "lambert + ggx and lambert + beckmann, comparison by BIC, an emcee "
                   "posterior of the best fit, validation renders (measured against fitted, "
                   "difference, FLIP), 3-D lobes and 2-D plots, all gathered in OUTDIR with a "
                   "self-contained report.html.",
                   "print the summary as JSON")
    p.add_argument("-o", "--output", default="results", metavar="OUTDIR",
                   help="folder for the reports, images and report.html (default: results)")
    p.add_argument("--seed", type=arguments.seed, default=0, help="seed (default: 0)")
    p.add_argument("--quick", action="store_true",
                   help="small renders and short chains (a smoke run)")
    p.add_argument("--force", action="store_true", help="write into a non-empty OUTDIR")


def demo(args, out):
    from brdf.demo import run
    summary = run(args.output, seed=args.seed, force=args.force, quick=args.quick)
    if args.json:
        out.json(summary)
    else:
        from brdf.formatting import round_numbers, significant
        rows = [[name, round_numbers(e["best"]),
                 significant(e["image_metrics"].get("flip", float("nan")))]
                for name, e in summary["datasets"].items()]
        out.table(["data", "best model (BIC)", "render FLIP"], rows)
        out.text(f"{summary['seconds']:.0f} s; open {args.output}/report.html")
    return EXIT_OK
