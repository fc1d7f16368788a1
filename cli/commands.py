"""Subcommand handlers: each takes the parsed arguments and an :class:`~brdf_cli.output.Output`
and returns the exit status. The library is imported here, when a subcommand runs, never at
start-up."""

EXIT_OK, EXIT_CHECK_FAILED = 0, 1


def load_subject(text, sample=None):
    """What ``check``, ``eval``, ``albedo`` and ``synth`` work on: the fitted model of a JSON
    fit report, a measured table when ``text`` names a file (or has a data file's extension),
    otherwise the model a spec describes. ``sample`` picks one material of a file that holds several (CUReT)."""
    import brdf
    if text.lower().endswith(".json"):
        return brdf.load_report(text).model
    if _names_file(text):
        return read_table(text, sample)
    return brdf.parse(text)


def read_table(path, sample=None):
    """``brdf.read(path)``, passing ``sample`` only when given (formats without several
    materials do not take it)."""
    import inspect
    import brdf
    from brdf.errors import InputError
    if sample is None:
        return brdf.read(path)
    module = brdf.io.format_of(path)
    if "sample" not in inspect.signature(module.read).parameters:
        raise InputError(f"{path}: --sample is for files holding several materials; "
                         f"format {module.FORMAT} holds one")
    return module.read(path, sample=sample)


def _names_file(text):
    import os
    from pathlib import Path
    from brdf.io import formats
    if os.path.exists(text):
        return True
    suffix = Path(text).suffix.lower()
    return bool(suffix) and "(" not in text and any(
        suffix in m.EXTENSIONS for m in formats().values())


def _directions(theta_deg, phi_deg):
    import numpy as np
    from brdf.geometry import spherical_to_cartesian
    return spherical_to_cartesian(np.radians(theta_deg), np.radians(phi_deg))


# --- models ----------------------------------------------------------------------------------

FLAGS = ("reciprocal", "energy_conserving", "delta")


def _describe(cls):
    """JSON-ready description of a registered component class and its parameters."""
    params = []
    for decl in cls.PARAMS:
        d = decl.describe()
        if getattr(decl, "fallback", None):
            d["fallback"] = decl.fallback
        params.append(d)
    # flags that depend on parameter values are properties, not class-level booleans
    flags = {k: getattr(cls, k) for k in FLAGS if isinstance(getattr(cls, k, None), bool)}
    return {"name": cls.name, "aliases": list(cls.aliases), "summary": cls.summary,
            "citation": cls.citation, "properties": flags, "params": params}


def _param_row(d):
    if "choices" in d:
        allowed = "|".join(d["choices"])
    else:
        allowed = f"[{d['bounds'][0]:g}, {d['bounds'][1]:g}]"
    default = d["default"]
    if default is None:
        default = f"(= {d.get('fallback', '')})"
    elif isinstance(default, float):
        default = f"{default:g}"
    per_channel = "yes" if d.get("per_channel") else ""
    return (d["name"], default, allowed, d.get("units", ""), per_channel,
            ", ".join(d["aliases"]), d["doc"])


def _print_component(out, d):
    aliases = f"  (aliases: {', '.join(d['aliases'])})" if d["aliases"] else ""
    out.text(f"{d['name']}{aliases}")
    for line in (d["summary"], d["citation"] and f"citation: {d['citation']}",
                 ", ".join(f"{k.replace('_', '-')}: {'yes' if v else 'no'}"
                           for k, v in d["properties"].items())):
        if line:
            out.text(f"  {line}")
    if d["params"]:
        header = ("parameter", "default", "bounds/choices", "units", "per-channel", "aliases",
                  "description")
        out.table(header, [_param_row(p) for p in d["params"]], indent="  ")
    out.text("")


def models(args, out):
    """List the model families and Fresnel terms with their parameters."""
    from brdf.models import FRESNEL, MODELS
    data = {"models": [_describe(c) for c in MODELS.classes()],
            "fresnel": [_describe(c) for c in FRESNEL.classes()]}
    if args.json:
        out.json(data)
        return EXIT_OK
    out.text("MODELS (add lobes with +, e.g. lambert(albedo=0.5) + ggx(alpha=0.2))\n")
    for d in data["models"]:
        _print_component(out, d)
    out.text("FRESNEL TERMS (the fresnel= parameter, e.g. fresnel=schlick(f0=0.04))\n")
    for d in data["fresnel"]:
        _print_component(out, d)
    return EXIT_OK


# --- check, eval, albedo ---------------------------------------------------------------------

def check(args, out):
    """Run the physical checks; exit 1 when any fails."""
    import brdf
    report = brdf.check(load_subject(args.spec, args.sample), seed=args.seed)
    if args.json:
        out.json(report.to_dict())
    else:
        out.text(str(report))
    return EXIT_OK if report.passed else EXIT_CHECK_FAILED


def evaluate(args, out):
    """Print f_r(wi, wo) per channel in 1/sr."""
    import numpy as np
    subject = load_subject(args.spec, args.sample)
    (ti, pi), (to, po) = args.wi, args.wo
    f = np.asarray(subject.eval(_directions(ti, pi), _directions(to, po)), float).reshape(-1)
    angles = {"theta_i": ti, "phi_i": pi, "theta_o": to, "phi_o": po}
    if args.json:
        out.json({"subject": str(subject), **angles, "units": "1/sr", "f": f})
        return EXIT_OK
    out.text(f"f_r of {subject} at "
             + " ".join(f"{k}={v:g}" for k, v in angles.items()) + " (degrees)")
    out.table(("channel", "f_r [1/sr]"), [(c, f"{v:.9g}") for c, v in enumerate(f)], "rr")
    return EXIT_OK


def albedo(args, out):
    """Print the directional albedo per incidence direction with its quadrature error."""
    import numpy as np
    subject = load_subject(args.spec, args.sample)
    phi, theta = (a.ravel() for a in np.meshgrid(args.phi_i, args.theta_i, indexing="ij"))
    a, err = subject.albedo(_directions(theta, phi), return_error=True)
    a, err = np.asarray(a, float), np.asarray(err, float)
    if args.json:
        rows = [{"theta_i": t, "phi_i": p, "albedo": a[k], "error": err[k]}
                for k, (t, p) in enumerate(zip(theta, phi))]
        out.json({"subject": str(subject), "rows": rows})
        return EXIT_OK
    nch = a.shape[-1]
    names = ["albedo", "error"] if nch == 1 else (
        [f"albedo[{c}]" for c in range(nch)] + [f"error[{c}]" for c in range(nch)])
    rows = [(f"{t:g}", f"{p:g}", *(f"{v:.6f}" for v in a[k]), *(f"{v:.1e}" for v in err[k]))
            for k, (t, p) in enumerate(zip(theta, phi))]
    out.text(f"directional albedo of {subject} (error: quadrature error estimate)")
    out.table(("theta_i", "phi_i", *names), rows, "r" * (2 + len(names)))
    return EXIT_OK


# --- measured tables -------------------------------------------------------------------------

def info(args, out):
    """Describe a measured table: format, channels, coverage, values, provenance."""
    from brdf.table import summary_rows
    summary = read_table(args.file, args.sample).summary()
    if args.json:
        out.json(summary)
        return EXIT_OK
    out.table(("field", "value"), summary_rows(summary))
    return EXIT_OK


def convert(args, out):
    """Read a table (or a model: a spec or fit report) and write it in the format the output's
    extension names (models only to formats that sample them, e.g. .binary and .bsdf)."""
    import brdf
    subject = load_subject(args.input, args.sample)
    path = brdf.write(subject, args.output, force=args.force)
    if not isinstance(subject, brdf.Table):
        if args.json:
            out.json({"input": args.input, "output": str(path), "model": str(subject)})
        else:
            out.text(f"wrote {path} (model {subject})")
        return EXIT_OK
    if args.json:
        out.json({"input": args.input, "output": str(path), "samples": len(subject)})
    else:
        out.text(f"wrote {path} ({len(subject):,} samples x {subject.channels} channels)")
    return EXIT_OK


def synth(args, out):
    """Sample a model (or resample a table) with the virtual gonioreflectometer and write it."""
    import brdf
    table = brdf.measure(load_subject(args.spec, args.sample), args.geometry, args.noise, args.seed)
    path = brdf.write(table, args.output, force=args.force)
    if args.json:
        out.json({"output": str(path), "samples": len(table), "geometry": args.geometry,
                  "noise": args.noise, "seed": args.seed})
    else:
        out.text(f"wrote {path}: {len(table):,} samples of {args.spec} at {args.geometry}, "
                 f"noise {args.noise}, seed {args.seed}")
    return EXIT_OK


# --- fitting -----------------------------------------------------------------------------------

def _assignments(items):
    """``{name: value}`` from ``NAME=VALUE`` strings (``--fix``)."""
    import math
    from brdf.errors import InputError
    from .arguments import parse_float
    out = {}
    for item in items:
        name, _, value = (part.strip() for part in item.partition("="))
        try:
            number = parse_float(value)
        except ValueError:
            number = math.nan
        if not name or not math.isfinite(number):
            raise InputError(f"--fix expects NAME=VALUE with a finite number, got {item!r}")
        out[name] = number
    return out


#: The public name of :func:`_assignments`, for the subcommands in their own modules.
assignments = _assignments


def emit_report(document, result, args, out):
    """Write ``document`` to ``-o`` atomically (replacing a file only with ``--force``) and
    print it: the JSON with ``--json``, else ``str(result)``."""
    if args.output:
        from brdf.fitting.report import save_report
        save_report(document, args.output, args.force)
    if args.json:
        out.json(document)
    else:
        out.text(str(result))


def refuse_existing(args, *paths):
    """OutputError before any work if an output file exists and --force is not given."""
    from pathlib import Path
    from brdf.errors import OutputError
    for path in paths:
        if path and Path(path).exists() and not args.force:
            raise OutputError(f"{path}: exists; pass --force to replace it")


def fit(args, out):
    """Fit a spec to a table (and sample its posterior with --mcmc); write the JSON report
    atomically; exit 1 unless converged."""
    import brdf
    from brdf.errors import InputError
    from brdf.fitting.report import save_report
    from .arguments import chain_options
    from .export import export_path, report as export_report
    target = export_path(args)
    refuse_existing(args, args.output, args.chain, args.corner, target)
    if target:  # a model without an equivalent is refused before the fit, not after
        from brdf.io.export import check_families
        check_families(args.spec, args.export)
    if not args.mcmc and (args.walkers or args.chain or args.corner or args.moves):
        raise InputError("--walkers, --moves, --chain and --corner need --mcmc")
    table = read_table(args.data)
    result = brdf.fit(table, args.spec, loss=args.loss, optimizer=args.optimizer,
                      starts=args.starts, energy_constraint=args.energy_constraint,
                      cutoff=args.cutoff, shared=args.shared, fix=_assignments(args.fix),
                      seed=args.seed, max_evals=args.max_evals)
    report = result.to_dict()
    post = None
    if args.mcmc:
        post = brdf.mcmc(table, result, seed=args.seed, chain=args.chain, force=args.force,
                         **chain_options(args))
        timing = report.pop("timing")
        report["posterior"] = post.to_dict()
        report["timing"] = {**timing, "mcmc_s": post.seconds}
        if args.corner:
            post.corner(args.corner, force=args.force)
    if args.output:
        save_report(report, args.output, args.force)
    if args.json:
        exported = target and brdf.export(result, args.export, target, force=args.force)
        out.json(report if not exported else {**report, "export": exported.to_dict()})
    else:
        # the fit first: an export that is refused must not hide what was fitted
        out.text(str(result) + ("" if post is None else "\n" + str(post)))
        if target:
            export_report(brdf.export(result, args.export, target, force=args.force), out,
                          False)
    if post is not None and not post.converged:
        return EXIT_CHECK_FAILED
    failed = not result.converged or (args.energy_constraint and not result.energy["holds"])
    return EXIT_CHECK_FAILED if failed else EXIT_OK


def compare(args, out):
    """Fit several specs to one table and print them ranked; exit 1 if a fit did not
    converge."""
    import brdf
    refuse_existing(args, args.output)
    result = brdf.compare(read_table(args.data), args.specs, by=args.by, loss=args.loss,
                          optimizer=args.optimizer, starts=args.starts,
                          energy_constraint=args.energy_constraint, cutoff=args.cutoff,
                          shared=args.shared, fix=_assignments(args.fix), seed=args.seed,
                          max_evals=args.max_evals)
    emit_report(result.to_dict(), result, args, out)
    return EXIT_OK if all(r["converged"] for r in result.rows) else EXIT_CHECK_FAILED


def batch(args, out):
    """Fit one spec to many files; exit 1 if any failed or did not converge."""
    import brdf
    result = brdf.batch(args.inputs, args.spec, args.output, jobs=args.jobs,
                        scheduler=args.scheduler, force=args.force, loss=args.loss,
                        optimizer=args.optimizer, starts=args.starts,
                        energy_constraint=args.energy_constraint, cutoff=args.cutoff,
                        shared=args.shared, fix=_assignments(args.fix), seed=args.seed,
                        max_evals=args.max_evals)
    if args.json:
        out.json(result.to_dict())
    else:
        out.text(str(result))
    return EXIT_OK if result.ok else EXIT_CHECK_FAILED
