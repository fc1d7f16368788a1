"""Subcommand handlers: each takes the parsed arguments and an :class:`~brdf_cli.output.Output`
and returns the exit status. The library is imported here, when a subcommand runs, never at
start-up."""

EXIT_OK, EXIT_CHECK_FAILED = 0, 1


def load_subject(text):
    """What ``check``, ``eval`` and ``albedo`` work on: the model a spec describes.

    Measured tables will be accepted here too, by dispatching on whether ``text`` names a file.
    """
    import brdf
    return brdf.parse(text)


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
    report = brdf.check(load_subject(args.spec), seed=args.seed)
    if args.json:
        out.json(report.to_dict())
    else:
        out.text(str(report))
    return EXIT_OK if report.passed else EXIT_CHECK_FAILED


def evaluate(args, out):
    """Print f_r(wi, wo) per channel in 1/sr."""
    import numpy as np
    subject = load_subject(args.spec)
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
    subject = load_subject(args.spec)
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
