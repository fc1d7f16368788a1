"""Point estimates with nlopt: ``brdf.fit(data, spec, ...) -> FitResult``.

Local optimizers run from several starts by default (:data:`DEFAULT_STARTS`): a data-driven
start computed from the table (:mod:`brdf.fitting.starts`), the spec's values and the best
points of a seeded Sobol design of the box; the best end is kept and every run is reported. Global optimizers search the whole box, then a
local optimizer polishes their best point, so that the result carries a convergence verdict
(a global search stops only at its evaluation budget). The energy constraint keeps the
directional albedo at or below 1 at a set of incidence angles, as nlopt inequality constraints:
natively for LD_SLSQP, LN_COBYLA and GN_ISRES, through nlopt's augmented Lagrangian (AUGLAG)
around the chosen method otherwise.

The result holds the fitted model and parameters, every metric at the optimum, nlopt's status,
the physical checks of the fitted model and the provenance (input SHA-256, spec, seed, options,
library versions). Wall times are kept apart in ``timing``: everything else is the same, byte for
byte, for the same inputs and seed.
"""

import math
import os
import time
from dataclasses import dataclass

import numpy as np

from .. import arguments
from .._threads import serial_below
from ..errors import InputError
from ..progress import task
from ..io import as_table
from . import losses
from .mixed_problem import problem_for
from .report import SCHEMA

__all__ = ["fit", "FitResult", "OPTIMIZERS", "ENERGY_THETA", "ENERGY_PHI", "DEFAULT_MAX_EVALS",
           "DEFAULT_TOL", "DEFAULT_STARTS", "energy_angles"]

#: Optimizers by name: ``(nlopt algorithm, kind)`` with kind ``local-gradient``,
#: ``local-free`` or ``global``.
OPTIMIZERS = {
    "LD_LBFGS": ("LD_LBFGS", "local-gradient"),
    "LD_SLSQP": ("LD_SLSQP", "local-gradient"),
    "LN_BOBYQA": ("LN_BOBYQA", "local-free"),
    "LN_NELDERMEAD": ("LN_NELDERMEAD", "local-free"),
    "LN_COBYLA": ("LN_COBYLA", "local-free"),
    "GN_DIRECT_L": ("GN_DIRECT_L", "global"),
    "GN_CRS2_LM": ("GN_CRS2_LM", "global"),
    "GN_ISRES": ("GN_ISRES", "global"),
    "MLSL": ("G_MLSL_LDS", "global"),
}
#: Optimizers that take inequality constraints themselves (the others go inside AUGLAG).
CONSTRAINED = ("LD_SLSQP", "LN_COBYLA", "GN_ISRES")
#: Local optimizer inside MLSL and for polishing a global search (constrained: LD_SLSQP).
POLISH, POLISH_CONSTRAINED = "LD_LBFGS", "LD_SLSQP"
#: Incidence polar angles (degrees) where the energy constraint holds the albedo <= 1 from the
#: start: normal incidence, where diffuse plus specular sums often peak, and denser towards
#: grazing (up to the energy check's most grazing angle), where microfacet lobes without
#: Fresnel and normalisations such as Duer's Ward peak.
ENERGY_THETA = (0.0, 30.0, 60.0, 75.0, 85.0, 89.0, 89.9)
#: Incidence azimuths (degrees) of the energy constraint for anisotropic models.
ENERGY_PHI = (0.0, 45.0, 90.0, 135.0)
#: When the energy check of a constrained fit still finds an albedo above 1 (between the
#: constrained angles), that angle joins the constraint and the fit resumes, this many times.
ENERGY_ROUNDS = 3
#: Relative step of the constraint's central differences. The albedo comes from an adaptive
#: cubature whose panel choice shifts with the parameters, adding noise of a few 1e-6; a step of
#: 1e-3 keeps that noise to ~1e-3 of the derivative (the truncation error is ~1e-6).
ENERGY_STEP = 1e-3
#: Relative tolerance of AUGLAG's subproblems. Tighter (1e-8), the inner L-BFGS stalls on the
#: penalty's curvature and nlopt reports a failure; the outer iterations still stop at ``tol``.
AUGLAG_INNER_TOL = 1e-6
#: A point counts as feasible when no constrained albedo exceeds 1 by more than this.
FEASIBLE_TOL = 1e-6
#: Objective evaluations per local run or per global search, unless ``max_evals`` says.
DEFAULT_MAX_EVALS = 2000
#: Relative tolerance on the loss (nlopt ftol_rel); x stops at its square root (xtol_rel).
DEFAULT_TOL = 1e-10
#: Local runs of a default fit: the data-driven start, the spec's values and the best Sobol
#: points of the screening (benchmarks/bench_fit_robustness.py measures what this buys).
DEFAULT_STARTS = 8
#: Sobol points of the box whose loss is screened (on the start subsample) for the starts.
SCREEN_POINTS = 256
#: Points per compiled pass of the screening (the samples are read once per pass).
SCREEN_BATCH = 32
#: Two run ends are different optima when a coordinate of x (log for log-scaled parameters)
#: differs by more than this fraction of its box width.
MODE_SEPARATION = 0.05
#: A different optimum within this relative distance of the best loss makes a fit multimodal.
MULTIMODAL_GAP = 0.05
#: Ends polished on all the samples of a large table: the best and distinct near-best ones.
MODE_POLISHES = 2
#: Threads that run the first-stage local runs side by side (None: one per core). Each run
#: is independent and deterministic, and results are kept in the order of the starts, so the
#: report does not depend on it. On 2 cores, eight runs on the RGL paper (5,668 samples):
#: 1.37-1.46 s one after another, 0.93 s on two threads, identical ends.
RUN_WORKERS = None
_CONVERGED = ("SUCCESS", "STOPVAL_REACHED", "FTOL_REACHED", "XTOL_REACHED")
_STATUS = ("SUCCESS", "STOPVAL_REACHED", "FTOL_REACHED", "XTOL_REACHED", "MAXEVAL_REACHED",
           "MAXTIME_REACHED", "FAILURE", "INVALID_ARGS", "OUT_OF_MEMORY", "ROUNDOFF_LIMITED",
           "FORCED_STOP")


@dataclass(frozen=True)
class FitResult:
    """The outcome of :func:`fit`.

    Attributes
    ----------
    params : dict
        Every numeric parameter of the fitted model under its flat name, fixed ones included.
    model : Model
        The fitted model; ``spec`` is ``str(model)``, which parses back to it.
    spec : str
    loss : float
        The minimised metric at the optimum; ``loss_name`` says which.
    loss_name : str
    metrics : dict
        Every metric of :data:`brdf.fitting.losses.LOSSES` the data allow, at the optimum.
    status : str
        nlopt's return code name for the final run (e.g. ``"FTOL_REACHED"``).
    converged : bool
        Whether that run ended on a tolerance (not on its budget or a failure).
    evaluations : int
        Objective evaluations (each with its gradient, for gradient-based methods) in all runs.
    free : tuple of str
        The fitted parameters; ``fixed`` maps the others to their values.
    fixed : dict
    bounds : dict
        ``{free name: [lower, upper]}``.
    runs : tuple of dict
        Each start or stage: run (its label), optimizer, status, loss, evaluations,
        feasibility; local runs also ``start`` and ``end`` (``{free name: value}``) and
        ``samples`` (how many it was scored on: the start subsample or all of them).
    data : dict
        Samples used and the weighting (:meth:`brdf.fitting.losses.Samples.describe`).
    energy : dict
        ``constrained``, ``holds`` (the energy check of the fitted model), ``worst_albedo``
        and where, and the constrained incidence angles.
    checks : dict
        ``brdf.check(model).to_dict()``.
    provenance : dict
        Input (path, SHA-256), spec, seed, options, library versions.
    timing : dict
        Wall times in seconds: ``total_s``; ``prepare_s`` (samples, weights, loss terms);
        ``optimize_s`` (the starts and the nlopt runs); ``finish_s`` (the physical checks, any
        energy refinement runs, the metrics, the warnings).
    warnings : tuple of dict
        ``{"parameter", "kind", "detail"}`` with kind ``at-bound``, ``collapsed``,
        ``undetermined`` or ``multimodal`` (:mod:`brdf.fitting.verdicts`).
    verdict : str
        ``"ok"`` without warnings, else ``"warning"``; ``converged`` stays the optimiser's.
    """

    params: dict
    model: object
    spec: str
    loss: float
    loss_name: str
    metrics: dict
    status: str
    converged: bool
    evaluations: int
    free: tuple
    fixed: dict
    bounds: dict
    runs: tuple
    data: dict
    energy: dict
    checks: dict
    provenance: dict
    timing: dict
    warnings: tuple = ()
    verdict: str = "ok"

    def to_dict(self):
        """JSON-ready report; ``timing`` is its last key (drop it to compare runs)."""
        from ..formatting import json_ready
        return json_ready({
            "schema": SCHEMA, "spec": self.spec, "model": self.model.to_dict(),
            "params": self.params, "free": list(self.free), "fixed": self.fixed,
            "bounds": self.bounds, "loss": {"name": self.loss_name, "value": self.loss},
            "metrics": self.metrics, "status": self.status, "converged": self.converged,
            "evaluations": self.evaluations, "runs": list(self.runs), "data": self.data,
            "energy": self.energy, "checks": self.checks, "provenance": self.provenance,
            "warnings": list(self.warnings), "verdict": self.verdict, "timing": self.timing})

    def save(self, path, force=False):
        """Write the JSON report (:meth:`to_dict`) to ``path`` atomically; an existing file
        is replaced only with ``force`` (see :func:`brdf.fitting.report.save_report`)."""
        from .report import save_report
        save_report(self.to_dict(), path, force)

    def __str__(self):
        from ..formatting import format_table
        d = self.data
        verdict = "converged" if self.converged else "NOT converged"
        rows = [(name, f"{value:.8g}", *(f"{b:g}" for b in self.bounds[name]), "free")
                if name in self.bounds else (name, f"{value:.8g}", "", "", "fixed")
                for name, value in self.params.items()]
        e = self.energy
        lines = [
            f"fit of {self.provenance['spec']} to {self.provenance['input']['name']}: "
            f"{d['samples_used']:,} of {d['samples_total']:,} samples (cutoff {d['cutoff_deg']:g}"
            f" deg, {d['weighting']} weights)",
            f"loss {self.loss_name} = {self.loss:.6g}; status {self.status} ({verdict}) after "
            f"{self.evaluations} evaluations in {len(self.runs)} run(s), "
            f"{self.timing['total_s']:.2f} s",
            format_table(("parameter", "value", "lower", "upper", ""), rows, "lrrrl"),
            "metrics: " + ", ".join(f"{k} {v:.6g}" for k, v in self.metrics.items()),
            f"energy: max albedo {e['worst_albedo']:.6f} at theta_i={e['theta_i']:g} "
            f"(channel {e['channel']}): {'holds' if e['holds'] else 'EXCEEDS 1'}"
            f"{' (constrained)' if e['constrained'] else ''}",
            "checks: " + ", ".join(f"{c['name']} {'pass' if c['passed'] else 'FAIL'}"
                                   for c in self.checks["checks"]),
            f"fitted: {self.spec}",
            f"verdict: {self.verdict}" + ("" if not self.warnings else
                                          f" ({len(self.warnings)})"),
        ]
        lines += [f"  warning {w['kind']}: {w['parameter']}: {w['detail']}"
                  for w in self.warnings]
        return "\n".join(lines)


class _Tracker:
    """The loss and constraint values seen at each point, to return the best feasible point
    whatever way a run ends (nlopt raises on a round-off stop and keeps no point)."""

    def __init__(self, constrained):
        self.constrained = constrained
        self.points = {}

    def record(self, x, key, value):
        self.points.setdefault(x.tobytes(), {"x": x.copy()})[key] = value

    def best(self):
        """``(x, loss, feasible)`` of the lowest loss among feasible points (among all points
        when none is feasible), or None before any evaluation."""
        scored = [p for p in self.points.values() if "loss" in p]
        if not scored:
            return None
        def feasible(p):
            return not self.constrained or p.get("worst", math.inf) <= FEASIBLE_TOL
        ok = [p for p in scored if feasible(p)] or scored
        p = min(ok, key=lambda p: p["loss"])
        return p["x"], p["loss"], feasible(p)


class _Objective:
    """nlopt objective: the loss (and its gradient when nlopt asks)."""

    def __init__(self, problem, tracker, progress):
        self.problem, self.tracker, self.progress = problem, tracker, progress
        self.calls = 0

    def __call__(self, x, grad):
        self.calls += 1
        with serial_below(len(self.problem.samples.wi)):
            if grad.size:
                loss, grad[:] = self.problem.loss_and_gradient(x)
            else:
                loss = self.problem.loss(x)
        self.tracker.record(x, "loss", loss)
        self.progress.update(1)
        self.progress.set_postfix(loss=f"{loss:.4g}")
        return loss


class _Energy:
    """nlopt vector inequality constraint: albedo(wi_j)_c - 1 <= 0 at incidence angles
    ``angles`` (m, 2) in degrees (theta, phi), from ``Model.albedo``; the Jacobian analytic
    (:meth:`Problem.albedo_jacobian`) or, for delta, multi-term and custom lobes, by central
    differences (:meth:`Problem.difference_rows`)."""

    def __init__(self, problem, tracker, angles):
        from ..geometry import directions_from_degrees
        self.problem, self.tracker = problem, tracker
        self.wi = directions_from_degrees(angles[:, 0], angles[:, 1])
        self.size = len(self.wi) * problem.channels

    def albedo(self, x):
        a = self.problem.model(x).albedo(self.wi)
        return np.broadcast_to(a, (len(self.wi), self.problem.channels))

    def __call__(self, result, x, grad):
        if grad.size:
            exact = self.problem.albedo_jacobian(x, self.wi)
            if exact is None:
                rows, width = self.problem.difference_rows(x, ENERGY_STEP)
                a = np.array([self.albedo(r) for r in rows])
                exact = a[0], self.problem.difference_jacobian(a, width)
            a, jac = exact
            grad[:] = jac.reshape(self.size, -1)
        else:
            a = self.albedo(x)
        result[:] = (a - 1.0).ravel()
        self.tracker.record(x, "worst", float(result.max()))


def energy_angles(model):
    """The incidence angles ``(m, 2)`` (theta, phi in degrees) the energy constraint starts
    with: :data:`ENERGY_THETA`, times :data:`ENERGY_PHI` for an anisotropic model."""
    phi = ENERGY_PHI if model.is_anisotropic else (0.0,)
    theta, phi = np.meshgrid(ENERGY_THETA, phi, indexing="ij")
    return np.stack([theta.ravel(), phi.ravel()], axis=-1)


def _status_name(code):
    import nlopt
    return next((n for n in _STATUS if getattr(nlopt, n) == code), str(code))


def _optimizer(name):
    if name not in OPTIMIZERS:
        raise InputError(f"unknown optimizer {name!r}; optimizers: {', '.join(OPTIMIZERS)}")
    return OPTIMIZERS[name]


def _make(problem, algorithm, objective, energy, max_evals, tol):
    """An nlopt optimizer with bounds, stopping rules, objective and (maybe) the constraint."""
    import nlopt
    n = len(problem.free)
    opt = nlopt.opt(getattr(nlopt, algorithm), n)
    if algorithm == "G_MLSL_LDS":
        opt.set_local_optimizer(_local(POLISH, n, tol))
    if energy is not None and algorithm not in CONSTRAINED:
        inner, opt = opt, nlopt.opt(nlopt.AUGLAG, n)
        _stopping(inner, max_evals, max(tol, AUGLAG_INNER_TOL))
        opt.set_local_optimizer(inner)
    opt.set_lower_bounds(problem.lower)
    opt.set_upper_bounds(problem.upper)
    opt.set_min_objective(objective)
    if energy is not None:
        opt.add_inequality_mconstraint(energy, np.full(energy.size, 1e-9))
    _stopping(opt, max_evals, tol)
    return opt


def _local(algorithm, n, tol):
    import nlopt
    opt = nlopt.opt(getattr(nlopt, algorithm), n)
    opt.set_ftol_rel(tol)
    opt.set_xtol_rel(math.sqrt(tol))
    return opt


def _stopping(opt, max_evals, tol):
    opt.set_maxeval(int(max_evals))
    opt.set_ftol_rel(tol)
    opt.set_xtol_rel(math.sqrt(tol))


def _run(problem, algorithm, x0, angles, options, label, budgeted=True):
    """One nlopt run from ``x0``, constrained at ``angles`` unless None: ``(x, loss, feasible,
    record)``. A ``budgeted`` run (one of the fit's planned runs) forgoes the rest of its
    evaluations in the progress meter when it ends early."""
    import nlopt
    tracker = _Tracker(angles is not None)
    objective = _Objective(problem, tracker, options["progress"])
    energy = None if angles is None else _Energy(problem, tracker, angles)
    opt = _make(problem, algorithm, objective, energy, options["max_evals"], options["tol"])
    try:
        opt.optimize(np.clip(x0, problem.lower, problem.upper))
        code = opt.last_optimize_result()
    except (nlopt.RoundoffLimited, RuntimeError, nlopt.runtime_error):
        code = opt.last_optimize_result()
        if code not in (nlopt.ROUNDOFF_LIMITED, nlopt.FAILURE):
            raise
    if budgeted:
        options["progress"].forgo(options["max_evals"] - objective.calls)
    x, loss, feasible = tracker.best()
    record = {"run": label, "optimizer": algorithm, "status": _status_name(code),
              "loss": loss, "evaluations": objective.calls,
              "feasible": None if angles is None else feasible}
    return x, loss, feasible, record


def _runs(problem, optimizer, starts, angles, options):
    """The runs of a fit before any energy refinement: ``(best x, records, ends)``; the kept
    run's record comes last (its status is the fit's); ``ends`` holds ``(x, loss, feasible)``
    of each run on all the samples (the multimodality check compares them)."""
    import nlopt
    algorithm, kind = OPTIMIZERS[optimizer]
    if kind == "global":
        nlopt.srand(options["seed"])
        x, _, _, search = _run(problem, algorithm, problem.x0, angles, options, "global search")
        x, loss, feasible, polish = _run(problem, _local_of(optimizer, angles), x, angles,
                                         options, "polish")
        return x, [search, polish], [(x, loss, feasible)]
    return _multistart(problem, algorithm, starts, angles, options)


def _start_points(problem, screen, starts, seed):
    """The starts of a local fit: ``[(label, x)]``. With one start, the better (on the
    screening samples) of the data-driven start and the spec's values; else both, then the
    ``starts - 2`` best of :data:`SCREEN_POINTS` seeded Sobol points of the box."""
    from .starts import data_driven, design
    x_data, loss_data = data_driven(problem, screen)
    x_spec = problem.x0
    if starts == 1:
        with serial_below(len(screen.samples.wi)):
            loss_spec = float(screen.channel_losses(x_spec).sum())
        keep_spec = np.isfinite(loss_spec) and loss_spec < loss_data
        return [("spec start", x_spec) if keep_spec else ("data-driven start", x_data)]
    points = [("data-driven start", x_data), ("spec start", x_spec)]
    extra = starts - 2
    if extra > 0:
        X = design(problem, max(SCREEN_POINTS, extra), seed)
        scores = np.empty(len(X))
        with serial_below(len(screen.samples.wi)):
            for a in range(0, len(X), SCREEN_BATCH):
                scores[a:a + SCREEN_BATCH] = screen.channel_losses(X[a:a + SCREEN_BATCH]).sum(1)
        scores = np.where(np.isfinite(scores), scores, np.inf)
        order = np.argsort(scores, kind="stable")[:extra]
        points += [(f"sobol start {int(k)}", X[k]) for k in order]
    return points


def _distinct(x, others, problem):
    """Whether ``x`` is a different optimum from every point of ``others``: some coordinate
    of x (the logarithm for log-scaled parameters) differs by more than
    :data:`MODE_SEPARATION` of its box width."""
    width = problem.upper - problem.lower
    return all(np.max(np.abs(x - o) / width) > MODE_SEPARATION for o in others)


def _multistart(problem, algorithm, starts, angles, options):
    """Local runs from :func:`_start_points`, then a second stage where needed.

    On a table larger than the screening subsample the first runs polish on the subsample;
    with the energy constraint they run without it (a constrained run costs an albedo
    Jacobian per step). Then the best end, and up to :data:`MODE_POLISHES` - 1 distinct ends
    within :data:`MULTIMODAL_GAP` of its loss, are polished on all the samples, constrained
    when asked. Returns ``(best x, records, ends)`` as :func:`_runs`."""
    from .starts import subsample
    screen = problem.restricted(subsample(problem.samples))
    points = _start_points(problem, screen, starts, options["seed"])
    single = screen is problem and angles is None
    def local(point):
        label, x0 = point
        x, loss, feasible, record = _run(screen, algorithm, x0, angles if single else None,
                                         options, label)
        record = {**record, "start": problem.natural(np.clip(x0, problem.lower, problem.upper)),
                  "end": problem.natural(x), "samples": len(screen.samples.wi)}
        return x, loss, feasible, record

    workers = min(len(points), RUN_WORKERS or os.cpu_count() or 1)
    if workers > 1:
        from concurrent.futures import ThreadPoolExecutor
        with ThreadPoolExecutor(workers) as pool:
            first = list(pool.map(local, points))  # in the order of the starts
    else:
        first = [local(p) for p in points]
    order = sorted(range(len(first)), key=lambda k: (not first[k][2], first[k][1], k))
    runs = list(first)
    if not single:
        chosen = [order[0]]
        best = first[order[0]][1]
        for k in order[1:]:
            if len(chosen) == MODE_POLISHES:
                break
            if first[k][1] <= best * (1 + MULTIMODAL_GAP) and _distinct(
                    first[k][0], [first[c][0] for c in chosen], problem):
                chosen.append(k)
        what = "all samples" if screen is not problem else "energy constrained"
        if screen is not problem and angles is not None:
            what = "all samples, energy constrained"
        for k in chosen:
            x0 = first[k][0]
            x, loss, feasible, record = _run(problem, algorithm, x0, angles, options,
                                             f"{first[k][3]['run']}, {what}")
            runs.append((x, loss, feasible, {**record, "start": problem.natural(x0),
                                             "end": problem.natural(x),
                                             "samples": len(problem.samples.wi)}))
        order = sorted(range(len(first), len(runs)),
                       key=lambda k: (not runs[k][2], runs[k][1], k))
    best = order[0]
    records = [r[3] for k, r in enumerate(runs) if k != best] + [runs[best][3]]
    final = runs if single else runs[len(first):]
    return runs[best][0], records, [(r[0], r[1], r[2]) for r in final]


def _local_of(optimizer, angles):
    """The local algorithm that resumes a fit: the chosen one when local, else the polisher."""
    algorithm, kind = OPTIMIZERS[optimizer]
    if kind != "global":
        return algorithm
    return POLISH if angles is None else POLISH_CONSTRAINED


def _refine_energy(problem, optimizer, x, angles, report, records, options):
    """Add the check's worst incidence angle to the constraint and resume while the energy
    check of a constrained fit fails (at most :data:`ENERGY_ROUNDS` times): ``(x, report)``."""
    from ..properties import check
    for k in range(ENERGY_ROUNDS):
        energy = report["energy"]
        if energy.passed is not False:
            break
        angles = np.vstack([angles, [[energy.where["theta_i"], energy.where["phi_i"]]]])
        x, _, _, record = _run(problem, _local_of(optimizer, angles), x, angles, options,
                               f"energy refinement {k + 1}", budgeted=False)
        records.append(record)
        report = check(problem.model(x))
    return x, report, angles


def _versions():
    from importlib.metadata import version
    import nlopt
    import numba
    import scipy
    return {"brdf": version("brdf"), "numpy": np.__version__, "scipy": scipy.__version__,
            "nlopt": nlopt.__version__, "numba": numba.__version__}


def check_options(optimizer, starts, seed, max_evals, tol):
    """The number of starts (None: :data:`DEFAULT_STARTS`, or 1 for a global optimizer);
    raises InputError naming the first bad option (as :func:`fit` takes them)."""
    _, kind = _optimizer(optimizer)
    if starts is None:
        starts = 1 if kind == "global" else DEFAULT_STARTS
    starts = arguments.integer(starts, "starts", 1)
    if kind == "global" and starts > 1:
        raise InputError(f"starts is for local optimizers; {optimizer} searches the whole box")
    arguments.integer(seed, "seed", 0)  # an int: the report records it
    arguments.integer(max_evals, "max_evals", 1)
    arguments.real(tol, "tol", 0.0, 1.0, low_open=True)
    if tol >= 1.0:
        raise InputError(f"tol must be a number in (0, 1), got {tol!r}")
    return starts


def _energy_summary(report, angles):
    energy = report["energy"]
    summary = {"constrained": angles is not None, "holds": energy.passed,
               "worst_albedo": energy.worst, "theta_i": energy.where["theta_i"],
               "phi_i": energy.where["phi_i"], "channel": energy.where["channel"],
               "tolerance": energy.tolerance}
    if angles is not None:
        summary["constrained_angles_deg"] = angles.tolist()
    return summary


def fit(data, spec, *, loss="cosine-l2", optimizer="LD_LBFGS", starts=None,
        energy_constraint=False, cutoff=losses.DEFAULT_CUTOFF, shared=(), fix=None, bounds=None,
        seed=0, max_evals=DEFAULT_MAX_EVALS, tol=DEFAULT_TOL, progress=None):
    """Fit a model to measured samples with nlopt.

    Parameters
    ----------
    data : Table, path or object with ``wi``, ``wo``, ``values`` (and ``sigma``)
        The measurements; a path is read with :func:`brdf.read`.
    spec : str or Model
        The model to fit; its parameter values are one of the starting points.
    loss : str
        A metric of :data:`brdf.fitting.losses.LOSSES` (default ``cosine-l2``).
    optimizer : str
        A key of :data:`OPTIMIZERS`: LD_LBFGS, LD_SLSQP (analytic gradients,
        see :class:`~brdf.fitting.problem.Problem`; central differences for models with
        custom lobes, see :class:`~brdf.fitting.mixed_problem.MixedProblem`), LN_BOBYQA,
        LN_NELDERMEAD, LN_COBYLA (derivative-free), GN_DIRECT_L, GN_CRS2_LM, GN_ISRES, MLSL
        (global, then polished).
    starts : int, optional
        Local runs (default :data:`DEFAULT_STARTS`; global optimizers take 1). The data-driven
        start (:func:`brdf.fitting.starts.data_driven`: the scales projected out by least
        squares over a grid of lobe widths), the spec's values, and the ``starts - 2`` best of
        :data:`SCREEN_POINTS` scrambled Sobol points of the box (seeded; log-scaled
        parameters in log space) by their loss on the start subsample. Each is polished by the
        local optimizer, on the subsample for a table larger than it and without the energy
        constraint (then the best end, and a distinct near-best one, again on all the samples
        and constrained); the best is kept and every run is in ``runs``. ``starts=1`` is one run from the better of the data-driven start and
        the spec's values.
    energy_constraint : bool
        Constrain the directional albedo to at most 1 at :func:`energy_angles`; should the
        energy check of the result still fail between them, its worst angle joins the
        constraint and the fit resumes (:data:`ENERGY_ROUNDS`). LD_SLSQP takes the constraint
        natively and is the cheapest choice; AUGLAG around LD_LBFGS needs several times more
        evaluations (each with the constraint's Jacobian: one albedo cubature with analytic
        derivatives, or 2G + 1 for central differences where a lobe has none, see
        :meth:`Problem.albedo_jacobian`).
    cutoff : float
        Grazing cutoff in degrees on theta_i and theta_o (see
        :data:`brdf.fitting.losses.DEFAULT_CUTOFF`).
    shared, fix, bounds
        Per-channel parameters fitted as one value; ``{name: value}`` held fixed;
        ``{name: (lower, upper)}`` narrowing the box (see :class:`Problem`).
    seed : int
        Seeds the random starts and nlopt's own random numbers (global methods).
    max_evals : int
        Objective evaluations per local run or global search.
    tol : float
        Relative tolerance on the loss (nlopt ftol_rel; xtol_rel is its square root).
    progress : bool or callable, optional
        None (default): a bar on stderr when it is a terminal, otherwise one line when the
        fit ends (``fit: 853 evals in 2.1 s``); True: the bar; False: nothing; a callable is
        called as ``progress(evaluations, budget)`` after each evaluation (see
        :mod:`brdf.progress`).

    Returns
    -------
    FitResult
    """
    from ..properties import check
    start = time.perf_counter()
    starts = check_options(optimizer, starts, seed, max_evals, tol)
    table = as_table(data)
    problem = problem_for(table, spec, loss=loss, cutoff=cutoff, shared=shared, fix=fix,
                          bounds=bounds)
    if not problem.free:
        raise InputError(f"nothing to fit: every parameter of {problem.base} is fixed")
    prepared = time.perf_counter()
    angles = energy_angles(problem.base) if energy_constraint else None
    runs = 2 if OPTIMIZERS[optimizer][1] == "global" else starts + MODE_POLISHES
    with task(runs * max_evals, "fit", "eval", progress) as meter:
        options = {"max_evals": max_evals, "tol": tol, "seed": seed, "progress": meter}
        x, records, ends = _runs(problem, optimizer, starts, angles, options)
        # the polishing runs a fit did not need: the planned work is all behind it
        meter.forgo(meter.total - meter.count - meter.forgone)
        optimized = time.perf_counter()
        report = check(problem.model(x))
        if angles is not None:
            x, report, angles = _refine_energy(problem, optimizer, x, angles, report, records,
                                               options)
    metrics = problem.metrics(x)
    warnings = _warnings(problem, x, metrics[problem.loss_name], ends, records)
    end = time.perf_counter()
    timing = {"total_s": end - start, "prepare_s": prepared - start,
              "optimize_s": optimized - prepared, "finish_s": end - optimized}
    options = {"loss": problem.loss_name, "optimizer": optimizer, "starts": int(starts),
               "energy_constraint": bool(energy_constraint), "cutoff_deg": problem.samples.cutoff,
               "shared": list(problem.shared), "fix": dict(fix or {}),
               "bounds": {k: list(v) for k, v in (bounds or {}).items()},
               "max_evals": int(max_evals), "tol": float(tol)}
    return _result(problem, table, spec, x, metrics, records, report, angles, options, seed,
                   timing, warnings)


def _warnings(problem, x, loss, ends, records):
    """:func:`brdf.fitting.verdicts.warnings_of` at the kept optimum; the Hessian on the start
    subsample of a large table."""
    from .starts import subsample
    from .verdicts import warnings_of
    screen = problem.restricted(subsample(problem.samples))
    return warnings_of(problem, x, loss, ends, MULTIMODAL_GAP, MODE_SEPARATION, screen)


def _result(problem, table, spec, x, metrics, records, report, angles, options, seed, timing,
            warnings):
    from ..spec import parse
    model = problem.model(x)
    params = model.params
    final = records[-1]
    source = getattr(table, "source", None)
    provenance = {
        "input": {"name": str(getattr(table, "name", type(table).__name__)),
                  **(source.to_dict() if source is not None else {"sha256": None})},
        "spec": str(parse(spec)), "seed": int(seed), "options": options,
        "versions": _versions(),
    }
    return FitResult(
        params=params, model=model, spec=str(model), loss=metrics[problem.loss_name],
        loss_name=problem.loss_name, metrics=metrics, status=final["status"],
        converged=final["status"] in _CONVERGED,
        evaluations=int(sum(r["evaluations"] for r in records)), free=problem.names,
        fixed={k: v for k, v in params.items() if k not in problem.names},
        bounds={p.name: [p.lower, p.upper] for p in problem.free}, runs=tuple(records),
        data=problem.samples.describe(), energy=_energy_summary(report, angles),
        checks=report.to_dict(), provenance=provenance, timing=timing,
        warnings=tuple(warnings), verdict="warning" if warnings else "ok")
