"""Posteriors of model parameters with emcee (Foreman-Mackey et al. 2013, PASP 125, 306).

The log-posterior over the fitter's vector x (:class:`~brdf.fitting.problem.Problem`) is

- the prior: uniform over the fitting box of x. x holds the logarithm of parameters declared
  with a log prior, so those get a log-uniform prior on their value and the others a uniform
  one, as declared; no Jacobian is needed because the density is stated in x;
- plus a Gaussian likelihood. When the table states per-sample sigma, the residuals are
  standardised by it, log L = -chi^2 / 2, whatever loss the point estimate used (the stated
  noise is the better model, above all a relative one, whose sigma follows the lobe).
  Otherwise the likelihood is that of the loss's residuals r_kc (:mod:`brdf.fitting.losses`;
  linear or in log space, as the loss is) with a noise scale s fitted with the model (named
  :data:`NOISE`, log-uniform prior): r_kc ~ N(0, s^2 / w_k) with the sample weights w_k
  normalised to mean 1 over the n measured values, so that
  log L = -n log s - n L(x) / (2 s^2) + const, L being the loss. Uniform weights give the plain
  likelihood; MERL's solid-angle weights make samples that stand for more of the domain more
  precise without changing the total information (n values).

Walkers start in a small ball around the nlopt optimum and move by differential evolution by
default (:data:`MOVES`): on these near-Gaussian posteriors its autocorrelation time is a third
of the stretch move's (8 parameters of lambert + beckmann on RGL's paper: 28 steps against 90),
so the chain converges in a third of the steps. The chain grows in chunks until it is
longer than :data:`TAU_MULTIPLE` integrated autocorrelation times (emcee's estimator, Goodman &
Weare 2010; Sokal 1997) and that estimate changed by less than 5 % since the last chunk, or
until ``max_steps``. Burn-in is twice the largest tau and thinning half the smallest.
"""

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .. import arguments
from .._threads import serial_below
from ..errors import InputError
from ..progress import task

__all__ = ["mcmc", "Posterior", "LogPosterior", "NOISE", "TAU_MULTIPLE", "PERCENTILES", "MOVES"]

#: Name of the fitted noise scale (in the loss's residual units) in posterior summaries.
NOISE = "noise.sigma"
#: The chain must be longer than this many autocorrelation times (Foreman-Mackey et al. 2013
#: advise 50 or more for a reliable tau).
TAU_MULTIPLE = 50
#: Relative change of tau between checks (the chain grows by a tenth) below which its estimate
#: counts as settled: early estimates from short chains run low.
TAU_STABLE = 0.05
#: Percentiles reported: 95 % and 68 % central intervals around the median.
PERCENTILES = (2.5, 16.0, 50.0, 84.0, 97.5)
DEFAULT_MAX_STEPS = 20000
#: Steps before the first convergence check; later checks come every tenth of the chain so far.
FIRST_CHECK = 200
#: Fewest walkers that differential-evolution moves can work with.
DE_WALKERS = 4
#: Width of the starting ball, as a fraction of each coordinate's box.
BALL = 1e-3
#: The noise scale's prior box: this factor either side of its maximum-likelihood value at the
#: optimum (wide enough to hold any plausible posterior mass, finite so the prior is proper).
NOISE_RANGE = 1e4


def _de_moves():
    import emcee
    # differential evolution (ter Braak 2006, Stat. Comput. 16, 239; emcee's DEMove after Nelson
    # et al. 2014, ApJS 210, 11) mixed with its snooker update (ter Braak & Vrugt 2008, Stat.
    # Comput. 18, 435), in the proportions emcee's documentation uses
    return [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]


def _stretch_moves():
    import emcee
    # Goodman & Weare 2010 (Comm. App. Math. Comp. Sci. 5, 65), eq. 7, a = 2: emcee's default
    return [(emcee.moves.StretchMove(), 1.0)]


#: Proposal moves by name (``mcmc(moves=...)``, ``--moves``): a builder and a description.
MOVES = {
    "de": (_de_moves, "differential evolution (0.8) and its snooker update (0.2)"),
    "stretch": (_stretch_moves, "affine-invariant stretch move"),
}


class LogPosterior:
    """Vectorised log-posterior of a :class:`Problem`: rows of ``X`` (walkers, dim) -> (walkers,).

    The last coordinate is log s (the noise scale) unless the table states sigma.
    """

    def __init__(self, problem, x_opt):
        from . import losses
        self.problem = problem
        samples = problem.samples
        self.known_sigma = samples.sigma is not None and bool(np.isfinite(samples.sigma).any())
        if self.known_sigma:
            self.terms = terms = losses.terms("chi-square", samples, len(problem.free))
            self.n = int((samples.measured & np.isfinite(samples.sigma)).sum())
        else:
            self.terms = terms = problem.terms
            self.n = int(samples.measured.sum())
        self.norm = terms.norm
        lower, upper = problem.lower, problem.upper
        if not self.known_sigma:
            rms = math.sqrt(max(float(problem.channel_losses(x_opt, terms)[0].sum()), 0.0))
            floor = 1e-12 * max(float(np.sqrt(np.mean(terms.target ** 2))), 1e-300)
            s_hat = max(rms, floor)
            lower = np.append(lower, math.log(s_hat / NOISE_RANGE))
            upper = np.append(upper, math.log(s_hat * NOISE_RANGE))
            self.s_hat = s_hat
        self.lower, self.upper = lower, upper
        self.names = problem.names + (() if self.known_sigma else (NOISE,))

    @property
    def dim(self):
        return len(self.lower)

    def __call__(self, X):
        X = np.atleast_2d(X)
        out = np.full(len(X), -np.inf)
        inside = np.all((X >= self.lower) & (X <= self.upper), axis=1)
        if not inside.any():
            return out
        Xi = X[inside]
        m = len(self.problem.names)
        with serial_below(len(Xi) * len(self.problem.samples.wi)):
            loss = self.problem.channel_losses(Xi[:, :m], self.terms).sum(axis=1)
        if self.known_sigma:
            out[inside] = -0.5 * loss * self.norm                  # chi^2 = loss x (n - k)
        else:
            log_s = Xi[:, m]
            out[inside] = -self.n * log_s - 0.5 * self.n * loss * np.exp(-2.0 * log_s)
        return out

    def natural(self, X):
        """Rows of x as parameter values (logarithms undone; the noise scale as s)."""
        X = np.atleast_2d(X)
        out = np.empty_like(X)
        for i, p in enumerate(self.problem.free):
            out[:, i] = p.from_x(X[:, i])
        if not self.known_sigma:
            out[:, -1] = np.exp(X[:, -1])
        return out

    def start(self, x_opt, walkers, rng):
        """``walkers`` points in a ball around the optimum (and s at its ML value), inside the
        box: a coordinate at a bound starts just inside it."""
        centre = np.asarray(x_opt, dtype=float)
        if not self.known_sigma:
            centre = np.append(centre, math.log(self.s_hat))
        width = self.upper - self.lower
        p0 = centre + BALL * width * rng.standard_normal((walkers, self.dim))
        margin = 1e-6 * width
        return np.clip(p0, self.lower + margin, self.upper - margin)


@dataclass
class Posterior:
    """Posterior summary from :func:`mcmc`.

    Attributes
    ----------
    names : tuple of str
        Flat parameter names (and :data:`NOISE` when the noise scale was fitted).
    samples : ndarray, shape (S, D)
        Posterior draws in natural units, after burn-in and thinning.
    percentiles : dict
        ``{name: {"2.5": v, "16": v, "50": v, "84": v, "97.5": v}}``.
    correlation : ndarray, shape (D, D)
    tau : ndarray, shape (D,)
        Integrated autocorrelation times in steps.
    acceptance : float
        Mean acceptance fraction of the walkers.
    converged : bool
    verdict : str
        Why the chain counts as converged, or why not.
    walkers, steps, burn, thin : int
    moves : str
        The proposal moves the walkers made.
    optimum : dict
        The nlopt point estimate the walkers started around.
    fit : FitResult
    chain : str or None
        Where the full chain was saved.
    seconds : float
    """

    names: tuple
    samples: np.ndarray
    percentiles: dict
    correlation: np.ndarray
    tau: np.ndarray
    acceptance: float
    converged: bool
    verdict: str
    walkers: int
    steps: int
    burn: int
    thin: int
    optimum: dict
    fit: object = field(repr=False)
    log_posterior: object = field(repr=False)
    draws_x: np.ndarray = field(repr=False)
    chain: object = None
    seconds: float = 0.0
    moves: str = MOVES["de"][1]

    @property
    def median(self):
        return {n: p["50"] for n, p in self.percentiles.items()}

    def interval(self, name, level=95):
        """Central credible interval ``(lower, upper)`` of ``name`` at 68 or 95 percent."""
        lo, hi = {68: ("16", "84"), 95: ("2.5", "97.5")}[level]
        return self.percentiles[name][lo], self.percentiles[name][hi]

    def to_dict(self):
        """JSON-ready summary (no timing: it goes beside the report's other timings)."""
        return {
            "sampler": f"emcee ensemble: {self.moves}",
            "parameters": list(self.names), "percentiles": self.percentiles,
            "correlation": self.correlation.tolist(),
            "tau_steps": self.tau.tolist(), "acceptance_fraction": self.acceptance,
            "converged": self.converged, "verdict": self.verdict, "walkers": self.walkers,
            "steps": self.steps, "burn_in": self.burn, "thin": self.thin,
            "draws": len(self.samples), "optimum": self.optimum, "chain": self.chain,
        }

    def __str__(self):
        from ..formatting import format_table
        rows = [(n, f"{self.optimum.get(n, float('nan')):.6g}",
                 *(f"{self.percentiles[n][k]:.6g}" for k in ("50", "16", "84", "2.5", "97.5")),
                 f"{t:.1f}") for n, t in zip(self.names, self.tau)]
        head = (f"posterior: {self.walkers} walkers x {self.steps} steps (burn-in {self.burn}, "
                f"thin {self.thin}, {len(self.samples)} draws), acceptance "
                f"{self.acceptance:.2f}, {self.seconds:.1f} s")
        table = format_table(("parameter", "optimum", "median", "16%", "84%", "2.5%", "97.5%",
                              "tau"), rows, "lrrrrrrr")
        state = "converged" if self.converged else "NOT converged"
        return "\n".join([head, table, f"{state}: {self.verdict}"])

    # -- derived views ---------------------------------------------------------------------------
    def models(self, draws=100, seed=0):
        """``draws`` models drawn from the posterior (seeded)."""
        rng = arguments.rng(seed, "models: seed")
        draws = arguments.integer(draws, "models: draws", 1)
        pick = rng.choice(len(self.draws_x), size=min(draws, len(self.draws_x)), replace=False)
        m = len(self.log_posterior.problem.names)
        return [self.log_posterior.problem.model(x[:m]) for x in self.draws_x[np.sort(pick)]]

    def predictive(self, theta_i=30.0, draws=100, seed=0, step=1.0):
        """Posterior predictive bands (percentiles :data:`PERCENTILES` over drawn models).

        Returns ``{"albedo": {"theta_i_deg", "bands"}, "in_plane": {"theta_i_deg",
        "theta_o_deg", "bands"}}``; ``bands`` are shaped (5, angles, C). The directional albedo
        runs over theta_i in [0, 89] degrees; the in-plane slice has wi at ``theta_i`` (phi 0)
        and theta_o in [-89, 89], negative on the incident side (phi_o 0), positive on the
        specular side (phi_o 180).
        """
        from ..geometry import spherical_to_cartesian
        models = self.models(draws, seed)
        angles = np.linspace(0.0, 89.0, int(round(89.0 / step)) + 1)
        wi_curve = spherical_to_cartesian(np.radians(angles), 0.0)
        slice_deg = np.linspace(-89.0, 89.0, int(round(178.0 / step)) + 1)
        wo = spherical_to_cartesian(np.radians(np.abs(slice_deg)),
                                    np.where(slice_deg < 0, 0.0, np.pi))
        wi = spherical_to_cartesian(math.radians(theta_i), 0.0)
        albedo = np.array([m.albedo(wi_curve) for m in models])
        values = np.array([m.eval(wi, wo) for m in models])
        return {"albedo": {"theta_i_deg": angles,
                           "bands": np.percentile(albedo, PERCENTILES, axis=0)},
                "in_plane": {"theta_i_deg": float(theta_i), "theta_o_deg": slice_deg,
                             "bands": np.percentile(values, PERCENTILES, axis=0)}}

    def corner(self, path, force=False, dpi=100):
        """Write a corner plot (the ``corner`` package, Foreman-Mackey 2016) as PNG at ``path``,
        with the optimum marked; atomic, and an existing file only with ``force``."""
        import corner as corner_plot
        from matplotlib.figure import Figure
        from ..io import atomic_output
        d = len(self.names)
        fig = Figure(figsize=(2.2 * d + 1, 2.2 * d + 1))
        fig.subplots(d, d)
        optimum = [self.optimum[n] for n in self.names]
        # corner's truth lines index a grid of axes, which a single parameter does not have
        corner_plot.corner(self.samples, labels=list(self.names), fig=fig,
                           quantiles=[0.16, 0.5, 0.84], show_titles=True, title_fmt=".4g",
                           truths=optimum if d > 1 else None)
        if d == 1:
            fig.axes[0].axvline(optimum[0], color="#4682b4")
        with atomic_output(path, force) as tmp:
            fig.savefig(tmp, format="png", dpi=dpi)


def _seed_state(seed):
    """A numpy RandomState for emcee (which takes no Generator) from an int or Generator."""
    if isinstance(arguments.seed(seed, "mcmc: seed"), np.random.Generator):
        seed = int(seed.integers(2 ** 32))
    return np.random.RandomState(int(seed) % 2 ** 32), np.random.default_rng(int(seed))


def _moves(moves):
    """``(emcee moves, description)`` for a name of :data:`MOVES`, an emcee Move or a list of
    ``(Move, weight)`` pairs (passed to emcee as they are)."""
    import emcee
    if isinstance(moves, str):
        if moves not in MOVES:
            raise InputError(f"moves must be one of {', '.join(MOVES)} or emcee moves, "
                             f"got {moves!r}")
        build, description = MOVES[moves]
        return build(), description
    pairs = [(moves, 1.0)] if isinstance(moves, emcee.moves.Move) else moves
    try:
        ok = len(pairs) > 0 and all(isinstance(m, emcee.moves.Move) and float(w) > 0
                                    for m, w in pairs)
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise InputError(f"moves must be one of {', '.join(MOVES)}, an emcee Move or a list "
                         f"of (Move, weight > 0) pairs, got {moves!r}")
    return list(pairs), ", ".join(f"{type(m).__name__} ({float(w):g})" for m, w in pairs)


def _walkers(walkers, dim):
    if walkers is None:
        return max(32, 4 * dim + (4 * dim) % 2)
    if not arguments.is_integer(walkers) or walkers < 2 * dim or walkers % 2:
        raise InputError(f"walkers must be an even integer >= {2 * dim} (twice the {dim} "
                         f"sampled parameters), got {walkers!r}")
    return int(walkers)


def _chain_backend(chain, force):
    """``(backend or None, temporary path or None)`` for ``chain`` (.npz is written at the end;
    .h5 is emcee's HDF5 backend, written as the run goes to a temporary file)."""
    if chain is None:
        return None, None
    from pathlib import Path
    path = Path(chain)
    if path.suffix not in (".npz", ".h5", ".hdf5"):
        raise InputError(f"{chain}: chain files end in .npz or .h5, got {path.suffix or 'none'}")
    if path.exists() and not force:
        from ..errors import OutputError
        raise OutputError(f"{chain}: exists; pass force=True (--force) to replace it")
    if path.suffix == ".npz":
        return None, None
    import importlib.util
    if importlib.util.find_spec("h5py") is None:
        raise InputError(f"{chain}: HDF5 chains need h5py (pip install h5py); or use .npz")
    import emcee
    tmp = path.with_name(f".{path.name}.partial")
    tmp.unlink(missing_ok=True)
    return emcee.backends.HDFBackend(str(tmp), name="mcmc"), tmp


def _save_chain(sampler, post, chain, tmp, force):
    import os
    if tmp is not None:
        os.replace(tmp, chain)
        return
    from ..io import atomic_output
    with atomic_output(chain, force) as out:
        with open(out, "wb") as fh:
            np.savez(fh, chain=sampler.get_chain(), log_prob=sampler.get_log_prob(),
                     names=np.array(post.names), natural=post.samples,
                     burn=post.burn, thin=post.thin, tau=post.tau)


def _run(sampler, p0, max_steps, meter):
    """Grow the chain until converged or ``max_steps``: ``(steps, tau, converged, verdict)``;
    ``meter`` (a :class:`brdf.progress.Task`) counts the steps."""
    state, steps, last = p0, 0, None
    while steps < max_steps:
        chunk = min(max(FIRST_CHECK, steps // 10), max_steps - steps)
        state = sampler.run_mcmc(state, chunk, progress=False)
        steps += chunk
        meter.update(chunk)
        tau = sampler.get_autocorr_time(tol=0)
        settled = last is not None and np.all(np.abs(tau - last) < TAU_STABLE * tau)
        if np.all(np.isfinite(tau)) and steps > TAU_MULTIPLE * tau.max() and settled:
            return steps, tau, True, (f"chain of {steps} steps is {steps / tau.max():.0f} x the "
                                      f"largest autocorrelation time ({tau.max():.1f} steps); "
                                      f"tau changed by less than {TAU_STABLE:.0%} since the "
                                      "last check")
        last = tau
    return steps, tau, False, (f"stopped at max_steps={max_steps}: {steps / tau.max():.0f} x "
                               f"the largest autocorrelation time ({tau.max():.1f} steps), "
                               f"{TAU_MULTIPLE} x needed with tau settled; raise max_steps")


def _start_fit(data, start, seed, fit_options):
    """The FitResult the walkers start from, and the problem it was fitted on."""
    from .nlopt_fit import FitResult, fit
    from .mixed_problem import problem_for
    if not isinstance(start, FitResult):
        start = fit(data, start, seed=seed, **fit_options)
    opts = start.provenance["options"]
    problem = problem_for(data, start.spec, loss=opts["loss"], cutoff=opts["cutoff_deg"],
                          shared=opts["shared"], fix=opts["fix"],
                          bounds={k: tuple(v) for k, v in opts["bounds"].items()})
    return start, problem, problem.x0  # the spec's values: the optimum


def mcmc(data, start, *, walkers=None, max_steps=DEFAULT_MAX_STEPS, seed=0, moves="de",
         chain=None, force=False, progress=None, **fit_options):
    """Sample the posterior of a model's parameters given measured data (emcee).

    Parameters
    ----------
    data : Table or path
        The measurements (a path is read with :func:`brdf.read`).
    start : FitResult, str or Model
        A point estimate from :func:`brdf.fit` on the same data (its loss, cutoff, shared,
        fixed and bounded parameters are reused), or a spec to fit first with ``fit_options``.
    walkers : int, optional
        Even, at least twice the number of sampled parameters (default max(32, 4 dim)).
    max_steps : int
        Cap on the chain length.
    seed : int or numpy.random.Generator
        Same seed, same chain.
    moves : str, emcee Move or list of (Move, weight)
        How walkers propose: ``"de"`` (differential evolution with snooker updates, the
        default) or ``"stretch"`` (emcee's default), see :data:`MOVES`; or emcee moves.
    chain : str or path, optional
        Save the whole chain: ``.npz`` (x-space chain, log-probabilities, natural-unit draws),
        or ``.h5`` (emcee's HDF5 backend, group ``mcmc``; needs h5py).
    force : bool
        Replace an existing chain file.
    progress : bool, optional
        None (default): a bar on stderr when it is a terminal, otherwise one line when the
        chain ends (``mcmc: 2400 steps in 12.0 s``); True: the bar; False: nothing (see
        :mod:`brdf.progress`). The same for the fit of a spec given as ``start``.

    Returns
    -------
    Posterior
    """
    import emcee
    from ..io import as_table
    began = time.perf_counter()
    max_steps = arguments.integer(max_steps, "max_steps", FIRST_CHECK)
    state, rng = _seed_state(seed)
    proposals, described = _moves(moves)
    backend, tmp = _chain_backend(chain, force)
    table = as_table(data)
    # a spec's fit first reports its progress as the chain will
    result, problem, x_opt = _start_fit(table, start, seed,
                                        {"progress": progress, **fit_options})
    logpost = LogPosterior(problem, x_opt)
    nwalkers = _walkers(walkers, logpost.dim)
    if nwalkers < DE_WALKERS and any(isinstance(m, (emcee.moves.DEMove,
                                                    emcee.moves.DESnookerMove))
                                     for m, _ in proposals):
        raise InputError(f"walkers must be >= {DE_WALKERS} with differential-evolution moves "
                         f"(a walker moves along the difference of two others of the other "
                         f"half), got {nwalkers}; or moves='stretch'")
    sampler = emcee.EnsembleSampler(nwalkers, logpost.dim, logpost, vectorize=True,
                                    backend=backend, moves=proposals)
    sampler.random_state = state.get_state()
    try:
        with task(max_steps, "mcmc", "step", progress) as meter:
            steps, tau, converged, verdict = _run(sampler, logpost.start(x_opt, nwalkers, rng),
                                                  int(max_steps), meter)
    except BaseException:
        if tmp is not None:
            tmp.unlink(missing_ok=True)
        raise
    burn = min(int(2 * tau.max()), steps // 2)
    thin = max(1, int(0.5 * tau.min()))
    draws_x = sampler.get_chain(discard=burn, thin=thin, flat=True)
    samples = logpost.natural(draws_x)
    acceptance = float(np.mean(sampler.acceptance_fraction))
    if not 0.1 <= acceptance <= 0.9:
        verdict += f"; acceptance fraction {acceptance:.2f} is outside [0.1, 0.9]"
    optimum = dict(zip(logpost.names, logpost.natural(
        np.append(x_opt, math.log(logpost.s_hat)) if not logpost.known_sigma else x_opt)[0]))
    post = Posterior(
        names=logpost.names, samples=samples,
        percentiles={n: {f"{q:g}": float(v) for q, v in zip(PERCENTILES, col)}
                     for n, col in zip(logpost.names,
                                       np.percentile(samples, PERCENTILES, axis=0).T)},
        correlation=np.atleast_2d(np.corrcoef(samples, rowvar=False)), tau=tau,
        acceptance=acceptance, converged=converged, verdict=verdict, walkers=nwalkers,
        steps=steps, burn=burn, thin=thin, optimum={k: float(v) for k, v in optimum.items()},
        fit=result, log_posterior=logpost, draws_x=draws_x,
        chain=None if chain is None else str(chain), moves=described)
    if chain is not None:
        _save_chain(sampler, post, chain, tmp, force)
    post.seconds = time.perf_counter() - began
    return post
