"""brdf: measure, check, fit and render bidirectional reflectance distribution functions.

>>> import brdf
>>> m = brdf.parse("lambert(albedo=0.8) + ggx(alpha=0.2)")
>>> report = brdf.check(m)
"""

__version__ = "0.1.0"

from . import geometry, models, radiometry  # noqa: E402
from .errors import BRDFError, FormatError, InputError, ParameterError, SpecError  # noqa: E402
from .spec import from_dict, from_json, parse  # noqa: E402

__all__ = ["__version__", "parse", "from_dict", "from_json", "check", "models", "geometry",
           "radiometry",
           "BRDFError", "SpecError", "ParameterError", "InputError", "FormatError"]


def check(obj, **options):
    """Physical checks of a model or spec (non-negativity, reciprocity, energy); see
    :func:`brdf.properties.check`."""
    from .properties import check as _check
    return _check(obj, **options)
