"""Fitting BRDF models to measured tables.

:func:`fit` (exported as ``brdf.fit``) finds point estimates with nlopt; :mod:`.losses` holds
the error metrics, weights and cutoff; :mod:`.problem` maps parameter vectors to models and
losses; :func:`mcmc` (exported as ``brdf.mcmc``) samples posteriors with emcee;
:func:`compare` ranks several fitted specs by AIC or BIC; :mod:`.report` documents the JSON fit
report and loads it back (:func:`load_report`); :func:`batch` fits many files, locally or on Dask.
"""

from .batch import BatchResult, batch
from .compare import Comparison, compare
from .losses import LOSSES
from .mcmc import Posterior, mcmc
from .nlopt_fit import OPTIMIZERS, FitResult, fit
from .problem import Problem
from .report import FitReport, load_report

__all__ = ["fit", "FitResult", "mcmc", "Posterior", "compare", "Comparison", "batch", "BatchResult", "load_report", "FitReport", "Problem", "LOSSES", "OPTIMIZERS"]
