"""The JSON fit report: its versioned schema, loading it back, and information criteria.

Schema ``brdf.fit/1`` (written by :meth:`FitResult.to_dict`, ``brdf-fit fit -o``): one JSON
object, UTF-8, keys in this order; angles in degrees, BRDF values in 1/sr, times in seconds.

=================  ==========================================================================
key                value
=================  ==========================================================================
``schema``         ``"brdf.fit/1"``; readers refuse other major versions
``spec``           the fitted model as a spec string (``brdf.parse`` reads it back)
``model``          the fitted model as a JSON object (``brdf.from_dict``): the source of truth
``params``         ``{"lobe.param" or "lobe.param[c]": number}``, every numeric parameter
``free``           names of the fitted parameters
``fixed``          ``{name: value}`` of the parameters held fixed
``bounds``         ``{free name: [lower, upper]}`` of the fit
``loss``           ``{"name": metric, "value": number}``: what was minimised
``metrics``        ``{metric: value}`` for every metric the data allow (chi-square needs sigma)
``status``         nlopt's return code name for the final run
``converged``      true when that run ended on a tolerance (not its budget or a failure)
``evaluations``    objective evaluations over all runs
``runs``           one object per start or stage: run, optimizer, status, loss, evaluations,
                   feasible; local runs also start and end (``{free name: value}``) and
                   samples (scored on the start subsample or on all samples)
``data``           samples_total, samples_used, values_used, channels, cutoff_deg, weighting
``energy``         constrained, holds, worst_albedo, theta_i, phi_i, channel, tolerance
``checks``         ``brdf.check`` of the fitted model (non-negativity, reciprocity, energy)
``provenance``     input {name, path, sha256, format, size}, spec (the start), seed, options,
                   library versions
``warnings``       list of ``{"parameter", "kind", "detail"}``, kind ``at-bound``,
                   ``collapsed``, ``undetermined`` or ``multimodal``
                   (:mod:`brdf.fitting.verdicts`); absent in reports written before it
``verdict``        ``"ok"`` (no warnings) or ``"warning"``; ``converged`` stays the
                   optimiser's status
``posterior``      present with ``--mcmc``: :meth:`brdf.fitting.mcmc.Posterior.to_dict`
``timing``         wall times (total_s, prepare_s, optimize_s, finish_s, mcmc_s): always
                   last, the one part that changes between runs with the same seed
=================  ==========================================================================

A report loads back with :func:`load_report`; its ``.model`` renders, plots and evaluates like
any model, and the command line takes a report file wherever it takes a MATERIAL.
"""

import math
import os
from dataclasses import dataclass

from ..errors import FormatError, InputError

__all__ = ["SCHEMA", "FitReport", "load_report", "save_report", "information_criteria"]

SCHEMA = "brdf.fit/1"
_REQUIRED = ("spec", "model", "params", "loss", "metrics", "converged", "data", "provenance")


@dataclass(frozen=True)
class FitReport:
    """A fit report read back (:func:`load_report`).

    Attributes
    ----------
    path : str
    model : Model
        The fitted model.
    document : dict
        The whole report as read.
    """

    path: str
    model: object
    document: dict

    def __getattr__(self, key):
        # the report's keys as attributes: report.params, report.metrics, report.posterior...
        document = self.__dict__.get("document", {})
        if key in document:
            return document[key]
        raise AttributeError(key)

    @property
    def spec(self):
        return str(self.model)

    @property
    def warnings(self):
        """The report's warnings (an empty list for reports written before they existed)."""
        return self.document.get("warnings", [])

    @property
    def verdict(self):
        """``"ok"``, ``"warning"``, or None for a report written before verdicts existed."""
        return self.document.get("verdict")


def load_report(path):
    """Read a JSON fit report (schema :data:`SCHEMA`) back; ``.model`` is the fitted model.

    Raises FormatError naming the file and the place for a folder or a file that cannot be
    read, bytes that are not UTF-8, text that is not JSON or nests too deeply, another schema,
    a missing key or a model description that does not parse.
    """
    from ..errors import BRDFError
    from ..io.files import read_json
    from ..spec import from_dict
    if not isinstance(path, (str, os.PathLike)) or not os.fspath(path):
        raise InputError(f"load_report: path must be a non-empty file path, got {path!r}")
    path = os.fspath(path)
    # a regular file, UTF-8, at most 64 MB, nested at most 100 levels (brdf.io.files)
    document = read_json(path, 64 << 20, "a JSON fit report")
    if not isinstance(document, dict) or "schema" not in document:
        raise FormatError(path, "", f"a JSON object with \"schema\": \"{SCHEMA}\" (a fit report "
                                    "written by brdf-fit fit -o)")
    schema = document["schema"]
    name, _, version = str(schema).partition("/")
    if (name, version.split(".")[0]) != tuple(SCHEMA.split("/")):  # 1.x reads as 1
        raise FormatError(path, "key schema", f"{SCHEMA!r}, got {schema!r}")
    missing = [k for k in _REQUIRED if k not in document]
    if missing:
        raise FormatError(path, f"key {missing[0]}", f"the fit report's keys "
                                                     f"{', '.join(_REQUIRED)}; it is missing")
    try:
        model = from_dict(document["model"])
    except BRDFError as exc:
        raise FormatError(path, "key model", f"a model description ({exc})") from None
    return FitReport(path, model, document)


def save_report(document, path, force=False):
    """Write a report ``document`` (a JSON-ready dict, e.g. :meth:`FitResult.to_dict`) to
    ``path`` as indented JSON, atomically; an existing file is replaced only with ``force``
    (otherwise :class:`~brdf.errors.OutputError`). Non-finite numbers are refused, so every
    JSON reader takes the file."""
    import json
    from ..io import atomic_output
    text = json.dumps(document, indent=2, allow_nan=False) + "\n"
    with atomic_output(path, force) as tmp:
        tmp.write_text(text, encoding="utf-8")


def information_criteria(metrics, loss_name, values, free):
    """Akaike and Bayesian information criteria of a fit, from its metrics.

    The likelihood is the one :func:`brdf.mcmc` samples: with per-sample sigma (the metrics
    hold ``chi-square``) -2 log L = chi^2 + const, so AIC = chi^2 + 2k and BIC = chi^2 + k ln n
    (Burnham & Anderson 2002, eq. 2.1; Schwarz 1978); otherwise Gaussian residuals of the loss
    with the noise variance at its maximum-likelihood value, -2 log L = n ln L + const (L the
    loss: the weighted mean squared residual), which adds the variance to the k parameters.

    Parameters
    ----------
    metrics : dict
        A fit's metrics (``FitResult.metrics`` or a report's ``metrics``).
    loss_name : str
        The metric the fit minimised.
    values : int
        Measured values the fit used (n).
    free : int
        Free parameters of the model (k).

    Returns
    -------
    dict
        ``{"n", "k", "likelihood", "minus_2_log_likelihood", "aic", "bic"}``.
    """
    n, k = int(values), int(free)
    if "chi-square" in metrics:
        m2ll, likelihood = metrics["chi-square"] * (n - k), "stated sigma (chi-square)"
    else:
        loss = max(metrics[loss_name], math.ulp(0.0))
        m2ll, likelihood = n * math.log(loss), f"Gaussian on {loss_name} residuals, ML variance"
        k += 1
    return {"n": n, "k": k, "likelihood": likelihood, "minus_2_log_likelihood": m2ll,
            "aic": m2ll + 2 * k, "bic": m2ll + k * math.log(n)}
