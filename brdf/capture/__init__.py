"""BRDFs from photographs: inverse illumination of known scenes.

:func:`fit_images` (exported as ``brdf.fit_images``) fits a model spec to one or more views, each
a scene file (:func:`brdf.render.load`'s format, the unknown BRDF on the shapes whose material
is ``"@material"``) and a photograph of it, and returns a fit whose report carries a
``capture`` section. Modules: :mod:`.views` (reading and checking views, masks and images),
:mod:`.responses` (inverse camera responses), :mod:`.direct` (the ``direct`` method: pixels to
samples under the direct light), :mod:`.inverse` (the fit and its result).
"""

from .inverse import METHODS, ImageFitResult, fit_images
from .responses import RESPONSES, Response, response
from .views import MATERIAL_MARK, Photo, View, read_photo, read_view

__all__ = ["fit_images", "ImageFitResult", "METHODS", "read_view", "read_photo", "View", "Photo",
           "Response", "response", "RESPONSES", "MATERIAL_MARK"]
