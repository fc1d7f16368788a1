"""Model comparison: fit several specs to one table and rank them by AIC or BIC."""

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .report import information_criteria

__all__ = ["compare", "Comparison", "CRITERIA"]

CRITERIA = ("aic", "bic")
#: A candidate whose lobe collapsed is refitted from this many times its starts (at least
#: :data:`~brdf.fitting.nlopt_fit.DEFAULT_STARTS` times it), with another seed, before ranking.
REFIT_FACTOR = 4


@dataclass(frozen=True)
class Comparison:
    """Fits of several specs to one table, best first (:func:`compare`).

    Attributes
    ----------
    by : str
        The criterion that orders them, ``"aic"`` or ``"bic"``.
    rows : tuple of dict
        One per spec, best first: spec (the start), fitted (the fitted spec), n, k, loss,
        metrics, likelihood, aic, bic, delta (of the criterion against the best), weight
        (Akaike or Schwarz weight, exp(-delta / 2) normalised: the relative support of each
        model within this set, Burnham & Anderson 2002, sec. 2.9), converged, checks_pass,
        verdict and warnings (of the fit kept), refitted (whether a collapsed lobe sent it
        through the wider refit of :func:`compare`).
    results : tuple of FitResult
        The fits, in the same order.
    """

    by: str
    rows: tuple
    results: tuple

    @property
    def best(self):
        return self.results[0]

    def to_dict(self):
        return {"schema": "brdf.compare/1", "by": self.by, "models": list(self.rows)}

    def __str__(self):
        from ..formatting import format_table
        body = [(str(i + 1), r["spec"], str(r["k"]), f"{r['loss']:.6g}", f"{r['aic']:.2f}",
                 f"{r['bic']:.2f}", f"{r['delta']:.2f}", f"{r['weight']:.3f}",
                 "yes" if r["converged"] else "NO", "pass" if r["checks_pass"] else "FAIL",
                 r["verdict"] if not r["warnings"] else
                 "WARNING: " + ", ".join(sorted({w["kind"] for w in r["warnings"]})))
                for i, r in enumerate(self.rows)]
        head = ("rank", "spec", "k", self.rows[0]["loss_name"], "AIC", "BIC",
                f"d{self.by.upper()}", "weight", "converged", "checks", "verdict")
        notes = (f"n = {self.rows[0]['n']:,} measured values; likelihood: "
                 f"{self.rows[0]['likelihood']}; best first by {self.by.upper()}")
        warned = [f"  {r['spec']}: {w['kind']} {w['parameter']}: {w['detail']}"
                  for r in self.rows for w in r["warnings"]]
        return "\n".join([format_table(head, body, "rlrrrrrrlll"), notes,
                          f"best: {self.rows[0]['fitted']}"]
                         + (["warnings (fits not to be trusted as they stand):"] + warned
                            if warned else []))


def compare(data, specs, *, by="aic", **fit_options):
    """Fit each spec to ``data`` with the same options and rank the fits.

    A fit whose lobe collapsed (a ``collapsed`` warning, :mod:`brdf.fitting.verdicts`) is
    fitted again from :data:`REFIT_FACTOR` times as many starts with the next seed, and the
    lower loss is ranked; a candidate still carrying warnings is marked in the table (its
    ``verdict`` column and the lines under it) and in the JSON rows.

    Parameters
    ----------
    data : Table or path
    specs : sequence of str or Model
        At least two models.
    by : {"aic", "bic"}
        The criterion that orders the table (see
        :func:`brdf.fitting.report.information_criteria` for the likelihood behind both).
    **fit_options
        Passed to :func:`brdf.fit` for every spec (loss, optimizer, starts, cutoff,
        energy_constraint, seed, ...). A name in ``shared`` or ``fix`` applies to the specs
        that have that parameter (``ggx.alpha`` leaves a ``ward`` spec alone); a name that no
        spec has is an error.

    Returns
    -------
    Comparison
    """
    from ..io import as_table
    from ..models._kernels import every_family
    from .nlopt_fit import fit
    if by not in CRITERIA:
        raise InputError(f"unknown criterion {by!r}; criteria: {', '.join(CRITERIA)}")
    specs = list(specs)
    if len(specs) < 2:
        raise InputError(f"compare needs at least two specs, got {len(specs)}")
    table = as_table(data)
    per_spec = _options_per_spec(specs, fit_options)
    results, refitted = [], []
    with every_family():  # one compile for all the specs' families, not one per spec
        for spec, options in zip(specs, per_spec):
            result = fit(table, spec, **options)
            again = _refit_collapsed(table, spec, options, result)
            refitted.append(again is not None)
            results.append(result if again is None or again.loss >= result.loss else again)
    rows = [{**_row(spec, r), "refitted": again}
            for spec, r, again in zip(specs, results, refitted)]
    order = sorted(range(len(rows)), key=lambda i: (rows[i][by], i))
    best = rows[order[0]][by]
    support = np.array([math.exp(-0.5 * (rows[i][by] - best)) for i in order])
    ranked = []
    for i, s in zip(order, support / support.sum()):
        ranked.append({**rows[i], "delta": rows[i][by] - best, "weight": float(s)})
    return Comparison(by, tuple(ranked), tuple(results[i] for i in order))


def _refit_collapsed(table, spec, options, result):
    """A refit of ``spec`` from :data:`REFIT_FACTOR` times the starts (another seed) when a
    lobe of ``result`` collapsed, else None (nor for a global optimizer's single run)."""
    from .nlopt_fit import DEFAULT_STARTS, OPTIMIZERS, fit
    if not any(w["kind"] == "collapsed" for w in result.warnings):
        return None
    if OPTIMIZERS[options.get("optimizer", "LD_LBFGS")][1] == "global":
        return None
    starts = REFIT_FACTOR * max(options.get("starts") or DEFAULT_STARTS, DEFAULT_STARTS)
    return fit(table, spec, **{**options, "starts": starts,
                               "seed": int(options.get("seed", 0)) + 1})


def _options_per_spec(specs, options):
    """The fit options of each spec: ``shared`` and ``fix`` cut down to the names it has.
    Raises InputError for a name that no spec has, listing every spec's parameters."""
    from ..spec import parse
    from .problem import names_apply, parameter_names
    names = [parameter_names(parse(s) if isinstance(s, str) else s) for s in specs]
    shared, fix = list(options.get("shared", ())), dict(options.get("fix", {}) or {})
    for what, given in (("shared", shared), ("fix", list(fix))):
        for name in given:
            if not any(names_apply(name, n) for n in names):
                every = sorted({p for n in names for p in n})
                raise InputError(f"{what}: unknown parameter {name!r} in all of the specs; "
                                 f"parameters: {', '.join(every)} (per-channel ones also as "
                                 "NAME[i])")
    out = []
    for n in names:
        mine = dict(options)
        if "shared" in options:
            mine["shared"] = [s for s in shared if names_apply(s, n)]
        if "fix" in options:
            mine["fix"] = {k: v for k, v in fix.items() if names_apply(k, n)}
        out.append(mine)
    return out


def _row(spec, result):
    ic = information_criteria(result.metrics, result.loss_name, result.data["values_used"],
                              len(result.free))
    return {"spec": str(spec), "fitted": result.spec, "n": ic["n"], "k": ic["k"],
            "loss_name": result.loss_name, "loss": result.loss, "metrics": result.metrics,
            "likelihood": ic["likelihood"], "aic": ic["aic"], "bic": ic["bic"],
            "converged": result.converged,
            "checks_pass": all(c["passed"] is not False for c in result.checks["checks"]),
            "verdict": result.verdict, "warnings": list(result.warnings)}
