"""Parametric BRDF models: one module per family, all registered by name.

``MODELS`` maps spec names to classes (``brdf-fit models`` lists them); models add with ``+``.
The built-in compiled families are listed in ``_kinds.FAMILIES``.
"""

from importlib import import_module

from . import _kinds, fresnel  # noqa: F401  (registration)
from ._registry import FRESNEL, MODELS, register
from .base import Choice, Compiled, Component, Model, Nested, Param, Sum
from .fresnel import Conductor, Dielectric, NoFresnel, Schlick
from .lambert import Lambert
from .microfacet import BeckmannModel as Beckmann
from .microfacet import GGXModel as GGX
from .mirror import Mirror
from .blinn_phong import BlinnPhong
from .phong import ModifiedPhong, Phong
from .ward import Ward
from .ashikhmin_shirley import AshikhminShirley
from .lafortune import Lafortune
from .custom import CustomModel, load_plugin, register_model, unregister_model

for _module in _kinds.MODULES:  # every built-in family registers its classes on import
    import_module(f".{_module}", __name__)

__all__ = ["MODELS", "FRESNEL", "register", "Param", "Choice", "Nested", "Component", "Model",
           "Sum", "Compiled", "Lambert", "Mirror", "GGX", "Beckmann", "NoFresnel", "Schlick",
           "Dielectric", "Conductor"]
__all__ += ["Phong", "ModifiedPhong", "BlinnPhong"]
__all__ += ["Ward"]
__all__ += ["Lafortune", "AshikhminShirley"]
__all__ += ["CustomModel", "register_model", "unregister_model", "load_plugin"]
