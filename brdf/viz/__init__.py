"""Pictures of BRDFs: 3-D lobes (:mod:`brdf.viz.lobes`, pyvista), the 2-D plots analysts
expect (:mod:`brdf.viz.plots`, matplotlib) and the interactive explorer in the browser
(:func:`explore`, :mod:`brdf.viz.explorer`; the optional extra ``brdf[explore]``).

Every function takes a model (``brdf.parse``, ``brdf.load_report(...).model``) or a measured
table (``brdf.read``) and evaluates it through its own ``eval`` / ``albedo``. pyvista and
matplotlib are imported only when a picture is made, so ``import brdf.viz`` stays cheap.

>>> import brdf
>>> from brdf import viz
>>> fig = viz.albedo_plot(brdf.parse("lambert(albedo=0.8) + ggx(alpha=0.2)"))
"""

from .explorer import explore
from .lobes import lobe_plotter, lobe_surface, plot_lobes
from .plots import (albedo_plot, corner_plot, inplane_plot, predictive_plot, residual_plot,
                    save_figure, slice_plot, validation_figure)

__all__ = ["explore", "plot_lobes", "lobe_plotter", "lobe_surface", "inplane_plot", "slice_plot",
           "albedo_plot", "residual_plot", "corner_plot", "predictive_plot",
           "validation_figure", "save_figure"]
