"""A run's figures drawn in worker processes (``openfdk run`` and ``openfdk plot``).

matplotlib draws on one core: the nine figures of DM's 100-frame gait run
(docs/tutorial-knee-gait.md) took 5.3 s of a 16 s command, the body poses' figure (46
axes) about 3 s of it. The figures do not depend on each other, so :func:`write_figures`
shares them between ``workers`` processes forked from this one (they inherit the loaded
results; nothing is pickled but the figures' names, the outcome and a side job's
result), each drawing its share and writing the PNG files itself. The shares are balanced by each figure's
expected cost in axes (:func:`~.run.figure_plan`): the longest first, each to the
least loaded worker (Graham's LPT rule, within 4/3 of the best split).

The files are the same as when drawn in this process, byte for byte
(tests/test_plots_parallel.py). Without ``fork`` (Windows), with one CPU, or with
``OPENFDK_PLOT_WORKERS=1`` the figures are drawn here, one after the other. A figure
that fails in a worker does not stop the others: every failure is collected and
reported together, naming the figures (:class:`FigureError`); so does a worker that is
stopped (killed for memory, a signal), naming the figures it had not written. A symbolic link planted
at a figure's path is refused before any worker starts (``openfdk.io.outdir``).

A :class:`SideJob` shares the workers with the figures: ``openfdk run``'s check whether a
contact patch reaches a mesh's rim (:func:`openfdk.contact.rim.contact_rim_frames`, 1.6 s
of CPU for DM's 100 frames). It is one more share of the LPT split, weighed in the
figures' units; its result comes back to this process, which reports it (the warnings
are this process's). Run in this process while the workers drew (until stop 60), it was
a third process on DM's 2-core machine: the 100-frame command spent a median of 5.6 s
after its FDK solve, 5.0 s with the check as a share (docs/outputs.md, "Two processes").
"""

from __future__ import annotations

import multiprocessing
import os
import warnings
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

from .run import figure_plan, save_figures

#: the most worker processes the figures are drawn in (two already take the body poses'
#: figure apart from the others; it is the longest single one)
MAX_WORKERS = 2

#: the job a forked worker draws from: (results, measures, directory, side job or None),
#: set only while the workers run
_JOB = None
#: the name of the side job's share entry (no figure has it: figure names are words)
SIDE = "(side job)"
_UNSET = object()


class SideJob:
    """A computation drawn with the figures (module docstring). ``compute()`` (no arguments)
    runs in a worker when there are workers (forked: it sees this process's data) and
    returns a picklable result; :meth:`finish` then gives it to ``report(result)`` in this
    process. ``weight``: its expected cost in the figures' units (axes,
    :func:`~.run.figure_plan`; about 0.054 s each on DM's run).

    Whatever happens to the figures, the caller calls :meth:`finish` once: it computes the
    result here if no worker did (one worker, no ``fork``, a worker that failed or was
    stopped: an error of ``compute`` is then raised here as its own), and reports it."""

    def __init__(self, compute, report, weight=0.0):
        self.compute, self.report, self.weight = compute, report, float(weight)
        self._result, self._finished = _UNSET, False

    def take(self, result):
        """Keep ``result``, computed elsewhere (a worker), for :meth:`finish`."""
        self._result = result

    def finish(self):
        """Report the result (computed here first if no worker did); a second call does nothing."""
        if self._finished:
            return
        self._finished = True
        result = self.compute() if self._result is _UNSET else self._result
        self.report(result)


class FigureError(ValueError):
    """One or more figures could not be drawn (from the results as read: ``openfdk plot``
    reports it as bad input); the message names each with its error. ``written``: the
    paths of the figures that were written."""

    def __init__(self, message, written=()):
        super().__init__(message)
        self.written = list(written)


def plot_workers():
    """The number of processes to draw figures in: ``OPENFDK_PLOT_WORKERS`` if set (≥ 1),
    else the CPUs this process may use, at most :data:`MAX_WORKERS`; 1 where processes
    cannot be forked."""
    if "fork" not in multiprocessing.get_all_start_methods():
        return 1
    raw = os.environ.get("OPENFDK_PLOT_WORKERS", "").strip()
    if raw:
        try:
            n = int(raw)
        except ValueError:
            raise ValueError(f"OPENFDK_PLOT_WORKERS={raw!r}: give a whole number ≥ 1") from None
        if n < 1:
            raise ValueError(f"OPENFDK_PLOT_WORKERS={raw!r}: give a whole number ≥ 1")
        return n
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(MAX_WORKERS, cpus))


def balanced_shares(weights, workers):
    """Indices of ``weights`` (n,) split into at most ``workers`` non-empty lists by the
    LPT rule (module docstring); each list in increasing order."""
    shares = [[] for _ in range(max(1, min(workers, len(weights))))]
    load = [0.0] * len(shares)
    for i in sorted(range(len(weights)), key=lambda i: (-weights[i], i)):
        j = min(range(len(shares)), key=lambda j: (load[j], j))
        shares[j].append(i)
        load[j] += weights[i]
    return [sorted(s) for s in shares if s]


def _draw(names):
    """In a worker: draw and write the figures ``names`` (and compute the side job for
    :data:`SIDE`); [(name, error message or None, the side job's result or None)]."""
    results, measures, directory, side = _JOB
    builds = {name: build for name, build, _ in figure_plan(results, measures)}
    done = []
    for name in names:
        try:
            if name == SIDE:
                done.append((name, None, side.compute()))
                continue
            save_figures({name: builds[name]()}, directory)
            done.append((name, None, None))
        except Exception as exc:  # reported by the parent with the other figures' outcome
            done.append((name, f"{type(exc).__name__}: {exc}", None))
    return done


def write_figures(results, directory, measures=None, workers=None, side=None) -> list[Path]:
    """Draw the figures of ``results`` (a :class:`~openfdk.results.run.RunResults`) into
    ``directory`` (created) as ``<name>.png``, in ``workers`` processes (default
    :func:`plot_workers`). Returns the paths in the figures' order; raises
    :class:`FigureError` naming every figure that failed (the others are written).

    side : a :class:`SideJob` computed in a worker beside the figures (``openfdk run``'s
    contact-rim check), or None. Its result is kept for its :meth:`SideJob.finish`, which
    the caller makes (here the job is never reported, nor computed without workers)."""
    global _JOB
    from ..io.outdir import refuse_link

    plan = figure_plan(results, measures)
    workers = plot_workers() if workers is None else int(workers)
    d = Path(directory)
    save_figures({}, d)  # the folder checked (no planted link) and created once, here
    for name, _, _ in plan:
        refuse_link(d / f"{name}.png")  # a planted link refused before anything is drawn
        # (an earlier drawing's file removed: a file there afterwards is this call's, also
        # when a worker is stopped before it can report)
        (d / f"{name}.png").unlink(missing_ok=True)
    if workers <= 1 or len(plan) < 2 or "fork" not in multiprocessing.get_all_start_methods():
        return save_figures(((name, build()) for name, build, _ in plan), d)
    jobs = [(name, weight) for name, _, weight in plan] + ([(SIDE, side.weight)] if side is not None else [])
    shares = [[jobs[i][0] for i in share] for share in balanced_shares([w for _, w in jobs], workers)]
    _JOB = (results, measures, d, side)
    outcome = {}
    try:
        with warnings.catch_warnings():
            # (Python ≥ 3.12 warns of fork in a process with threads; the workers only draw)
            warnings.simplefilter("ignore", DeprecationWarning)
            with ProcessPoolExecutor(len(shares), mp_context=multiprocessing.get_context("fork")) as pool:
                futures = [pool.submit(_draw, share) for share in shares]
                for share, future in zip(shares, futures):
                    try:
                        for name, error, result in future.result():
                            if name == SIDE:
                                if error is None:
                                    side.take(result)  # (failed: SideJob.finish computes it here)
                            else:
                                outcome[name] = error
                    except BrokenProcessPool as exc:  # a worker killed (out of memory, a signal)
                        outcome.update((name, f"its worker process stopped ({exc})") for name in share
                                       if name != SIDE and not (d / f"{name}.png").is_file())
    finally:
        _JOB = None
    for name, _, _ in plan:  # a stopped worker's figures that were written before it stopped
        if name not in outcome and (d / f"{name}.png").is_file():
            outcome[name] = None
    written = [d / f"{name}.png" for name, _, _ in plan if outcome.get(name, "not drawn") is None]
    failed = [f"{name}: {outcome.get(name) or 'not drawn'}" for name, _, _ in plan if outcome.get(name, 1) is not None]
    if failed:
        raise FigureError(f"{len(failed)} of {len(plan)} figures not written ({'; '.join(failed)})", written)
    return written


def write_plots(result_dir, out_dir=None, measures=None, model=None, side=None) -> list[Path]:
    """Read a result folder and write its figures (default into ``RESULT_DIR/plots``) with
    :func:`write_figures` (``side`` as there); ``model``: the run's Model when the
    caller has it loaded (the FDK DOFs' and the constraints' units; else read from the
    model file again)."""
    from ..results.run import read_results

    return write_figures(read_results(result_dir, model), out_dir or Path(result_dir) / "plots", measures,
                         side=side)


__all__ = ["write_plots", "write_figures", "plot_workers", "balanced_shares", "FigureError", "SideJob",
           "MAX_WORKERS"]
