"""Fitting BRDF models to measured tables.

:func:`fit` (exported as ``brdf.fit``) finds point estimates with nlopt; :mod:`.losses` holds
the error metrics, weights and cutoff; :mod:`.problem` maps parameter vectors to models and
losses; :func:`mcmc` (exported as ``brdf.mcmc``) samples posteriors with emcee.
"""

from .losses import LOSSES
from .mcmc import Posterior, mcmc
from .nlopt_fit import OPTIMIZERS, FitResult, fit
from .problem import Problem

__all__ = ["fit", "FitResult", "mcmc", "Posterior", "Problem", "LOSSES", "OPTIMIZERS"]
