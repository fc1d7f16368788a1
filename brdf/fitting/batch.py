"""Fitting many tables: local worker processes, or a Dask distributed cluster.

Each input gets its own fit with the same spec and options and its report ``OUTDIR/<stem>.json``
(stems shared by several inputs get a suffix from their path's hash, stable from run to run).
Workers read their input themselves (on a cluster every worker must see the same paths, e.g. a
shared file system) and send the report back; the driver writes reports and the summary, so
OUTDIR only needs to exist where the driver runs.

Runs resume: a report already in OUTDIR whose input SHA-256, spec, seed and options (loss,
optimizer, starts, energy constraint, cutoff, fixed values, bounds, evaluation budget) match is
kept and the input skipped. A report that does not match (the input or the options changed) is refitted
only with ``force``; without it that input is reported as failed, and the others go on. The
summary files (``summary.csv``, ``summary.json``) describe the latest run and are rewritten by
each run.
"""

import glob as globbing
import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

from .. import arguments, spawned
from ..errors import BRDFError, InputError
from ..io.files import file_sha256
from ..progress import task

__all__ = ["batch", "BatchResult", "STATUSES"]

#: ``fitted`` (converged), ``not-converged``, ``skipped`` (a matching report was there),
#: ``failed`` (bad input, a stale report without force, or an error in the worker).
STATUSES = ("fitted", "not-converged", "skipped", "failed")
_COLUMNS = ("file", "report", "status", "loss_name", "loss", "converged", "energy_holds",
            "verdict", "warnings", "seconds", "error")


@dataclass(frozen=True)
class BatchResult:
    """Outcome of :func:`batch`: one row per input, in sorted input order.

    Attributes
    ----------
    rows : tuple of dict
        file, report, status (see :data:`STATUSES`), loss_name, loss, converged, energy_holds,
        verdict (``ok``/``warning``), warnings (the kinds, ``;``-separated), seconds, error, and
        every fitted parameter under its flat name.
    outdir : str
    """

    rows: tuple
    outdir: str

    @property
    def ok(self):
        """Whether every input is fitted and converged (or skipped)."""
        return all(r["status"] in ("fitted", "skipped") for r in self.rows)

    def counts(self):
        return {s: sum(r["status"] == s for r in self.rows) for s in STATUSES}

    def to_dict(self):
        return {"schema": "brdf.batch/1", "outdir": self.outdir, "counts": self.counts(),
                "files": list(self.rows)}

    def __str__(self):
        from ..formatting import format_table
        body = [(Path(r["file"]).name, r["status"],
                 "" if r["loss"] is None else f"{r['loss']:.6g}",
                 "" if r["energy_holds"] is None else ("yes" if r["energy_holds"] else "NO"),
                 (r["verdict"] or "") if not r["warnings"] else f"warning: {r['warnings']}",
                 f"{r['seconds']:.2f}", r["error"] or "") for r in self.rows]
        counts = ", ".join(f"{n} {s}" for s, n in self.counts().items() if n)
        return "\n".join([format_table(("file", "status", "loss", "energy", "verdict", "s",
                                        "error"), body, "llrllrl"),
                          f"{len(self.rows)} files: {counts}; reports in {self.outdir}"])


def _inputs(inputs):
    """Sorted, de-duplicated input paths from a glob pattern or a sequence of paths/patterns."""
    patterns = [inputs] if isinstance(inputs, (str, os.PathLike)) else list(inputs)
    paths = set()
    for pattern in map(str, patterns):
        found = globbing.glob(pattern, recursive=True) if globbing.has_magic(pattern) \
            else [pattern] if os.path.exists(pattern) else []
        paths.update(p for p in found if os.path.isfile(p))
    if not paths:
        raise InputError(f"no input file matches {', '.join(map(str, patterns))}")
    return sorted(paths)


def _report_names(paths):
    """``{path: report file name}``: the stem, with a hash of the path where stems collide."""
    stems = {}
    for p in paths:
        stems.setdefault(Path(p).stem, []).append(p)
    names = {}
    for stem, group in stems.items():
        for p in group:
            digest = hashlib.sha256(os.path.abspath(p).encode()).hexdigest()[:8]
            names[p] = f"{stem}.json" if len(group) == 1 else f"{stem}-{digest}.json"
    return names


def _matching_report(report_path, path, spec, options):
    """The report at ``report_path`` if it was fitted from this input (SHA-256), spec, seed and
    options, else None."""
    try:
        report = json.loads(Path(report_path).read_text(encoding="utf-8"))
        prov = report["provenance"]
        same = (prov["input"]["sha256"] == file_sha256(path) and prov["spec"] == spec
                and prov["seed"] == options["seed"] and _same_options(prov["options"], options))
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return report if same else None


def _same_options(saved, options):
    if not isinstance(saved, dict):
        return False
    given = {"loss": options["loss"], "optimizer": options["optimizer"],
             "starts": options["starts"], "energy_constraint": options["energy_constraint"],
             "cutoff_deg": float(options["cutoff"]), "max_evals": options["max_evals"],
             "fix": options["fix"], "bounds": {k: list(v) for k, v in options["bounds"].items()}}
    return all(saved.get(k) == v for k, v in given.items())


def fit_file(path, spec, options, plugins=()):
    """Worker task: ``(report dict, None)`` or ``(None, one-line error)`` for one input.
    ``plugins`` (:func:`brdf.models.custom.plugin_sources` of the caller) are imported first
    where not yet loaded, so that spawned and remote workers know the caller's custom families."""
    from ..models.custom import ensure_plugins
    from .nlopt_fit import fit
    try:
        ensure_plugins(plugins)
        return fit(path, spec, progress=False, **options).to_dict(), None
    except BRDFError as exc:
        return None, str(exc)
    except OSError as exc:
        return None, f"{exc.filename or path}: {exc.strerror or exc}"
    except Exception as exc:  # a worker's bug must not stop the other inputs
        return None, f"internal error: {type(exc).__name__}: {exc}"


def _row(path, report_path, status, report=None, error=None):
    row = {"file": str(path), "report": str(report_path), "status": status, "loss_name": None,
           "loss": None, "converged": None, "energy_holds": None, "verdict": None,
           "warnings": None, "seconds": 0.0, "error": error}
    if report is not None:
        row.update(loss_name=report["loss"]["name"], loss=report["loss"]["value"],
                   converged=report["converged"], energy_holds=report["energy"]["holds"],
                   verdict=report.get("verdict"),
                   warnings=";".join(sorted({w["kind"] for w in report.get("warnings", [])})),
                   seconds=report["timing"]["total_s"])
        row.update({name: report["params"][name] for name in report["free"]})
    return row


def _init_worker(threads, settings):
    """Set up a local worker, once it has started: its share of the cores and its parent's
    reporting (quiet, program name)."""
    import numba
    from ..progress import configure
    numba.set_num_threads(threads)
    configure(*settings)


def _local_pool(jobs):
    """A pool of ``jobs`` spawned workers sharing the cores (:func:`brdf.spawned.pool`), and
    the shared count of its workers that finished starting."""
    from ..progress import current
    threads = max(1, (os.cpu_count() or 1) // jobs)
    return spawned.pool(jobs, _init_worker, (threads, tuple(current())))


def _dask_client(scheduler):
    try:
        from dask.distributed import Client
    except ImportError:
        raise InputError("--scheduler needs dask.distributed: pip install \"brdf[dask]\"") \
            from None
    try:
        return Client(scheduler, timeout=30)
    except (OSError, TimeoutError) as exc:
        raise InputError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from None


def _submit(todo, spec, options, jobs, scheduler):
    """Yield ``(path, (report, error))`` as the fits finish, in any order."""
    from ..models.custom import plugin_sources
    plugins = plugin_sources()
    if scheduler is not None:
        from dask.distributed import as_completed
        client = _dask_client(scheduler)
        try:
            futures = {client.submit(fit_file, p, spec, options, plugins, pure=False): p
                       for p in todo}
            for future in as_completed(futures):
                yield futures[future], future.result()
        finally:
            client.close()
    elif jobs == 1:
        for p in todo:
            yield p, fit_file(p, spec, options, plugins)
    else:
        from concurrent.futures import as_completed
        pool, started = _local_pool(jobs)
        with spawned.main_guarded(started, "brdf.batch"), pool:
            futures = {pool.submit(fit_file, p, spec, options, plugins): p for p in todo}
            for future in as_completed(futures):
                yield futures[future], future.result()


def _write_summary(result, outdir):
    import csv
    import io
    from ..io import atomic_output
    params = sorted({k for r in result.rows for k in r if k not in _COLUMNS})
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=list(_COLUMNS) + params, lineterminator="\n")
    writer.writeheader()
    writer.writerows(result.rows)
    for name, content in (("summary.csv", text.getvalue()),
                          ("summary.json", json.dumps(result.to_dict(), indent=2) + "\n")):
        with atomic_output(outdir / name, True) as tmp:
            tmp.write_text(content, encoding="utf-8")


def batch(inputs, spec, outdir, *, jobs=None, scheduler=None, force=False, progress=None,
          loss="cosine-l2", optimizer="LD_LBFGS", starts=None, energy_constraint=False,
          cutoff=80.0, shared=(), fix=None, bounds=None, seed=0, max_evals=2000):
    """Fit ``spec`` to every input file and write one report per file plus a summary.

    Parameters
    ----------
    inputs : str or sequence
        A glob pattern (``"scans/**/*.binary"``), or paths and patterns.
    spec : str or Model
        The model to fit to each; checked before any work is sent out.
    outdir : str or path
        Where reports and ``summary.csv`` / ``summary.json`` go (created if missing).
    jobs : int, optional
        Local worker processes (default: one per core); 1 fits in this process.
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://host:8786``); fits then run on its
        workers and ``jobs`` is ignored.
    force : bool
        Refit inputs that have a report already.
    progress : bool, optional
        None (default): a bar over files on stderr when it is a terminal, otherwise one line
        per file as it is done (``batch: t1.csv fitted (2 of 3) after 4.1 s``) and one at
        the end; True: the bar; False: nothing (see :mod:`brdf.progress`).
    loss, optimizer, starts, energy_constraint, cutoff, shared, fix, bounds, seed, max_evals
        As for :func:`brdf.fit` (the same default starts), the same for every input.

    Returns
    -------
    BatchResult

    Raises
    ------
    MainGuardError
        When local workers die as they start because the calling script runs this call at
        its top level: spawned workers import the script again, so the call belongs under
        ``if __name__ == "__main__":``.
    """
    spawned.stop_if_starting()
    from ..io import atomic_output
    from ..spec import parse
    from . import losses
    from .nlopt_fit import DEFAULT_TOL, check_options
    spec = str(parse(spec))
    losses.check_loss(loss)
    starts = check_options(optimizer, starts, seed, max_evals, DEFAULT_TOL)
    if jobs is not None:
        jobs = arguments.integer(jobs, "jobs", 1)
    paths = _inputs(inputs)
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    names = _report_names(paths)
    options = {"loss": loss, "optimizer": optimizer, "starts": starts,
               "energy_constraint": energy_constraint, "cutoff": cutoff, "shared": list(shared),
               "fix": dict(fix or {}), "bounds": dict(bounds or {}), "seed": seed,
               "max_evals": max_evals}
    rows, todo = {}, []
    for p in paths:
        target = outdir / names[p]
        if target.exists() and not force:
            report = _matching_report(target, p, spec, options)
            rows[p] = (_row(p, target, "skipped", report) if report is not None else
                       _row(p, target, "failed", error=f"{target}: exists and was fitted from "
                            "another input, spec or options; pass --force to refit"))
        else:
            todo.append(p)
    with task(len(todo), "batch", "file", progress) as meter:
        for p, (report, error) in _submit(todo, spec, options, jobs or os.cpu_count() or 1,
                                          scheduler):
            target = outdir / names[p]
            if report is None:
                rows[p] = _row(p, target, "failed", error=error)
            else:
                with atomic_output(target, True) as tmp:
                    tmp.write_text(json.dumps(report, indent=2, allow_nan=False) + "\n",
                                   encoding="utf-8")
                status = "fitted" if report["converged"] else "not-converged"
                rows[p] = _row(p, target, status, report)
            meter.done(f"{Path(p).name} {rows[p]['status']}")
    result = BatchResult(tuple(rows[p] for p in paths), str(outdir))
    _write_summary(result, outdir)
    return result
