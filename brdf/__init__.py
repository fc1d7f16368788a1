"""brdf: measure, check, fit and render bidirectional reflectance distribution functions.

>>> import brdf
>>> m = brdf.parse("lambert(albedo=0.8) + ggx(alpha=0.2)")
>>> report = brdf.check(m)
"""

__version__ = "0.1.0"

from . import _numba_import  # noqa: E402,F401  (first: see there)
from . import geometry, io, models, radiometry  # noqa: E402
from .errors import (BRDFError, FormatError, InputError, MainGuardError, OutputError,  # noqa: E402
                     ParameterError, SpecError)
from .io import read, write  # noqa: E402
from .table import Table  # noqa: E402
from .spec import from_dict, from_json, parse  # noqa: E402
from .models.custom import CustomModel, register_model, unregister_model  # noqa: E402

__all__ = ["__version__", "parse", "from_dict", "from_json", "check", "read", "write",
           "measure", "fit", "fit_images", "mcmc", "compare", "export", "batch", "load_report",
           "CustomModel", "register_model", "unregister_model", "Table", "models", "geometry",
           "radiometry", "io",
           "BRDFError", "SpecError", "ParameterError", "InputError", "FormatError", "OutputError",
           "MainGuardError"]


def check(obj, **options):
    """Physical checks of a model or spec (non-negativity, reciprocity, energy); see
    :func:`brdf.properties.check`."""
    from .properties import check as _check
    return _check(obj, **options)


def measure(model, geometry="inplane:5", noise="none", seed=0, **options):
    """Virtual gonioreflectometer: sample ``model`` at ``geometry`` with ``noise``; see
    :func:`brdf.gonioreflectometer.measure`."""
    from .gonioreflectometer import measure as _measure
    return _measure(model, geometry, noise, seed, **options)


def fit(data, spec, **options):
    """Fit a model spec to measured data with nlopt; see :func:`brdf.fitting.fit`."""
    from .fitting import fit as _fit
    return _fit(data, spec, **options)


def fit_images(spec, views, **options):
    """Fit a model spec to photographs of known scenes (inverse illumination); see
    :func:`brdf.capture.fit_images`."""
    from .capture import fit_images as _fit_images
    return _fit_images(spec, views, **options)


def mcmc(data, start, **options):
    """Posterior of a model's parameters with emcee; see :func:`brdf.fitting.mcmc`."""
    from .fitting import mcmc as _mcmc
    return _mcmc(data, start, **options)


def compare(data, specs, **options):
    """Fit several specs to one table and rank them by AIC or BIC; see
    :func:`brdf.fitting.compare`."""
    from .fitting import compare as _compare
    return _compare(data, specs, **options)


def export(model, format, path=None, force=False, max_error=None, measured=False):
    """Write a model or fit (result, report, or report path) as a Mitsuba 3 BSDF or a glTF 2.0
    material, stating what is exact and what approximate (a model the format has no
    counterpart for becomes the closest material of its family); see `brdf.io.export`."""
    from .io.export import export as _export
    return _export(model, format, path, force, max_error, measured)


def load_report(path):
    """A saved JSON fit report back, with ``.model`` the fitted model; see
    :func:`brdf.fitting.load_report`."""
    from .fitting import load_report as _load_report
    return _load_report(path)


def batch(inputs, spec, outdir, **options):
    """Fit one spec to many files (local processes or a Dask cluster), resumable; see
    :func:`brdf.fitting.batch`."""
    from .fitting import batch as _batch
    return _batch(inputs, spec, outdir, **options)
